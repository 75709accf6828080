"""Populations of canes: the bundled (or field) canes with drawn material and diameters.

Draw ``i`` of a population of ``N`` (seed ``S``) takes the ``i mod n``-th
selected cane (round robin, so every cane appears N/n times) and a random
generator seeded with ``[S, i]`` (draw ``i`` is the same whatever ``N``), and
draws:

* **modulus** E from the named :data:`~canebench.model.distributions.MODULUS_DISTRIBUTIONS`
  entry (``all``, ``dormant``, ``fruiting``, ``dormant-duke``,
  ``fruiting-duke``: beta distributions matching the paper's means and
  range; see that module for which numbers are assumed);
* **caliper diameters**: every caliper reading d_k is redrawn as
  d_k + sigma e_k (e_k standard normal), and the harness refits its
  diameter line through the redrawn readings as for any cane, which
  propagates the readings' uncertainty into the fit's intercept and slope.
  sigma is the larger of ``caliper_sd_m`` (default 0.15 mm, the synthetic
  generator's caliper noise) and the cane's own fit residual standard
  deviation (readings off the fitted line, with n - 2 degrees of freedom,
  when it has 3 or more calipers). A redrawn reading is kept at or above
  half the original (never reached at 0.15 mm on millimetre canes).

* **effects that vary between canes**: an effect whose model file gives its spread between canes
  (``between_canes``: discovery's per-cane root or collar, a log-normal with the fitted median and
  ln sd) takes a value drawn from it, as a new cane would, from a stream of its own (seeded
  ``[S, i, 1]``, so the draws above are those of a model without it). Where the file also gives
  the fit's sampling covariance of (ln median, ln ln_sd) (``cov_ln``, which discovery writes), each
  member first draws its median and ln sd from that normal (:meth:`~canebench.model.effects.Spread.draw`):
  18 canes pin a spread to about 17 %, and a population drawn from the point estimate alone would
  be narrower in its tails than the canes it stands for. The canes' own fitted values
  (``local``) are not used: a member is a new cane on a measured cane's geometry, as its modulus
  is drawn and not that cane's.

Everything else (geometry, density, damping, discretization, formula,
other effects) is the model configuration's, unchanged.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..data.cane import Caliper, CaneDescription
from ..errors import InputError
from ..model.chain import cane_curve, resolve_s
from ..model.config import ModelConfig
from ..model.distributions import MODULUS_DISTRIBUTIONS, ModulusDistribution

DEFAULT_CALIPER_SD_M = 0.15e-3
DEFAULT_DISTRIBUTION = "all"
MAX_POPULATION = 1_000_000

WHAT_IS_DRAWN = (
    "per draw i (rng seeded [seed, i]): cane = selection[i mod n]; modulus E ~ the named modulus distribution; "
    "each caliper diameter d_k + sigma e_k, e_k ~ N(0, 1), sigma = max(caliper_sd_m, the cane's diameter-fit "
    "residual sd), the diameter line refit through the drawn readings; an effect with a spread between canes "
    "(between_canes) its value ~ median exp(ln_sd z) from a stream seeded [seed, i, 1], with (ln median, "
    "ln ln_sd) first drawn from their sampling normal where the model gives cov_ln, no cane's own value; "
    "everything else from the model configuration"
)


@dataclass(frozen=True)
class Draw:
    """One member of a population."""

    index: int
    cane: CaneDescription  # with the drawn caliper readings
    push_id: str
    config: ModelConfig  # with the drawn modulus
    record: dict[str, Any]


def get_distribution(name: str) -> ModulusDistribution:
    from ..registry import UnknownName

    try:
        return MODULUS_DISTRIBUTIONS[name]
    except UnknownName as exc:
        raise InputError("--distribution", "distribution", str(exc)) from None


def check_population_size(n: Any) -> int:
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or not 1 <= int(n) <= MAX_POPULATION:
        raise InputError("--population", "population", f"must be a whole number from 1 to {MAX_POPULATION}, "
                                                       f"got {n!r}")
    return int(n)


def fit_residual_sd(cane: CaneDescription, config: ModelConfig) -> float:
    """Residual sd (m) of the caliper readings about their least-squares line in arc length; 0 below 3 calipers."""
    if len(cane.calipers) < 3:
        return 0.0
    curve = cane_curve(cane, config)
    s = np.array([resolve_s(curve, c.where, cane.source, f"calipers[{i}]") for i, c in enumerate(cane.calipers)])
    d = np.array([c.diameter for c in cane.calipers])
    if np.ptp(s) < 1e-12:
        return float(np.std(d, ddof=1))
    A = np.column_stack([np.ones_like(s), s])
    coef, *_ = np.linalg.lstsq(A, d, rcond=None)
    r = d - A @ coef
    return float(np.sqrt(r @ r / (len(d) - 2)))


def draw_population(selection: list[tuple[CaneDescription, str]], config: ModelConfig, n: int, seed: int,
                    distribution: str = DEFAULT_DISTRIBUTION,
                    caliper_sd_m: float = DEFAULT_CALIPER_SD_M) -> list[Draw]:
    """``n`` draws over ``selection`` ((cane, push point id) pairs); deterministic for ``seed``."""
    n = check_population_size(n)
    if not selection:
        raise InputError("--population", "canes", "no cane selected to draw from")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise InputError("--seed", "seed", f"must be a whole number >= 0, got {seed!r}")
    if not (np.isfinite(caliper_sd_m) and caliper_sd_m >= 0):
        raise InputError("--caliper-sd-mm", "caliper_sd", f"must be a finite number >= 0, got {caliper_sd_m!r}")
    dist = get_distribution(distribution)
    for e in config.effects:
        if e.scope == "per_cane" and e.local and not e.between:
            # a model file written before between_canes (or by hand): no spread to draw a new cane from
            # (a per-trial effect's values, an obstruction's onsets, are its trials' and draw nothing)
            from ..errors import warn_input

            warn_input("--model", f"{e.name}.local", "per-cane values but no spread between canes "
                       "(between_canes): each member takes its source cane's own value, not a new cane's; "
                       "rerun canebench discover to write the spread")
    sigmas = [max(caliper_sd_m, fit_residual_sd(c, config)) for c, _ in selection]
    draws = []
    for i in range(n):
        k = i % len(selection)
        cane, push = selection[k]
        rng = np.random.default_rng([int(seed), i])
        E = float(dist.sample(1, rng)[0])
        d0 = np.array([c.diameter for c in cane.calipers])
        d1 = np.maximum(d0 + sigmas[k] * rng.standard_normal(len(d0)), 0.5 * d0)
        drawn = dataclasses.replace(cane, calipers=tuple(Caliper(c.where, float(d)) for c, d in zip(cane.calipers, d1)))
        record = {
            "draw": i, "seed": int(seed), "distribution": dist.name, "modulus_pa": E,
            "caliper_sd_m": sigmas[k], "caliper_diameters_m": d1.tolist(),
            "caliper_scales": (d1 / d0).tolist(), "diameter_scale_mean": float(d1.mean() / d0.mean()),
        }
        cfg = config.replace(modulus_pa=E)
        if any(e.between for e in config.effects):
            fx_rng = np.random.default_rng([int(seed), i, 1])
            specs = tuple(e.drawn(fx_rng) for e in config.effects)
            record["effects_drawn"] = {e.name: {k: dict(e.params)[k] for k, _ in old.between}
                                       for e, old in zip(specs, config.effects) if old.between}
            cfg = cfg.replace(effects=specs)
        draws.append(Draw(i, drawn, push, cfg, record))
    return draws
