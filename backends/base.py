"""The interface a backend implements, and what the harness gives it.

A backend only *builds, steps and reads*. The probe protocol (setpoints, PID
law and gains, sampling, stop rules, divergence checks), the stiffness fit
and scoring live in the harness (:mod:`canebench.probe.driver`).

Two kinds:

* :class:`DynamicBackend` - ``build(chain, protocol)`` returns a
  :class:`Simulation` that applies a force along the probe direction for one
  time step (``step``) and reads the probe point (``read``). Engines with an
  implicit built-in PID may also offer the *native* path (``set_setpoint`` /
  ``advance`` / ``force``), used when the protocol asks for ``controller =
  "engine"``; its gains are the protocol's.
* :class:`StaticBackend` - ``build(chain)`` returns a :class:`StaticModel`
  whose ``solve(displacement)`` gives the force holding the probe point at that
  displacement in exact static equilibrium.
"""

from __future__ import annotations

import importlib
from abc import ABC, abstractmethod
from typing import Any, Callable, ClassVar

from canebench.model.chain import Chain
from canebench.errors import BackendUnavailable
from canebench.probe.protocol import Protocol


class Backend(ABC):
    """Common part of every backend.

    Class attributes
    ----------------
    name : str
        Registry name (``--backends`` value).
    kind : str
        ``"dynamic"`` or ``"static"``.
    tags : tuple of str
        Free labels (``"reference"``, ``"implicit-springs"``...) for selection.
    engine_module : str
        Module whose import decides availability and gives the version.
    """

    name: ClassVar[str] = ""
    kind: ClassVar[str] = ""
    #: True if ``build`` compiles the optional third (twist) joint of each link
    supports_twist: ClassVar[bool] = False
    tags: ClassVar[tuple[str, ...]] = ()
    engine_module: ClassVar[str] = ""

    @classmethod
    def check_available(cls) -> None:
        """Raise :class:`BackendUnavailable` with the reason if the engine cannot be used."""
        try:
            importlib.import_module(cls.engine_module)
        except Exception as exc:  # any import-time failure makes it unavailable
            raise BackendUnavailable(f"{cls.engine_module}: {type(exc).__name__}: {exc}") from exc

    @classmethod
    def engine_version(cls) -> str:
        mod = importlib.import_module(cls.engine_module)
        return str(getattr(mod, "__version__", "unknown"))

    @abstractmethod
    def settings(self, protocol: Protocol) -> dict[str, Any]:
        """How the engine is configured for ``protocol`` (integrator, dt, where
        springs/damping/PID are integrated, why). Recorded in every result."""

    def answer(self, protocol: Protocol) -> str:
        """What kind of answer this backend gives under ``protocol``: ``dynamic``
        (the engine integrates the push in time), ``static`` (exact
        equilibrium) or ``quasi-static`` (a dynamic engine answering with a
        static solve on its own kinematics, making no time step). Recorded in
        every result so no reader mistakes one for another."""
        return self.kind


class Simulation(ABC):
    """One compiled chain in a dynamic engine."""

    #: True if ``set_setpoint``/``advance``/``force`` are implemented.
    native_pid: bool = False
    #: Engine time step (s).
    dt: float

    @abstractmethod
    def read(self) -> tuple[float, float]:
        """Probe point displacement (m) and velocity (m/s) along the probe
        direction, relative to its rest position, for the current state."""

    @abstractmethod
    def step(self, force: float) -> None:
        """Apply ``force`` (N) along the probe direction at the probe point for one step."""

    def run_controlled(self, controller: Callable[[float, float], float], n_steps: int, tail: int) -> float:
        """Advance ``n_steps`` applying ``controller(x, v)`` (the harness PID),
        evaluated from the state at the start of each step. Return the largest
        probe speed seen in the last ``tail`` steps (the harness's chatter check).

        Override to run the loop inside the engine (e.g. a pre-step callback);
        the control law stays the harness's.
        """
        vmax = 0.0
        read, step = self.read, self.step
        start_tail = n_steps - tail
        for i in range(n_steps):
            x, v = read()
            step(controller(x, v))
            if i >= start_tail and abs(v) > vmax:
                vmax = abs(v)
        return vmax

    def set_setpoint(self, setpoint: float) -> None:  # pragma: no cover - optional
        raise NotImplementedError

    def advance(self, n_steps: int) -> None:  # pragma: no cover - optional
        raise NotImplementedError

    def force(self) -> float:  # pragma: no cover - optional
        """Force (N) the native PID currently applies."""
        raise NotImplementedError

    def health(self) -> str | None:
        """Engine-specific sign of divergence (a warning flag...), or None."""
        return None

    def close(self) -> None:
        """Release engine resources."""


class DynamicBackend(Backend):
    kind = "dynamic"

    @abstractmethod
    def build(self, chain: Chain, protocol: Protocol) -> Simulation:
        """Compile ``chain`` for ``protocol`` (time step, integrator, PID mode)."""


class StaticModel(ABC):
    @abstractmethod
    def solve(self, displacement: float) -> float:
        """Force (N) along the probe direction that holds the probe point at
        ``displacement`` (m) in static equilibrium. Raise on failure."""

    def linear_stiffness(self) -> float:
        """Small-deflection stiffness (N/m) at the rest configuration, gravity off."""
        raise NotImplementedError


class StaticBackend(Backend):
    kind = "static"

    @abstractmethod
    def build(self, chain: Chain) -> StaticModel:
        """Compile ``chain`` into a static solver."""
