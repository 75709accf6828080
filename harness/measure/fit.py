"""Stiffness as the slope of force against displacement (shared by field and sim)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class LineFit:
    slope: float  # N/m
    intercept: float  # N
    r2: float
    n: int

    @property
    def slope_n_per_mm(self) -> float:
        return self.slope * 1e-3


def fit_line(x: np.ndarray, y: np.ndarray) -> LineFit | None:
    """Least-squares line y = a + b x; None with fewer than 3 points or no spread."""
    x = np.asarray(x, float)
    y = np.asarray(y, float)
    ok = np.isfinite(x) & np.isfinite(y)
    x, y = x[ok], y[ok]
    if len(x) < 3 or np.ptp(x) <= 0:
        return None
    xm, ym = x.mean(), y.mean()
    sxx = ((x - xm) ** 2).sum()
    b = ((x - xm) * (y - ym)).sum() / sxx
    a = ym - b * xm
    ss_res = ((y - a - b * x) ** 2).sum()
    ss_tot = ((y - ym) ** 2).sum()
    r2 = 1.0 - ss_res / ss_tot if ss_tot > 0 else 1.0
    return LineFit(float(b), float(a), float(r2), int(len(x)))
