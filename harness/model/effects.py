"""Physical effects a model configuration may add (``ModelConfig.effects``).

One base class, :class:`Effect`, with hooks that do nothing by default
(PyElastica's ``NoForces`` is the model): an effect overrides only the hooks
where it acts. Every hook is applied in one place of the pipeline, so an
effect reaches every engine, not one:

=====================  =============================================  ===========================
hook                   where it is applied                            reaches
=====================  =============================================  ===========================
``modulus``            :func:`canebench.model.chain.build_chain`      every chain and the beam
``diameter``           chain link diameters and the beam's EI(s)      every chain and the beam
``root_compliance``    series spring on the base joint pair; the      every chain and the beam
                       beam's base spring (``Chain.base_compliance``)
``probe_pitch_deg``    the probe direction of the chain               every backend
``measured``           the simulated trace before its slope is fit    every backend
                       (:func:`canebench.execute.pipeline.run_job`)
``fit_window_mm``      the field fit *and* the simulated fit of one   every backend
                       trial (obstruction: score only up to onset)
=====================  =============================================  ===========================

An effect in a configuration is an :class:`EffectSpec`: its name, global
parameter values, and values local to a cane or a trial (``local``), e.g.
the per-trial obstruction onsets. Third parties add effects through the
``canebench.effects`` entry-point group (a subclass of :class:`Effect`).
"""

from __future__ import annotations

import math
import re
import warnings
from collections.abc import Iterable
from dataclasses import dataclass, field
from importlib import metadata
from typing import Any, ClassVar, Mapping, NamedTuple

import numpy as np

from ..errors import InputError, warn_input
from ..registry import Registry

ENTRY_POINT_GROUP = "canebench.effects"


@dataclass(frozen=True)
class Parameter:
    """A named effect parameter.

    Attributes
    ----------
    unit : str
    low, high : float
        Search bounds of the discovery workflow (physically plausible range).
    null : float
        The value at which the effect does nothing (``inf`` for a spring in
        series); for a parameter that does not switch it off
        (``switches_off=False``), the default value.
    log : bool
        Searched on a log scale (positive quantities spanning decades); only
        positive values are valid.
    doc : str
    minimum, maximum : float
        Smallest and largest valid values (beyond the search bounds: a model
        file may set any valid value; one outside the physically plausible
        range, where ``low`` and ``high`` are its ends, is warned about).
    physical_bounds : bool
        Whether ``low`` and ``high`` are the ends of the physically plausible range (a modulus 0.2 to 5
        times the stated one, a root no softer than 0.3 N m/rad, a rig no softer than 20 N/m, a pitch
        within 45 degrees): a fit pressed against the end away from ``null`` says the effect cannot
        account for the data within physics, and the discovery workflow does not name it. False where
        a bound only limits the search (a flare's excess and length trade off, and a true flare is fitted
        at the 25 mm bound with a shorter length).
    switches_off : bool
        Whether this parameter at ``null`` alone switches the effect off,
        whatever the others are (a flare's excess does; its length, whose
        ``null`` is only a default, does not). The discovery workflow does not
        name an effect whose 95 % interval of such a parameter reaches ``null``
        (or, for a null beyond the search bounds, the bound on its side: a
        spring's stiffest bound stands for infinitely stiff).
    refined : bool
        Held at ``null`` while the discovery workflow selects effects, and fitted only afterwards,
        on the selected model, where a likelihood-ratio test asks for it
        (:mod:`canebench.discovery.refine`): a refinement of an effect's form that the data can
        seldom resolve, and whose extra freedom should not help an effect be named.
    """

    unit: str
    low: float
    high: float
    null: float
    log: bool = False
    doc: str = ""
    minimum: float = -math.inf
    switches_off: bool = True
    physical_bounds: bool = True
    maximum: float = math.inf
    refined: bool = False

    def null_bound(self) -> float:
        """The search bound at which the parameter does nothing: the one equal to its null, or beyond
        which the null lies (the high one of a spring whose null is infinitely stiff); NaN (no bound)
        where the null lies inside, or is NaN."""
        def at(b: float) -> bool:  # equal up to the optimizer's rounding (numpy's isclose, rtol 1e-6)
            return bool(np.isclose(self.null, b, rtol=1e-6, atol=1e-9))

        if at(self.high) or self.null > self.high:
            return self.high
        if at(self.low) or self.null < self.low:
            return self.low
        return math.nan


class Effect:
    """Base class of a physical effect: every hook leaves the model unchanged.

    Subclasses set :attr:`name`, :attr:`parameters` and override hooks.
    An instance holds one set of parameter values (``effect.p["k_root"]``).
    """

    name: ClassVar[str] = ""
    summary: ClassVar[str] = ""
    #: where it acts: material, geometry, base, probe, measurement, trial
    where: ClassVar[str] = ""
    parameters: ClassVar[dict[str, Parameter]] = {}
    #: scopes the discovery workflow may fit: global, per_cane, per_trial. With ``per_cane``, the
    #: workflow tests whether the first parameter that switches the effect off differs between canes
    #: (:mod:`canebench.discovery.per_cane`; a modulus scale per cane is each fit's random level)
    scopes: ClassVar[tuple[str, ...]] = ("global",)

    def __init__(self, **params: float) -> None:
        unknown = set(params) - set(self.parameters)
        if unknown:
            raise KeyError(f"unknown parameter(s) {sorted(unknown)} of effect {self.name!r}; "
                           f"known: {sorted(self.parameters)}")
        self.p = {k: float(params.get(k, par.null)) for k, par in self.parameters.items()}

    def __repr__(self) -> str:
        return f"{type(self).__name__}({', '.join(f'{k}={v:.4g}' for k, v in self.p.items())})"

    @classmethod
    def per_cane_parameter(cls) -> str | None:
        """The parameter that may differ between canes: the first that switches the effect off, where
        the effect allows the ``per_cane`` scope; None otherwise."""
        if "per_cane" not in cls.scopes:
            return None
        return next((p for p, par in cls.parameters.items() if par.switches_off), None)

    # ----------------------------------------------------------- hooks
    def modulus(self, E: float) -> float:
        """Flexural modulus (Pa) the model uses, given the stated one."""
        return E

    def diameter(self, s: np.ndarray, d: np.ndarray) -> np.ndarray:
        """Diameter (m) at arc lengths ``s`` (m from the base), given the caliper fit's ``d``."""
        return d

    def root_compliance(self) -> float:
        """Rotational compliance (rad/(N m)) at the base about both bending axes, in series with the clamp."""
        return 0.0

    def probe_pitch_deg(self) -> float:
        """Extra pitch of the probe from perpendicular (degrees, positive up)."""
        return 0.0

    def measured(self, x_m: np.ndarray, f_n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """What the rig records for a cane pushed by ``x_m`` with force ``f_n``."""
        return x_m, f_n

    def fit_window_mm(self) -> float | None:
        """Score this trial only over its first ... mm of contact (None: all of it)."""
        return None

    def record_end_mm(self) -> float | None:
        """Read this trial's rig record only up to this travel (mm from its first sample; None: all of it)."""
        return None


EFFECTS: Registry[type[Effect]] = Registry("physical effect")


def register_effect(cls: type[Effect], tags: tuple[str, ...] = ()) -> type[Effect]:
    EFFECTS.add(cls.name, cls, (cls.where, *tags), cls.summary)
    return cls


# --------------------------------------------------------------- the library


class ModulusScale(Effect):
    name = "modulus_scale"
    summary = "E differs from the stated modulus (season, variety): E_true = scale x E_stated"
    where = "material"
    parameters = {"scale": Parameter("1", 0.2, 5.0, 1.0, True, "E_true / E_stated")}
    scopes = ("global", "per_cane")

    def modulus(self, E: float) -> float:
        return E * self.p["scale"]


class RootCompliance(Effect):
    name = "root_compliance"
    summary = "the base is not a rigid clamp: a rotational spring k_root about both bending axes"
    where = "base"
    parameters = {"k_root": Parameter("N m/rad", 0.3, 3000.0, math.inf, True,
                                      "rotational stiffness of the root about each bending axis")}
    #: a root is its plant's and its soil's: discovery asks whether k_root differs between canes
    scopes = ("global", "per_cane")

    def root_compliance(self) -> float:
        return 1.0 / self.p["k_root"]


class RigCompliance(Effect):
    name = "rig_compliance"
    summary = "the rig flexes: a spring k_rig in series with the probe (the rig records its own travel)"
    where = "measurement"
    parameters = {"k_rig": Parameter("N/m", 20.0, 1.0e5, math.inf, True, "stiffness of the rig in series")}

    def measured(self, x_m: np.ndarray, f_n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return np.asarray(x_m) + np.asarray(f_n) / self.p["k_rig"], f_n


class BaseFlare(Effect):
    """d(s) = d_fit(s) + excess (d_fit(s) / 10 mm)^q exp(-s / length).

    By default (q = 0) an absolute thickening, not a fraction of the fitted
    diameter: a root collar similar in size on thin and thick canes, which
    stiffens thin canes far more, as the field data show. With q = 1 the
    excess is a share of the cane's own diameter, d_fit(s) (1 + A exp(-s /
    length)) with A = excess / 10 mm: a collar that grows with the cane.
    ``size_exponent`` (q) is held at 0 while effects are selected and fitted
    only where the selected model's likelihood asks for it
    (:mod:`canebench.discovery.refine`): among canes of one size the two forms
    are the same flare. Calipers taken at the push points cannot see it.
    """

    name = "base_flare"
    summary = ("the cane thickens toward the base beyond the linear caliper fit: "
               "d(s) = d_fit(s) + excess_mm (d_fit(s) / 10 mm)^size_exponent exp(-s / length_mm)")
    where = "geometry"
    #: the diameter at which ``excess_mm`` is the excess whatever ``size_exponent`` is (m)
    D_REF_M = 0.010
    parameters = {"excess_mm": Parameter("mm", 0.0, 25.0, 0.0, False, "extra diameter at the ground (of a cane "
                                         "10 mm thick there, where size_exponent is not 0)", minimum=0.0,
                                         physical_bounds=False),
                  "length_mm": Parameter("mm", 20.0, 600.0, 150.0, True, "e-folding length of the excess",
                                          physical_bounds=False,
                                          switches_off=False),
                  "size_exponent": Parameter("1", 0.0, 1.0, 0.0, False, "how the excess grows with the cane's own "
                                             "diameter: 0 one collar for every cane, 1 a share of the diameter",
                                             minimum=0.0, switches_off=False, physical_bounds=False, refined=True)}
    #: a collar is its cane's: discovery asks whether the excess differs between canes
    scopes = ("global", "per_cane")

    def diameter(self, s: np.ndarray, d: np.ndarray) -> np.ndarray:
        excess = 1e-3 * self.p["excess_mm"] * np.exp(-np.asarray(s) / (1e-3 * self.p["length_mm"]))
        q = self.p["size_exponent"]
        if q != 0.0:  # at 0 exactly the absolute collar (bit for bit: the fits that never free q)
            # a line that reaches zero far beyond the push (toward the tip) is floored later anyway
            excess = excess * (np.maximum(np.asarray(d, float), 1e-6) / self.D_REF_M) ** q
        return d + excess


class ProbeMisalignment(Effect):
    name = "probe_misalignment"
    summary = "the probe is pitched from perpendicular to the cane by angle_deg (positive up)"
    where = "probe"
    # beyond 89 degrees the probe pushes along the cane (the configuration's probe_angle_deg has the same limit)
    parameters = {"angle_deg": Parameter("deg", -45.0, 45.0, 0.0, False, "probe pitch", minimum=-89.0, maximum=89.0)}

    def probe_pitch_deg(self) -> float:
        return self.p["angle_deg"]


class Obstruction(Effect):
    """A second body engages partway through some trials (an elbow up in the
    force): those trials are scored only up to the onset, in the field and in
    every simulation (truncation, as the paper does for contacts)."""

    name = "obstruction"
    summary = "in some trials a second body engages partway (elbow): scored only up to onset_mm of contact"
    where = "trial"
    parameters = {"onset_mm": Parameter("mm", 1.0, 200.0, math.inf, False,
                                        "displacement after contact at which the second body engages",
                                        minimum=0.0, physical_bounds=False),
                  "record_end_mm": Parameter("mm", 0.0, 1000.0, math.inf, False,
                                             "where the field record is cut (travel from its first sample): set at "
                                             "the elbow where the elbow hides the contact knee from the field "
                                             "stage, so the contact is found before it", minimum=0.0,
                                             switches_off=False, physical_bounds=False)}
    scopes = ("per_trial",)

    def fit_window_mm(self) -> float | None:
        return self._set("onset_mm")

    def record_end_mm(self) -> float | None:
        return self._set("record_end_mm")

    def _set(self, name: str) -> float | None:
        v = self.p[name]
        return v if math.isfinite(v) else None  # the null (inf): not set for this trial


for _cls in (ModulusScale, RootCompliance, RigCompliance, BaseFlare, ProbeMisalignment, Obstruction):
    register_effect(_cls, ("builtin",))

_loaded = False


def load_entry_points() -> None:
    """Register third-party effects (entry-point group ``canebench.effects``) once."""
    global _loaded
    if _loaded:
        return
    _loaded = True
    for ep in metadata.entry_points(group=ENTRY_POINT_GROUP):
        if ep.name in EFFECTS:
            continue
        try:
            cls = ep.load()
        except Exception as exc:  # a broken plugin is skipped with its reason, never a crash
            warnings.warn(f"effect {ep.name!r} from {ep.value} is unavailable: {type(exc).__name__}: {exc}")
            continue
        if not (isinstance(cls, type) and issubclass(cls, Effect)):
            warnings.warn(f"entry point {ep.name!r} in {ENTRY_POINT_GROUP} is not an Effect subclass; skipped")
            continue
        register_effect(cls, ("plugin",))


def _least(values: Iterable[float | None]) -> float | None:
    """The smallest of the values that are set (None if none is): the strictest of several effects."""
    w = [v for v in values if v is not None]
    return min(w) if w else None


# --------------------------------------------------------------- specs in a configuration

_Pairs = tuple[tuple[str, float], ...]


def _pairs(d: Mapping[str, Any]) -> _Pairs:
    return tuple(sorted((str(k), float(v)) for k, v in d.items()))


#: the largest ln sd between canes a model file may give (a factor e^5 = 148 per sd: no cane's root or
#: collar spreads so; beyond it a log-normal draw overflows before it means anything)
LN_SD_MAX = 5.0
#: the largest sampling variances of (ln median, ln ln_sd) a model file may give: a median uncertain
#: by a factor e, a spread by a factor e^0.5 = 1.65, at one standard error. Beyond it a member's drawn
#: spread can reach hundreds and its value overflow, so discovery writes a spread known worse than that
#: cut to these variances (its correlation kept), and says so (``PerCaneTest.drawable_cov``)
COV_LN_MAX = (1.0, 0.25)


def _number(x: Any) -> float:
    """A model file's number: an int, a float, or a numeric string (YAML 1.1 reads ``2e1`` as text);
    ValueError for anything else (booleans, None, words) or a number too large for a float."""
    if isinstance(x, bool) or x is None or not isinstance(x, (int, float, str)):
        raise ValueError(x)
    try:
        return float(x)
    except OverflowError:
        raise ValueError(x) from None


class Spread(NamedTuple):
    """How one parameter varies between canes: log-normal, median ``median``, sd of its log ``ln_sd``.

    ``cov_ln``, where the fit gave it, is the sampling covariance of (ln median, ln ln_sd) (discovery's
    per-cane test: the inverse of the hierarchy's observed information). A cane drawn outside the data
    then carries that uncertainty too: the spread of a new cane's value is the fitted one's only up to
    its sampling error (about 17 % in ln_sd at 18 canes)."""

    median: float
    ln_sd: float
    cov_ln: tuple[tuple[float, float], tuple[float, float]] | None = None

    def draw(self, rng: np.random.Generator) -> float:
        """One new cane's value: with ``cov_ln``, (ln median, ln ln_sd) drawn from their sampling
        normal first (three standard normals), else the fitted log-normal's (one)."""
        if self.cov_ln is None:
            return float(self.median * math.exp(self.ln_sd * rng.standard_normal()))
        z = rng.standard_normal(3)
        (a, b), (_, c) = self.cov_ln
        # the 2 x 2 Cholesky factor, written out (a >= 0 and a c >= b^2 are checked on load)
        l11 = math.sqrt(a)
        l21 = b / l11 if l11 > 0 else 0.0
        l22 = math.sqrt(max(c - l21 * l21, 0.0))
        ln_median = math.log(self.median) + l11 * z[0]
        ln_sd = self.ln_sd * math.exp(l21 * z[0] + l22 * z[1])
        return float(math.exp(ln_median + ln_sd * z[2]))

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"median": self.median, "ln_sd": self.ln_sd}
        if self.cov_ln is not None:
            d["cov_ln"] = [list(r) for r in self.cov_ln]
        return d

    def check(self, source: str, where: str) -> None:
        """InputError naming ``source`` and ``where`` (``root_compliance.between_canes.k_root``) unless
        the median is finite and > 0, the ln sd finite in [0, :data:`LN_SD_MAX`] and ``cov_ln``, if
        given, a valid covariance (:func:`check_cov_ln`) beside an ln sd > 0."""
        if not (isinstance(self.median, float) and math.isfinite(self.median) and self.median > 0):
            raise InputError(source, f"{where}.median", f"must be a finite number > 0, got {self.median!r}")
        if not (isinstance(self.ln_sd, float) and math.isfinite(self.ln_sd) and 0 <= self.ln_sd <= LN_SD_MAX):
            raise InputError(source, f"{where}.ln_sd", f"must be a finite number in [0, {LN_SD_MAX:g}], got {self.ln_sd!r}")
        if self.cov_ln is not None:
            check_cov_ln(self.cov_ln, source, f"{where}.cov_ln")
            if self.ln_sd <= 0:
                raise InputError(source, f"{where}.cov_ln", "a sampling covariance of ln ln_sd needs ln_sd > 0")


def check_cov_ln(obj: Any, source: str, where: str) -> tuple[tuple[float, float], tuple[float, float]]:
    """``cov_ln`` as a tuple of float tuples: a symmetric positive semi-definite 2 x 2 [[a, b], [b, c]] of
    finite numbers with a <= 1 and c <= 0.25 (:data:`COV_LN_MAX`); InputError naming ``source`` and
    ``where`` otherwise."""
    what = (f"expected a symmetric positive semi-definite [[a, b], [b, c]] of numbers with 0 <= a <= "
            f"{COV_LN_MAX[0]:g} and 0 <= c <= {COV_LN_MAX[1]:g}, got {obj!r}")
    if not isinstance(obj, (list, tuple)) or len(obj) != 2 or not all(isinstance(r, (list, tuple)) and len(r) == 2
                                                                        for r in obj):
        raise InputError(source, where, what)
    try:
        (a, b), (b2, c) = ((_number(x) for x in r) for r in obj)
    except ValueError:
        raise InputError(source, where, what) from None
    if not all(math.isfinite(x) for x in (a, b, b2, c)) or not (0 <= a <= COV_LN_MAX[0] and 0 <= c <= COV_LN_MAX[1]):
        raise InputError(source, where, what)
    # bounded above, so the products below cannot overflow
    if abs(b - b2) > 1e-9 * max(abs(b), abs(b2), 1e-300) or b * b > a * c * (1 + 1e-9):
        raise InputError(source, where, what)
    return ((a, b), (b, c))


def _between(obj: Any, source: str) -> tuple[tuple[str, Spread], ...]:
    """A model file's ``between_canes`` ({parameter: {median, ln_sd[, cov_ln]}}) as
    :attr:`EffectSpec.between` (absent: None or an empty mapping). The values' ranges are checked
    with the rest of the effect (:meth:`Spread.check`, from :meth:`EffectSpec.validate`)."""
    if obj is None:
        return ()
    if not isinstance(obj, Mapping):
        raise InputError(source, "between_canes", f"expected a mapping of parameter: {{median, ln_sd}}, got {obj!r}")
    out = []
    for k, v in obj.items():
        if not isinstance(v, Mapping) or not {"median", "ln_sd"} <= set(v) <= {"median", "ln_sd", "cov_ln"}:
            raise InputError(source, str(k), f"expected {{median: ..., ln_sd: ...[, cov_ln: ...]}}, got {v!r}")
        try:
            median, ln_sd = _number(v["median"]), _number(v["ln_sd"])
        except ValueError:
            raise InputError(source, str(k), f"median and ln_sd must be numbers, got {dict(v)!r}") from None
        cov = check_cov_ln(v["cov_ln"], source, f"{k}.cov_ln") if v.get("cov_ln") is not None else None
        out.append((str(k), Spread(median, ln_sd, cov)))
    return tuple(sorted(out))


def _as_spread(v: Any) -> Any:
    """``v`` as a :class:`Spread` of floats with ``cov_ln`` as float tuples, where it can be read so;
    else ``v`` unchanged (:meth:`EffectSpec.validate` then names it)."""
    try:
        median, ln_sd, *rest = v
        if len(rest) > 1:
            return v
        cov = rest[0] if rest else None
        if cov is not None:
            cov = tuple(tuple(_number(x) for x in r) for r in cov)
        return Spread(_number(median), _number(ln_sd), cov)
    except (TypeError, ValueError):
        return v


@dataclass(frozen=True)
class EffectSpec:
    """An effect as a model configuration holds it (hashable, serializable).

    Attributes
    ----------
    name : str
    params : tuple of (name, value)
        Global parameter values (missing ones: the parameter's null value).
    local : tuple of (id, tuple of (name, value))
        Values that hold for one cane (cane id) or one trial (trial id) only.
    scope : str
        ``global``, ``per_cane`` or ``per_trial`` (what was fitted).
    between : tuple of (name, Spread)
        How a parameter varies between canes, where that was fitted (discovery's per-cane test):
        log-normal, median ``median``, sd of its logarithm ``ln_sd``, and the sampling covariance of
        their logs where known (:class:`Spread`). A cane outside the data is drawn from it by a
        population export; a trial's model uses ``params`` and ``local`` only.
    """

    name: str
    params: _Pairs = ()
    local: tuple[tuple[str, _Pairs], ...] = ()
    scope: str = "global"
    between: tuple[tuple[str, Spread], ...] = ()

    def __post_init__(self) -> None:
        # a spread given as a plain (median, ln_sd[, cov_ln]) tuple, or with lists (from Python), is a
        # Spread of floats and tuples, so that equal specs compare and hash equal however they were
        # written; what cannot be read so is left for validate() to name
        object.__setattr__(self, "between", tuple((str(k), _as_spread(v)) for k, v in self.between))

    @classmethod
    def parse(cls, obj: Any, source: str = "effects") -> "EffectSpec":
        """From an EffectSpec, a dict (model file) or text ``name`` / ``name(k=v, k2=v2)``."""
        if isinstance(obj, EffectSpec):
            return obj
        if isinstance(obj, Mapping):
            name = obj.get("effect", obj.get("name"))
            if not isinstance(name, str):
                raise InputError(source, "effect", f"an effect entry needs a name, got {dict(obj)!r}")
            try:
                local = tuple(sorted((str(k), _pairs(v)) for k, v in (obj.get("local") or {}).items()))
                params = _pairs(obj.get("params") or {})
            except (TypeError, ValueError, AttributeError) as exc:
                raise InputError(source, name, f"parameter values must be numbers: {exc}") from None
            return cls(name, params, local, str(obj.get("scope", "global")),
                       _between(obj.get("between_canes"), f"{source}: {name}.between_canes"))
        text = str(obj).strip()
        m = re.fullmatch(r"([A-Za-z_][\w.-]*)\s*(?:\((.*)\))?", text)
        if not m:
            raise InputError(source, text, "expected NAME or NAME(key=value, ...)")
        params = {}
        for item in filter(None, (p.strip() for p in (m.group(2) or "").split(","))):
            k, eq, v = item.partition("=")
            try:
                params[k.strip()] = float(v)
            except ValueError:
                raise InputError(source, f"{m.group(1)}.{k.strip()}", f"cannot read {v!r} as a number") from None
            if not eq:
                raise InputError(source, m.group(1), f"expected key=value, got {item!r}")
        return cls(m.group(1), _pairs(params))

    def values_for(self, cane_id: str | None = None, trial_id: str | None = None) -> dict[str, float]:
        """Parameter values that hold for one trial (global, then the cane's, then the trial's)."""
        out = dict(self.params)
        loc = dict(self.local)
        for key in (cane_id, trial_id):
            if key is not None and key in loc:
                out.update(dict(loc[key]))
        return out

    def localized(self, cane_id: str, trial_id: str) -> "EffectSpec":
        """The same effect with only the values for this trial (for job keys: other canes' values, and how
        the values vary between canes, are irrelevant)."""
        return EffectSpec(self.name, _pairs(self.values_for(cane_id, trial_id)), (), self.scope)

    def instance(self, cane_id: str | None = None, trial_id: str | None = None) -> Effect:
        return EFFECTS[self.name](**self.values_for(cane_id, trial_id))

    def units(self) -> dict[str, str]:
        """The unit of each global parameter, as the registered effect declares it."""
        par = EFFECTS[self.name].parameters
        return {p: par[p].unit for p, _ in self.params}

    def warn_implausible(self, source: str) -> None:
        """Warn (an error under ``--strict``) of each value outside its parameter's physically
        plausible range (a modulus 50 times the stated one, a rig of 1e-6 N/m): valid, so a user may
        mean it, but the answer is then no plant's. Called where a user's values come in (a model
        file, ``--set``), not on every configuration the workflow builds."""
        cls = EFFECTS.get(self.name)
        if cls is None:
            return
        for where, pairs in (("", self.params), *((f"[{k}]", v) for k, v in self.local)):
            for k, v in pairs:
                par = cls.parameters.get(k)
                if par is None or not par.physical_bounds or v == par.null:
                    continue
                # the end on the null's side only stands for it (a spring's stiffest bound for rigid):
                # beyond it the effect fades, which is no implausible plant
                side = par.null_bound()
                if (v < par.low and side != par.low) or (v > par.high and side != par.high):
                    unit = "" if par.unit == "1" else f" {par.unit}"
                    warn_input(source, f"{self.name}{where}.{k}", f"{v:g}{unit} is outside {par.low:g} to "
                               f"{par.high:g}{unit}, the physically plausible range ({par.doc})")

    def validate(self, source: str) -> None:
        load_entry_points()
        if self.name not in EFFECTS:
            import difflib

            close = difflib.get_close_matches(self.name, list(EFFECTS), n=1)
            raise InputError(source, "effects", f"unknown physical effect {self.name!r}"
                             + (f"; did you mean {close[0]!r}?" if close else f"; registered: {', '.join(EFFECTS)}"))
        cls = EFFECTS[self.name]
        if self.scope not in ("global", "per_cane", "per_trial"):
            raise InputError(source, f"{self.name}.scope", f"must be global, per_cane or per_trial, got {self.scope!r}")
        for where, pairs in (("", self.params), *((f"[{k}]", v) for k, v in self.local)):
            for k, v in pairs:
                if k not in cls.parameters:
                    raise InputError(source, f"{self.name}{where}.{k}",
                                     f"unknown parameter; {self.name} has {', '.join(cls.parameters)}")
                par = cls.parameters[k]
                ok = math.isfinite(v) or v == par.null
                if not ok or (par.log and v <= 0) or v < par.minimum or v > par.maximum:
                    limits = (f"; valid: {par.minimum:g} to {par.maximum:g}"
                              if math.isfinite(par.minimum) and math.isfinite(par.maximum) else "")
                    raise InputError(source, f"{self.name}{where}.{k}", f"invalid value {v!r} ({par.unit}){limits}")
        for k, spread in self.between:
            where = f"{self.name}.between_canes.{k}"
            if k not in cls.parameters:
                raise InputError(source, where, f"unknown parameter; {self.name} has {', '.join(cls.parameters)}")
            # a log-normal spread is what discovery fits for a cane's own positive value (a rig or a
            # pitch has none)
            varies = cls.per_cane_parameter()
            if k != varies:
                raise InputError(source, where, f"{self.name}.{k} cannot vary between canes"
                                 + (f" (only {varies} can)" if varies else f" ({self.name} is one value for all canes)"))
            if not isinstance(spread, Spread):
                raise InputError(source, where, f"expected (median, ln_sd[, cov_ln]) numbers, got {spread!r}")
            spread.check(source, where)

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"effect": self.name, "scope": self.scope, "params": dict(self.params)}
        if self.local:
            d["local"] = {k: dict(v) for k, v in self.local}
        if self.between:
            d["between_canes"] = {k: sp.to_dict() for k, sp in self.between}
        return d

    def drawn(self, rng: np.random.Generator) -> "EffectSpec":
        """A cane outside the data: each parameter in ``between`` drawn by :meth:`Spread.draw` (in the
        order of ``between``), the others at their global values, no cane's own."""
        if not self.between:
            return self
        values = dict(self.params)
        for k, spread in self.between:
            values[k] = spread.draw(rng)
        return EffectSpec(self.name, _pairs(values))

    def __str__(self) -> str:
        inner = ", ".join(f"{k}={v:.6g}" for k, v in self.params)
        extra = f" +{len(self.local)} local" if self.local else ""
        return f"{self.name}({inner}){extra}"


def split_effects_text(text: str) -> list[str]:
    """Split ``a(x=1, y=2), b`` at top-level commas."""
    out, depth, cur = [], 0, []
    for ch in text:
        if ch == "(":
            depth += 1
        elif ch == ")":
            depth -= 1
        if ch == "," and depth == 0:
            out.append("".join(cur).strip())
            cur = []
        else:
            cur.append(ch)
    if "".join(cur).strip():
        out.append("".join(cur).strip())
    return [s for s in out if s]


@dataclass
class AppliedEffects:
    """The effect instances acting on one trial, and their combined hooks."""

    effects: list[Effect] = field(default_factory=list)

    @classmethod
    def for_trial(cls, specs: tuple[EffectSpec, ...], cane_id: str | None, trial_id: str | None) -> "AppliedEffects":
        return cls([s.instance(cane_id, trial_id) for s in specs])

    def modulus(self, E: float) -> float:
        for e in self.effects:
            E = e.modulus(E)
        return E

    def diameter(self, s: np.ndarray, d: np.ndarray) -> np.ndarray:
        for e in self.effects:
            d = e.diameter(s, d)
        return d

    def root_compliance(self) -> float:
        return float(sum(e.root_compliance() for e in self.effects))

    def probe_pitch_deg(self) -> float:
        return float(sum(e.probe_pitch_deg() for e in self.effects))

    def measured(self, x_m: np.ndarray, f_n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        for e in self.effects:
            x_m, f_n = e.measured(x_m, f_n)
        return x_m, f_n

    def fit_window_mm(self) -> float | None:
        return _least(e.fit_window_mm() for e in self.effects)

    def record_end_mm(self) -> float | None:
        return _least(e.record_end_mm() for e in self.effects)

    @property
    def changes_diameter(self) -> bool:
        return any(type(e).diameter is not Effect.diameter for e in self.effects)
