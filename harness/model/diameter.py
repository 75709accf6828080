"""Cane diameter along its length from a few caliper measurements.

Paper assumption #1: diameter varies linearly with length along the cane. A
least-squares line through the (arc length, diameter) measurements is
evaluated at each link's midpoint. The 'diameter factor' f in [0, 1] scales
the fitted slope about the measurements' centroid: f = 0 gives a constant
diameter equal to the centroid's, f = 1 the fitted line.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class DiameterFit:
    s_centroid: float
    d_centroid: float
    slope: float  # fitted d(d)/ds (dimensionless), before the factor
    factor: float

    def __call__(self, s: np.ndarray | float) -> np.ndarray:
        s = np.asarray(s, dtype=float)
        return self.d_centroid + self.factor * self.slope * (s - self.s_centroid)


def fit_diameter(s: np.ndarray, d: np.ndarray, factor: float = 1.0) -> DiameterFit:
    """Least-squares line d = a + b s through the calipers, scaled by ``factor``.

    One measurement (or all at one place) gives a constant diameter.
    """
    s = np.asarray(s, dtype=float)
    d = np.asarray(d, dtype=float)
    sc, dc = float(s.mean()), float(d.mean())
    var = float(((s - sc) ** 2).sum())
    slope = float(((s - sc) * (d - dc)).sum() / var) if var > 1e-18 else 0.0
    return DiameterFit(sc, dc, slope, float(factor))
