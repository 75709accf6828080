"""Jobs: one (trial, backend, protocol, complete model configuration) each.

A job's key is a hash of everything its result depends on:

* the cane description's physics (centreline, raw flag, calipers, push
  points, material; not its file path or provenance notes) and the push point;
* the backend name and its engine's version;
* the protocol (every field) and the number of protocol steps (which the
  field trial's duration sets);
* the complete model configuration, including any physical effects and
  their parameters added later (``ModelConfig.to_dict``);
* canebench's code: a hash of every source file of the installed package
  (and of the backend's module when a plugin lives elsewhere), so a
  resumed run never mixes results of two versions of the physics, however
  small the change (the package version alone is not bumped for each).

The chain a job builds is a pure function of the cane, the push point, the
configuration and canebench's code, so this key determines the chain's
fingerprint (which every result row records as ``chain_hash``). The key is
computed from those inputs rather than from a built chain so that computing
it never runs model code in the parent: a pathological configuration
(``segments=100000``) must hang inside a job, where the time limit applies,
not while the job list is being made.

Same key, same result. Labels (a study's sample index, factor values) ride
along with a job into its row but are not part of the key: the same physics
asked for by two studies is computed once.
"""

from __future__ import annotations

import functools
import hashlib
import json
from pathlib import Path
from dataclasses import dataclass, field
from typing import Any

from .. import __version__
from ..data.cane import cane_to_dict
from ..data.dataset import Trial
from ..model.config import ModelConfig
from ..probe.protocol import Protocol


def _canonical(obj: Any) -> str:
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), default=_default)


def _default(obj: Any) -> Any:
    try:
        import numpy as np

        if isinstance(obj, np.ndarray):
            return obj.tolist()
        if isinstance(obj, np.generic):
            return obj.item()
    except ImportError:  # pragma: no cover
        pass
    if isinstance(obj, (set, frozenset)):
        return sorted(obj)
    raise TypeError(f"not serialisable in a job key: {type(obj).__name__}")


def cane_physics(trial: Trial) -> dict[str, Any]:
    """The part of a cane description a simulation depends on (not its file paths or notes)."""
    d = cane_to_dict(trial.cane)
    d.pop("provenance", None)
    for p in d.get("push_points", []):
        p.pop("trial", None)
    return d


@functools.lru_cache(maxsize=None)
def code_fingerprint(extra_module: str | None = None) -> str:
    """Hash of canebench's source files (and of ``extra_module``'s file, for plugin backends)."""
    import canebench

    h = hashlib.sha256()
    root = Path(canebench.__file__).resolve().parent
    files = sorted(root.rglob("*.py"))
    import canebench.backends as cb

    broot = Path(cb.__file__).resolve().parent
    if broot != root / "backends":  # editable layout: backends/ is a sibling of harness/
        files += sorted(broot.rglob("*.py"))
    if extra_module:
        try:
            import importlib

            f = getattr(importlib.import_module(extra_module), "__file__", None)
            if f:
                files.append(Path(f))
        except Exception:
            pass
    for f in files:
        h.update(f.name.encode())
        h.update(f.read_bytes())
    return h.hexdigest()[:16]


@functools.lru_cache(maxsize=4096)  # one per configuration, asked for by every row and trace of it
def config_hash(config: ModelConfig) -> str:
    """Short hash of a model configuration (labels rows of multi-configuration runs)."""
    return hashlib.sha256(_canonical(config.to_dict()).encode()).hexdigest()[:12]


@dataclass(frozen=True)
class Job:
    """One simulation to run.

    Attributes
    ----------
    trial : Trial
    backend : str
    engine_version : str
        Version of the backend's engine (part of the key: a new engine means new results).
    protocol : Protocol
    config : ModelConfig
    n_steps : int
        Protocol steps (the field trial's duration caps the paper's 90).
    labels : dict
        Study labels copied into the result row; not part of the key.
    backend_cls : type, optional
        The backend class itself, for backends registered at run time (not
        through the entry point), which worker processes cannot discover.
    """

    trial: Trial
    backend: str
    engine_version: str
    protocol: Protocol
    config: ModelConfig
    n_steps: int
    labels: dict[str, Any] = field(default_factory=dict, compare=False, hash=False)
    backend_cls: Any = field(default=None, compare=False, hash=False)
    backend_module: str = field(default="", compare=False, hash=False)

    def _plugin_module(self) -> str | None:
        mod = getattr(self.backend_cls, "__module__", None) or self.backend_module
        return None if not mod or mod.startswith("canebench.") else mod

    @property
    def key(self) -> str:
        k = getattr(self, "_key", None)
        if k is None:
            payload = {
                "cane": cane_physics(self.trial), "push": self.trial.push_id, "backend": self.backend,
                "engine": self.engine_version, "protocol": self.protocol.to_dict(), "config": self.config.to_dict(),
                "n_steps": int(self.n_steps), "canebench": __version__,
                "code": code_fingerprint(self._plugin_module()),
            }
            k = hashlib.sha256(_canonical(payload).encode()).hexdigest()[:24]
            object.__setattr__(self, "_key", k)
        return k


@dataclass
class JobResult:
    """What one job produced: a row of simulation columns and the sampled trace."""

    key: str
    row: dict[str, Any]
    displacement_m: list[float] = field(default_factory=list)
    force_n: list[float] = field(default_factory=list)

    def to_json(self) -> str:
        return json.dumps({"row": self.row, "x": self.displacement_m, "f": self.force_n}, default=_default)

    @classmethod
    def from_json(cls, key: str, text: str) -> "JobResult":
        d = json.loads(text)
        return cls(key, d["row"], d["x"], d["f"])
