"""Named flexural-modulus distributions to sample from ("modelers should pull
from distributions", the paper's conclusion).

A :class:`ModulusDistribution` is a four-parameter beta distribution on
[lower, upper] whose mean and standard deviation are exactly the stated ones
(method of moments, closed form). Beta because the modulus is bounded by
what was measured and positive, and because a normal truncated to the
paper's range cannot reach the dormant spread the paper implies (a truncated
normal on [a, b] has sd < (b - a) / sqrt(12) = 1.80 GPa even centred).

:data:`MODULUS_DISTRIBUTIONS` holds the paper's (tagged ``paper``):

* means and n: the paper's Results (dormant 4.57 GPa, n = 19; fruiting
  3.00 GPa, n = 40; Duke 4.33 GPa dormant, n = 5, and 3.59 GPa fruiting, n = 11);
* bounds: the paper's measured range over all samples, 1.82-8.05 GPa (no
  per-group ranges were published);
* sd: NOT published. Fruiting 0.95 GPa is assumed; dormant 1.78 GPa is then
  what makes Welch's t-test at the published n and means give the published
  p = 0.0015. Duke entries take their season's sd. "all" pools the seasons.
  With sd that wide for the range, the dormant, dormant-duke and all
  entries have alpha < 1: density rising toward 1.82 GPa. Only the mean, sd
  and bounds are claimed, not the shape.

:func:`distributions_from_result` fits the same kind of objects to a
modulus study (per season, season x variety, season x age), for data that
has samples. Runs, sweeps and exports call ``.sample(n, rng)`` (Pa) or
``.ppf(q)`` (for quasi-random or Morris designs on [0, 1]).
"""

from __future__ import annotations

import json
import re
import warnings
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd
from scipy import stats

from ..errors import InputError
from ..registry import Registry

if TYPE_CHECKING:
    from ..studies.modulus import ModulusResult

GPA = 1e9
PAPER_RANGE_PA = (1.82 * GPA, 8.05 * GPA)
PAPER_SD_GPA = {"dormant": 1.78, "fruiting": 0.95}


@dataclass(frozen=True)
class ModulusDistribution:
    """A bounded flexural-modulus distribution (Pa) with exact mean and sd.

    Attributes
    ----------
    name : str
        Registry name, e.g. ``fruiting-duke``.
    mean_pa, sd_pa : float
        Mean and standard deviation (Pa), matched exactly.
    lower_pa, upper_pa : float
        Support (Pa); every sample lies within.
    provenance : str
        Where each number comes from (paper table, assumption, fitted study).
    n : int or None
        Samples behind the mean, when known.
    """

    name: str
    mean_pa: float
    sd_pa: float
    lower_pa: float
    upper_pa: float
    provenance: str
    n: int | None = None

    def __post_init__(self) -> None:
        src = f"modulus distribution {self.name!r}"
        vals = (self.mean_pa, self.sd_pa, self.lower_pa, self.upper_pa)
        if not all(np.isfinite(v) for v in vals) or self.lower_pa <= 0 or self.sd_pa <= 0:
            raise InputError(src, "mean_pa/sd_pa/lower_pa/upper_pa", f"need finite, positive values, got {vals}")
        if not self.lower_pa < self.mean_pa < self.upper_pa:
            raise InputError(src, "mean_pa",
                             f"{self.mean_pa:.4g} not inside ({self.lower_pa:.4g}, {self.upper_pa:.4g})")
        m, v = self._unit_moments()
        if v >= m * (1 - m):
            raise InputError(src, "sd_pa", f"{self.sd_pa:.4g} too large for mean {self.mean_pa:.4g} within the bounds "
                                           f"(at most {np.sqrt(m * (1 - m)) * (self.upper_pa - self.lower_pa):.4g})")

    def _unit_moments(self) -> tuple[float, float]:
        w = self.upper_pa - self.lower_pa
        return (self.mean_pa - self.lower_pa) / w, (self.sd_pa / w) ** 2

    @property
    def shape(self) -> tuple[float, float]:
        """The beta's (alpha, beta) on [lower, upper]."""
        m, v = self._unit_moments()
        c = m * (1 - m) / v - 1
        return m * c, (1 - m) * c

    def frozen(self) -> Any:
        """The scipy.stats frozen distribution."""
        a, b = self.shape
        return stats.beta(a, b, loc=self.lower_pa, scale=self.upper_pa - self.lower_pa)

    def sample(self, n: int, rng: np.random.Generator | int | None = None) -> np.ndarray:
        """``n`` moduli (Pa); ``rng`` a Generator or a seed."""
        x = self.frozen().rvs(size=n, random_state=np.random.default_rng(rng))
        return np.clip(np.atleast_1d(x), self.lower_pa, self.upper_pa)

    def ppf(self, q: float | np.ndarray) -> np.ndarray:
        """Quantiles (Pa) of ``q`` in [0, 1] (maps a unit design onto the distribution)."""
        return self.frozen().ppf(q)

    def to_dict(self) -> dict:
        """Plain-JSON description, for run metadata and exports."""
        a, b = self.shape
        return {**asdict(self), "family": "beta on [lower, upper], moments matched", "alpha": a, "beta": b}


def _paper() -> Registry[ModulusDistribution]:
    reg: Registry[ModulusDistribution] = Registry("modulus distribution")
    lo, hi = PAPER_RANGE_PA
    rng_txt = "bounds: the paper's measured range over all samples 1.82-8.05 GPa"
    sd_txt = {"dormant": "sd 1.78 GPa not published: with fruiting sd 0.95 it makes Welch's t at the published "
                         "n and means give the published p = 0.0015",
              "fruiting": "sd 0.95 GPa not published: assumed"}
    for name, season, variety, n, mean in (("dormant", "dormant", "", 19, 4.57), ("fruiting", "fruiting", "", 40, 3.00),
                                           ("dormant-duke", "dormant", "Duke", 5, 4.33),
                                           ("fruiting-duke", "fruiting", "Duke", 11, 3.59)):
        what = f"{variety + ' ' if variety else ''}{season}-season mean {mean} GPa (n={n}): paper, Results"
        sd = sd_txt[season] + (f" (the {season} season's)" if variety else "")
        tags = ("paper", f"season:{season}") + ((f"variety:{variety.lower()}",) if variety else ())
        reg.add(name, ModulusDistribution(name, mean * GPA, PAPER_SD_GPA[season] * GPA, lo, hi,
                                          f"{what}; {rng_txt}; {sd}", n), tags, what)
    d, f = reg["dormant"], reg["fruiting"]
    n = d.n + f.n
    mean = (d.n * d.mean_pa + f.n * f.mean_pa) / n
    var = ((d.n - 1) * d.sd_pa**2 + (f.n - 1) * f.sd_pa**2 + d.n * (d.mean_pa - mean) ** 2
           + f.n * (f.mean_pa - mean) ** 2) / (n - 1)
    reg.add("all", ModulusDistribution("all", mean, float(np.sqrt(var)), lo, hi,
                                       f"both seasons pooled from 'dormant' and 'fruiting' (n={n}); {rng_txt}", n),
            ("paper",), "both seasons pooled")
    return reg


MODULUS_DISTRIBUTIONS: Registry[ModulusDistribution] = _paper()


def _slug(*parts: str) -> str:
    return "-".join(re.sub(r"[^a-z0-9+.]+", "-", str(p).lower()).strip("-") for p in parts if p)


def distributions_from_result(result: "ModulusResult | str | Path", min_n: int = 3) -> Registry[ModulusDistribution]:
    """Distributions fitted to a modulus study: per season, season x variety, season x age.

    Parameters
    ----------
    result : ModulusResult or path
        A study's result, or the folder it wrote (``modulus_samples.csv``,
        ``modulus_meta.json``), so nothing is recomputed.
    min_n : int
        Groups with fewer samples are left out.

    Returns
    -------
    Registry of ModulusDistribution
        Names ``dormant``, ``fruiting-duke``, ``fruiting-age-1-year``, ...,
        tagged ``fitted``; mean and sd of the group's sample E, bounds the
        study's range of sample E. A group whose sd cannot fit in those
        bounds is left out with a warning.
    """
    if isinstance(result, (str, Path)):
        smp = pd.read_csv(Path(result) / "modulus_samples.csv", keep_default_na=False, na_values=[""])
        meta = json.loads((Path(result) / "modulus_meta.json").read_text())
    else:
        smp, meta = result.samples, result.meta
    e = smp.E_gpa.to_numpy(float) * GPA
    lo, hi = float(e.min()), float(e.max())
    syn = " [SYNTHETIC data]" if meta.get("synthetic") else ""
    reg: Registry[ModulusDistribution] = Registry("modulus distribution")
    for keys in (("season",), ("season", "variety"), ("season", "age")):
        for k, g in smp.groupby(list(keys), sort=False):
            k = k if isinstance(k, tuple) else (k,)
            if len(g) < min_n:
                continue
            name = _slug(k[0], "age" if "age" in keys else "", *k[1:])
            x = g.E_gpa.to_numpy(float) * GPA
            prov = (f"fitted: modulus study of {meta.get('data_dir')}{syn}: mean and sd of {len(g)} sample E; "
                    f"bounds: the study's range of sample E")
            try:
                dist = ModulusDistribution(name, float(x.mean()), float(x.std(ddof=1)), lo, hi, prov, len(g))
            except InputError as exc:
                warnings.warn(f"{name}: left out: {exc}", RuntimeWarning, stacklevel=2)
                continue
            reg.add(name, dist, ("fitted",) + tuple(f"{a}:{str(b).lower()}" for a, b in zip(keys, k)), prov)
    return reg
