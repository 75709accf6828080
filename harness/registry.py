"""Backend registry fed by Python entry points (group ``canebench.backends``).

Like asv's environment plugins: every installed distribution may add an
engine by declaring an entry point; one that cannot import (engine missing,
broken build) is listed as unavailable with the reason and skipped, and the
run goes on with the others. Built-in backends register through the same
group from canebench's own ``pyproject.toml``.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from importlib import metadata
from typing import Any

from .errors import BackendUnavailable, UnknownBackend

ENTRY_POINT_GROUP = "canebench.backends"

# Used only when canebench itself is not installed (no entry-point metadata),
# e.g. when run from a source tree on PYTHONPATH.
_BUILTIN = {
    "mujoco": "canebench.backends.mujoco_backend:MujocoBackend",
    "pinocchio": "canebench.backends.pinocchio_backend:PinocchioBackend",
    "dart": "canebench.backends.dart_backend:DartBackend",
    "exudyn": "canebench.backends.exudyn_backend:ExudynBackend",
    "pybullet": "canebench.backends.pybullet_backend:PybulletBackend",
    "beam": "canebench.backends.beam_backend:BeamBackend",
}


@dataclass
class BackendInfo:
    name: str
    target: str  # "module:Class"
    cls: Any = None
    available: bool = False
    reason: str = ""
    version: str = ""
    tags: tuple[str, ...] = field(default_factory=tuple)
    kind: str = ""


_REGISTRY: dict[str, BackendInfo] = {}
_LOADED = False


def _load_class(target: str) -> Any:
    mod_name, _, attr = target.partition(":")
    import importlib

    return getattr(importlib.import_module(mod_name), attr)


def _probe(info: BackendInfo, loader: Any) -> BackendInfo:
    try:
        cls = loader()
        cls.check_available()
        info.cls, info.available = cls, True
        info.version = cls.engine_version()
        info.tags, info.kind = tuple(cls.tags), cls.kind
    except BackendUnavailable as exc:
        info.available, info.reason = False, str(exc)
    except Exception as exc:  # ImportError of the engine, broken plugin...
        info.available, info.reason = False, f"{type(exc).__name__}: {exc}"
    return info


def register_backend(cls: Any, name: str | None = None) -> BackendInfo:
    """Register a backend class directly (tests, notebooks)."""
    name = name or cls.name
    info = _probe(BackendInfo(name, f"{cls.__module__}:{cls.__qualname__}"), lambda: cls)
    _REGISTRY[name] = info
    return info


def discover(refresh: bool = False) -> dict[str, BackendInfo]:
    """All registered backends, available or not, by name."""
    global _LOADED
    if _LOADED and not refresh:
        return _REGISTRY
    eps = list(metadata.entry_points(group=ENTRY_POINT_GROUP))
    targets = {ep.name: (ep.value, ep.load) for ep in eps}
    for name, target in _BUILTIN.items():
        targets.setdefault(name, (target, lambda t=target: _load_class(t)))
    for name, (target, loader) in sorted(targets.items()):
        if name in _REGISTRY and not refresh:
            continue
        info = _probe(BackendInfo(name, target), loader)
        if not info.available:
            warnings.warn(f"canebench backend {name!r} unavailable: {info.reason}", RuntimeWarning, stacklevel=2)
        _REGISTRY[name] = info
    _LOADED = True
    return _REGISTRY


def get_backend(name: str) -> Any:
    """An instance of the named backend; raises if unknown or unavailable."""
    reg = discover()
    if name not in reg:
        raise UnknownBackend(f"unknown backend {name!r}; registered: {', '.join(sorted(reg)) or 'none'}")
    info = reg[name]
    if not info.available:
        raise BackendUnavailable(f"backend {name!r} is unavailable: {info.reason}")
    return info.cls()


def select(names: list[str]) -> tuple[list[str], dict[str, str]]:
    """Split requested names into usable ones and skipped ones (with reasons).

    Unknown names raise :class:`UnknownBackend` (a typo should stop the run);
    unavailable ones are skipped with their reason.
    """
    reg = discover()
    usable, skipped = [], {}
    for n in names:
        if n not in reg:
            raise UnknownBackend(f"unknown backend {n!r}; registered: {', '.join(sorted(reg))}")
        if reg[n].available:
            usable.append(n)
        else:
            skipped[n] = reg[n].reason
    return usable, skipped
