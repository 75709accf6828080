"""One tagged registry mechanism for everything selectable by name.

Backends, stiffness formulas, probe protocols, model presets, physical
effects and studies are each a :class:`Registry`: a name maps to an object,
with tags and a one-line description (dm_control's ``TaggedTasks`` is the
model). Registering a name twice is an error: a plugin must never silently
replace a built-in.

Backends are special only in where they come from: the entry-point group
``canebench.backends`` of every installed distribution, canebench's own
included (see ``pyproject.toml``). Like asv's environment plugins, a backend
whose engine cannot be imported is kept in the registry as *unavailable* with
its reason (a warning, not a crash), and runs skip it.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from importlib import metadata
from typing import Any, Callable, Generic, Iterator, TypeVar

from .errors import BackendUnavailable, CanebenchError, UnknownBackend

T = TypeVar("T")
ENTRY_POINT_GROUP = "canebench.backends"


class DuplicateName(CanebenchError):
    """A name registered twice in one registry."""


class UnknownName(CanebenchError, KeyError):
    """A name that is not in a registry."""

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else "unknown name"


@dataclass(frozen=True)
class Entry(Generic[T]):
    name: str
    obj: T
    tags: tuple[str, ...] = ()
    description: str = ""


class Registry(Generic[T]):
    """Named, tagged objects of one kind.

    Parameters
    ----------
    kind : str
        What the entries are ("stiffness formula", "protocol", ...), used in
        error messages.
    """

    def __init__(self, kind: str) -> None:
        self.kind = kind
        self._entries: dict[str, Entry[T]] = {}

    def add(self, name: str, obj: T, tags: tuple[str, ...] | list[str] = (), description: str = "") -> T:
        if name in self._entries:
            raise DuplicateName(f"{self.kind} {name!r} is already registered ({self._entries[name].obj!r})")
        self._entries[name] = Entry(name, obj, tuple(tags), description)
        return obj

    def register(self, name: str, tags: tuple[str, ...] | list[str] = (),
                 description: str = "") -> Callable[[T], T]:
        """Decorator form of :meth:`add`."""

        def deco(obj: T) -> T:
            return self.add(name, obj, tags, description)

        return deco

    def remove(self, name: str) -> None:
        """Drop an entry (tests and notebooks that register temporary ones)."""
        self._entries.pop(name, None)

    def entry(self, name: str) -> Entry[T]:
        try:
            return self._entries[name]
        except KeyError:
            raise UnknownName(f"unknown {self.kind} {name!r}; known: {', '.join(sorted(self._entries)) or 'none'}") \
                from None

    def __getitem__(self, name: str) -> T:
        return self.entry(name).obj

    def get(self, name: str, default: Any = None) -> Any:
        e = self._entries.get(name)
        return e.obj if e is not None else default

    def __contains__(self, name: object) -> bool:
        return name in self._entries

    def __iter__(self) -> Iterator[str]:
        return iter(self._entries)

    def __len__(self) -> int:
        return len(self._entries)

    def names(self, *tags: str) -> list[str]:
        """Names carrying every one of ``tags`` (all names when none given), sorted."""
        return sorted(n for n, e in self._entries.items() if set(tags) <= set(e.tags))

    def items(self) -> list[tuple[str, T]]:
        return [(n, e.obj) for n, e in self._entries.items()]

    def values(self) -> list[T]:
        return [e.obj for e in self._entries.values()]

    def description(self, name: str) -> str:
        return self.entry(name).description


# ---------------------------------------------------------------- backends


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
    from_entry_point: bool = True  # False: registered at run time (tests, notebooks)


BACKENDS: Registry[BackendInfo] = Registry("backend")
_LOADED = False


def _probe(info: BackendInfo, loader: Callable[[], Any]) -> BackendInfo:
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
    """Register a backend class directly (tests, notebooks); the name must be new."""
    discover()
    name = name or cls.name
    info = _probe(BackendInfo(name, f"{cls.__module__}:{cls.__qualname__}", from_entry_point=False), lambda: cls)
    BACKENDS.add(name, info, info.tags, info.kind)
    return info


def unregister_backend(name: str) -> None:
    BACKENDS.remove(name)


def discover(refresh: bool = False) -> Registry[BackendInfo]:
    """All backends of the entry-point group, available or not, by name.

    Two distributions declaring the same backend name with different targets
    is a :class:`DuplicateName` error (the same target seen twice, as an
    editable install can show it, is one backend).
    """
    global _LOADED
    if _LOADED and not refresh:
        return BACKENDS
    seen: dict[str, Any] = {}
    for ep in metadata.entry_points(group=ENTRY_POINT_GROUP):
        if ep.name in seen and seen[ep.name].value != ep.value:
            raise DuplicateName(f"backend {ep.name!r} is declared twice in entry-point group {ENTRY_POINT_GROUP!r}: "
                                f"{seen[ep.name].value} and {ep.value}")
        seen[ep.name] = ep
    if not seen:
        warnings.warn(f"no entry points in group {ENTRY_POINT_GROUP!r}: is canebench installed "
                      "(pip install -e .)?", RuntimeWarning, stacklevel=2)
    for name, ep in sorted(seen.items()):
        if name in BACKENDS and not refresh:
            continue
        info = _probe(BackendInfo(name, ep.value), ep.load)
        if not info.available:
            warnings.warn(f"canebench backend {name!r} unavailable: {info.reason}", RuntimeWarning, stacklevel=2)
        BACKENDS.remove(name)
        BACKENDS.add(name, info, info.tags, info.kind)
    _LOADED = True
    return BACKENDS


def get_backend(name: str) -> Any:
    """An instance of the named backend; raises if unknown or unavailable."""
    reg = discover()
    if name not in reg:
        raise UnknownBackend(f"unknown backend {name!r}; registered: {', '.join(sorted(reg)) or 'none'}")
    info = reg[name]
    if not info.available:
        raise BackendUnavailable(f"backend {name!r} is unavailable: {info.reason}")
    return info.cls()


def backend_version(name: str) -> str:
    reg = discover()
    return reg[name].version if name in reg else ""


def select(names: list[str]) -> tuple[list[str], dict[str, str]]:
    """Split requested names into usable ones and skipped ones (with reasons).

    Unknown names raise :class:`UnknownBackend` (a typo should stop the run);
    unavailable ones are skipped with their reason (returned, so the registry's own warning
    about them is not repeated). Each name counts once, in the order given.
    """
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        reg = discover()
    usable, skipped = [], {}
    for n in dict.fromkeys(names):
        if n not in reg:
            raise UnknownBackend(f"unknown backend {n!r}; registered: {', '.join(sorted(reg))}")
        if reg[n].available:
            usable.append(n)
        else:
            skipped[n] = reg[n].reason
    return usable, skipped
