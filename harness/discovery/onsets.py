"""Obstruction onsets: a stiffening elbow in a field trace that the cane alone
cannot make.

A cane's own force-displacement curve is smooth: large deflection and gravity
bend it gently (stiffening or softening). A second body engaging adds a
spring from one displacement on: the slope jumps. Per trial (contact
samples, tared), every breakpoint b with enough samples on both sides is
tried for a hinge F = a + k1 x + k2 (x - x_b)+, and the best hinge is
compared with the best smooth curve with as many parameters (a quadratic).
An onset is reported when all hold:

* the slope after is at least ``MIN_RATIO`` times the slope before;
* the hinge explains the trace clearly better than the quadratic
  (residual sum of squares at least ``MIN_SSE_RATIO`` times smaller): a kink,
  not curvature;
* the added force at the end of the trace is at least ``MIN_SNR`` times the
  trace's noise (from the median absolute second difference, which a smooth
  curve and a single kink hardly move);
* at least ``MIN_SIDE`` samples (2.5 mm at 0.5 mm steps) before and after.

None of these numbers depend on the cane's stiffness level or on the rig's
step beyond the sample spacing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

MIN_RATIO = 1.8
MIN_SSE_RATIO = 2.5
MIN_SNR = 8.0
MIN_SIDE = 5


@dataclass
class Onset:
    onset_mm: float
    slope_before: float
    slope_after: float
    sse_ratio: float
    snr: float


def _lstsq_sse(A: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, float]:
    coef, *_ = np.linalg.lstsq(A, y, rcond=None)
    r = y - A @ coef
    return coef, float(r @ r)


def detect_onset(x_mm: np.ndarray, f_n: np.ndarray) -> Onset | None:
    """The stiffening elbow of one tared contact trace, or None."""
    x = np.asarray(x_mm, float)
    f = np.asarray(f_n, float)
    n = len(x)
    if n < 2 * MIN_SIDE + 2:
        return None
    one = np.ones(n)
    _, sse_quad = _lstsq_sse(np.column_stack([one, x, x**2]), f)
    best = None
    for b in range(MIN_SIDE, n - MIN_SIDE):
        hinge = np.maximum(x - x[b], 0.0)
        coef, sse = _lstsq_sse(np.column_stack([one, x, hinge]), f)
        if best is None or sse < best[1]:
            best = (b, sse, coef)
    b, sse_h, coef = best
    k1, k2 = coef[1], coef[2]
    if not (k1 > 0 and k1 + k2 >= MIN_RATIO * k1):
        return None
    d2 = np.diff(f, 2)
    noise = max(float(np.median(np.abs(d2 - np.median(d2)))) / 0.6745 / np.sqrt(6.0), 1e-6)
    snr = float(k2 * (x[-1] - x[b]) / noise)
    ratio = sse_quad / max(sse_h, 1e-300)
    if ratio < MIN_SSE_RATIO or snr < MIN_SNR:
        return None
    return Onset(float(x[b]), float(k1), float(k1 + k2), float(ratio), snr)
