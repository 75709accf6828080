"""One model configuration for every modelling choice.

A run takes a :class:`ModelConfig`; sensitivity studies, sweeps and the
discovery workflow call the same pipeline with ``config.replace(...)`` or
``config.with_overrides({"modulus_pa": "3e9"})`` (the CLI's ``--set``).
"""

from __future__ import annotations

import dataclasses
import math
import typing
from dataclasses import dataclass, field
from typing import Any, Mapping

from ..errors import InputError
from .effects import AppliedEffects, EffectSpec, split_effects_text



@dataclass(frozen=True)
class ModelConfig:
    """Every modelling choice that turns a cane description into a chain.

    ``None`` for a material field means "take it from the cane description".

    Attributes
    ----------
    modulus_pa : float or None
        Flexural modulus E (Pa). The paper's naive case uses 4.57e9 for all canes.
    density : float or None
        Wood density (kg/m^3); paper 580.
    damping : float or None
        Joint damping (N m s/rad); paper 0.15.
    diameter_factor : float
        0: constant diameter equal to the caliper centroid's; 1: the
        least-squares line through the calipers; in between, the slope scaled.
    segments : int or None
        Fixed number of links; ``None`` uses the greedy 5 mm rule.
    max_deviation_m : float
        Greedy discretization tolerance (paper: 5 mm).
    min_segments : int
        Fewest links the greedy rule returns (paper: 3, the fewest its
        algorithm produced; a straight cane would otherwise get one link).
    discretization : str
        ``greedy`` (the paper's farthest-point splitting) or ``uniform``
        (equal links; ``segments`` of them, or ``min_segments``).
    node_at_push : bool
        Put a joint exactly at the probe point before the greedy splits
        (off in the paper; with it, the beam-consistent chain converges at
        second order at the probe instead of first).
    stiffness_formula : str
        Name in :data:`canebench.model.stiffness.FORMULAS` (``paper`` = 2EI/L).
    probe_angle_deg : float
        Probe pitch from perpendicular to the cane (paper's Morris range +-30).
    probe_tangent_window_m : float
        Half-width of the arc over which the cane's direction at the push
        point is taken (a centred chord) for the probe's perpendicular: a
        clicked polyline's one segment carries its points' noise (about 1
        degree at 2 mm over 100 mm gaps), which a pitched probe turns into
        stiffness scatter. 0 takes the segment's own direction.
    gravity : float
        Gravitational acceleration (m/s^2) along -z; MuJoCo's default 9.81 as in the paper.
    chaikin_iterations, chaikin_strength : int, float
        Smoothing of raw polylines (paper: 5 iterations, strength 0.35).
    min_diameter_m : float
        Floor for extrapolated diameters; links clamped to it are reported.
    poisson_ratio : float
        nu for the beam reference's torsion, GJ = EI / (1 + nu) (the chains
        have no twist joint). 0.3 is a typical value for green wood.
    beam_elements : int
        First mesh (RK4 elements) of the beam reference, doubled until converged.
    beam_rtol : float
        The beam's mesh is doubled until its small-deflection stiffness changes
        by less than this between meshes (the error estimate in every beam row).
    beam_max_elements : int
        Most elements the beam may use; not converged by then fails the trial.
    twist_joint : bool
        Add a third joint per link about the link's axis (torsion, stiffness
        from GJ = EI / (1 + nu) on the dual segment). Off in the paper; on, the
        beam-consistent chain converges to the beam with torsion (nu =
        ``poisson_ratio``) instead of to a torsion-rigid rod.
    effects : tuple of EffectSpec
        Extra physical effects with their parameters
        (:mod:`canebench.model.effects`; empty reproduces the paper). Given
        as text ``name`` / ``name(key=value, ...)``, dicts (a model file) or
        :class:`~canebench.model.effects.EffectSpec`.
    """

    modulus_pa: float | None = None
    density: float | None = None
    damping: float | None = None
    diameter_factor: float = 1.0
    segments: int | None = None
    max_deviation_m: float = 0.005
    min_segments: int = 3
    node_at_push: bool = False
    discretization: str = "greedy"
    stiffness_formula: str = "paper"
    probe_angle_deg: float = 0.0
    probe_tangent_window_m: float = 0.15
    gravity: float = 9.81
    chaikin_iterations: int = 5
    chaikin_strength: float = 0.35
    min_diameter_m: float = 1.0e-3
    poisson_ratio: float = 0.3
    beam_elements: int = 48
    beam_rtol: float = 1.0e-4
    beam_max_elements: int = 3072
    twist_joint: bool = False
    effects: tuple[EffectSpec, ...] = field(default_factory=tuple)

    def __post_init__(self) -> None:
        # one number, one key: 3000000000 and 3e9 are the same modulus
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if isinstance(v, int) and not isinstance(v, bool) and "float" in str(f.type):
                object.__setattr__(self, f.name, float(v))
        effects = self.effects
        if isinstance(effects, (str, EffectSpec, dict)):
            effects = [effects]
        if isinstance(effects, str):
            effects = split_effects_text(effects)
        object.__setattr__(self, "effects", tuple(
            e for item in effects
            for e in ([EffectSpec.parse(x) for x in split_effects_text(item)] if isinstance(item, str)
                      else [EffectSpec.parse(item)])))
        self.validate()

    def validate(self, source: str = "model configuration") -> None:
        """Raise :class:`InputError` naming the field for an invalid value."""
        for name in ("modulus_pa", "density", "damping"):
            v = getattr(self, name)
            if v is not None and not (math.isfinite(v) and v > 0):
                raise InputError(source, name, f"must be a positive finite number, got {v!r}")
        if not (0.0 <= self.diameter_factor <= 1.0):
            raise InputError(source, "diameter_factor", f"must be in [0, 1], got {self.diameter_factor!r}")
        if self.segments is not None and self.segments < 1:
            raise InputError(source, "segments", f"must be >= 1 or None, got {self.segments!r}")
        if not (self.max_deviation_m > 0):
            raise InputError(source, "max_deviation_m", "must be > 0")
        if self.min_segments < 1:
            raise InputError(source, "min_segments", "must be >= 1")
        if not (-89.0 < self.probe_angle_deg < 89.0):
            raise InputError(source, "probe_angle_deg", "must be within (-89, 89) degrees")
        if not (math.isfinite(self.probe_tangent_window_m) and 0.0 <= self.probe_tangent_window_m <= 1.0):
            raise InputError(source, "probe_tangent_window_m", "must be in [0, 1] m")
        if not (math.isfinite(self.gravity) and self.gravity >= 0):
            raise InputError(source, "gravity", "must be a finite number >= 0")
        if not (0 < self.chaikin_strength <= 0.5):
            raise InputError(source, "chaikin_strength", "must be in (0, 0.5]")
        if self.chaikin_iterations < 0:
            raise InputError(source, "chaikin_iterations", "must be >= 0")
        if not (self.min_diameter_m > 0):
            raise InputError(source, "min_diameter_m", "must be > 0")
        if not (-1.0 < self.poisson_ratio < 0.5):
            raise InputError(source, "poisson_ratio", "must be in (-1, 0.5)")
        if self.discretization not in ("greedy", "uniform"):
            raise InputError(source, "discretization", f"must be 'greedy' or 'uniform', got {self.discretization!r}")
        if self.beam_elements < 2:
            raise InputError(source, "beam_elements", "must be >= 2")
        if not (0 < self.beam_rtol < 0.1):
            raise InputError(source, "beam_rtol", f"must be in (0, 0.1), got {self.beam_rtol!r}")
        if self.beam_max_elements < self.beam_elements:
            raise InputError(source, "beam_max_elements", "must be >= beam_elements")
        from .stiffness import FORMULAS  # late: the formulas module registers on import

        names = [e.name for e in self.effects]
        if len(set(names)) != len(names):
            raise InputError(source, "effects", f"an effect is listed twice: {', '.join(names)}")
        for e in self.effects:
            e.validate(source)
            # the probe's pitch is the configuration's angle plus the effect's: the sum must stay off the axis
            pitches = [(f"{e.name}{w}.angle_deg", dict(v)["angle_deg"]) for w, v in
                       (("", e.params), *((f"[{k}]", v) for k, v in e.local)) if "angle_deg" in dict(v)]
            for fld, a in pitches:
                if not -89.0 < self.probe_angle_deg + a < 89.0:
                    raise InputError(source, fld, f"{a:g} deg with probe_angle_deg {self.probe_angle_deg:g} pitches "
                                                  f"the probe {self.probe_angle_deg + a:g} deg: must be within (-89, 89)")

        if self.stiffness_formula not in FORMULAS:
            import difflib

            close = difflib.get_close_matches(self.stiffness_formula, list(FORMULAS), n=1)
            raise InputError(source, "stiffness_formula", f"unknown formula {self.stiffness_formula!r}"
                             + (f"; did you mean {close[0]!r}?" if close else f"; known: {', '.join(FORMULAS)}"))
        for name in ("segments", "min_segments", "chaikin_iterations", "beam_elements", "beam_max_elements"):
            v = getattr(self, name)
            if v is not None and (isinstance(v, bool) or not isinstance(v, int)):
                raise InputError(source, name, f"must be an integer, got {v!r}")

    def replace(self, **changes: Any) -> "ModelConfig":
        """A copy with some fields changed (validated)."""
        return dataclasses.replace(self, **changes)

    def with_overrides(self, overrides: Mapping[str, Any], source: str = "--set") -> "ModelConfig":
        """A copy with fields set from strings or values (CLI ``key=value``)."""
        hints = typing.get_type_hints(ModelConfig)
        names = {f.name for f in dataclasses.fields(self)}
        changes: dict[str, Any] = {}
        for key, raw in overrides.items():
            if key not in names:
                raise InputError(source, key, f"unknown model setting; known: {', '.join(sorted(names))}")
            changes[key] = _coerce(raw, hints[key], source, key)
        try:
            out = self.replace(**changes)
        except InputError as exc:  # name where the bad value came from
            raise InputError(source, exc.field, exc.message) from None
        _warn_implausible(changes, source)
        if "effects" in changes:
            for e in out.effects:
                e.warn_implausible(source)
        return out

    def to_dict(self) -> dict[str, Any]:
        d = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        d["effects"] = [e.to_dict() for e in self.effects]
        return d

    def localized(self, cane_id: str, trial_id: str) -> "ModelConfig":
        """This configuration as one trial sees it: per-cane and per-trial effect
        values resolved, every other cane's dropped (so a job's key depends
        only on what acts on its trial)."""
        if not any(e.local or e.between for e in self.effects):
            return self
        return dataclasses.replace(self, effects=tuple(e.localized(cane_id, trial_id) for e in self.effects))

    def applied_effects(self, cane_id: str | None = None, trial_id: str | None = None) -> AppliedEffects:
        """Instances of this configuration's effects for one trial."""
        return AppliedEffects.for_trial(self.effects, cane_id, trial_id)

    def fit_window_mm(self, cane_id: str | None, trial_id: str | None, default: float | None = None) -> float | None:
        """The fit window of one trial: the protocol's, shortened by any effect (obstruction onset)."""
        w = self.applied_effects(cane_id, trial_id).fit_window_mm() if self.effects else None
        if w is None:
            return default
        return w if default is None else min(w, default)

    def record_end_mm(self, cane_id: str | None, trial_id: str | None) -> float | None:
        """Where one trial's rig record is cut (mm of travel from its first sample; None: nowhere)."""
        return self.applied_effects(cane_id, trial_id).record_end_mm() if self.effects else None


def _warn_implausible(changes: Mapping[str, Any], source: str) -> None:
    """The same unit checks as for cane files, for values set on the command line."""
    from ..data.cane import PLAUSIBLE_DENSITY, check_modulus
    from ..errors import warn_input

    if changes.get("modulus_pa") is not None:
        check_modulus(changes["modulus_pa"], source, "modulus_pa")
    rho = changes.get("density")
    if rho is not None and not (PLAUSIBLE_DENSITY[0] <= rho <= PLAUSIBLE_DENSITY[1]):
        warn_input(source, "density", f"{rho:.4g} kg/m^3 is implausible for wood")


def parse_assignments(items: list[str] | None, source: str = "--set") -> dict[str, str]:
    """Parse ``["a=1", "b=x"]`` into a dict, naming any malformed item."""
    out: dict[str, str] = {}
    for item in items or []:
        if "=" not in item:
            raise InputError(source, item, "expected key=value")
        k, v = item.split("=", 1)
        out[k.strip()] = v.strip()
    return out


def _coerce(raw: Any, hint: Any, source: str, key: str) -> Any:
    if not isinstance(raw, str):
        return _checked_value(raw, hint, source, key)
    text = raw.strip()
    if typing.get_origin(hint) is tuple:
        return tuple(split_effects_text(text))
    args = typing.get_args(hint)
    optional = type(None) in args
    if optional and text.lower() in ("none", "null", ""):
        return None
    base = next((a for a in args if a is not type(None)), hint) if args else hint
    try:
        if base is bool:
            low = text.lower()
            if low in ("1", "true", "yes", "on"):
                return True
            if low in ("0", "false", "no", "off"):
                return False
            raise ValueError(text)
        if base is int:
            return int(text)
        if base is float:
            v = float(text)
            if not math.isfinite(v):
                raise ValueError(text)
            return v
        return text
    except ValueError as exc:
        what = "a finite number" if base is float else getattr(base, "__name__", base)
        raise InputError(source, key, f"cannot read {raw!r} as {what}") from exc


def _checked_value(raw: Any, hint: Any, source: str, key: str) -> Any:
    """A value that is not text (a model file's YAML) checked against the field's type: a list for a
    modulus, a null where none is allowed or ``true`` for a number would otherwise reach the checks
    (or the engines) as something else."""
    if typing.get_origin(hint) is tuple:
        return raw  # effects: parsed and validated by EffectSpec
    args = typing.get_args(hint)
    optional = type(None) in args
    base = next((a for a in args if a is not type(None)), hint) if args else hint
    if raw is None:
        if optional:
            return None
        raise InputError(source, key, "must be given (null is not allowed here)")
    if base is bool:
        if isinstance(raw, bool):
            return raw
        raise InputError(source, key, f"must be true or false, got {raw!r}")
    if base in (int, float):
        number = isinstance(raw, (int, float)) and not isinstance(raw, bool)
        if number and base is int and isinstance(raw, float) and raw.is_integer():
            raw = int(raw)
        if not number or (base is int and not isinstance(raw, int)):
            what = "a whole number" if base is int else "a number"
            raise InputError(source, key, f"must be {what}, got {raw!r} ({type(raw).__name__})")
        if not math.isfinite(raw):
            raise InputError(source, key, f"must be finite, got {raw!r}")
        return raw
    if base is str and not isinstance(raw, str):
        raise InputError(source, key, f"must be text, got {raw!r} ({type(raw).__name__})")
    return raw
