"""Field stiffness extraction from a rig trial (reading: :mod:`canebench.data.rig`).

Rig CSV columns (see ../shared/field-data/README.md): ``Iteration``,
``Time Stamp`` (16-bit ms counter that wraps), ``Load Cell Reading (gf)``
(compressive positive, with a tare offset), ``Displacement (mm)`` (absolute
probe position, 0.5 mm per sample), ``Height (mm)``.

Extraction, step by step (each exists for a reason):

1. Validate: every column present and numeric; a NaN or a displacement that
   goes back is an error naming the file, row and column (a position logged
   twice is merged, its readings averaged, with a warning).
2. Time stamps are *unwrapped* (add 65536 at each negative jump) only to
   report the trial's duration; physics uses displacement, which the stepper
   sets exactly, so a wrapped counter cannot corrupt the slope.
3. Displacement is made relative to the first sample: the rig logs an
   absolute carriage position whose origin means nothing for the cane.
4. Contact onset: the probe starts short of the cane, so the record begins
   with a flat stretch (tare plus noise). A hinge model (flat, then a line)
   is fitted over the early part of the record; its knee is the onset. Fitting
   the flat part as part of the slope would lower the stiffness.
5. Tare: the level of the flat stretch is subtracted, so forces are contact
   forces; with no flat stretch (contact from the first sample) the first
   reading is taken as zero force and the trial is flagged.
6. Force limit: samples at or beyond 1000 gf (the rig's stop) are dropped;
   the load cell and the rig's stop make them unreliable.
7. Slope: least squares of force (N) on displacement (mm) from onset on,
   over the whole contact or over the first ``window_mm`` of it (the
   protocol's ``fit_window_mm``; the simulation is fitted over the same
   window). R^2, the residual RMS, the slope's standard error and a 95 %
   bootstrap interval (AR(1) sieve on the residuals, seeded) are kept; the first-10-mm slope
   is always reported beside it, since on many real trials it differs from
   the whole-push slope by more than 25 %.
8. Usability: no slope is reported when there are fewer than 5 contact
   samples, the *tared* reading never exceeds 20 gf, the slope is not
   positive, or R^2 < 0.8. Every such trial carries its reason.

How this differs from the rig's own analysis: the rig's script applies its
20 gf threshold to the raw, untared reading. A trial whose load cell sat at
-55 gf before contact (bush 4 cane 1 trial 1) then never "exceeds" 20 gf and
was dropped although its contact force rises cleanly (tared slope 0.0093 N/mm,
R^2 0.98, the paper's lowest stiffness). Here thresholds apply to contact
forces, after taring.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..data.rig import RigTrial
from ..units import GF_TO_N
from .fit import bootstrap_slope_interval, fit_line, window

FORCE_LIMIT_GF = 1000.0
RIG_FIT_THRESHOLD_GF = 20.0
MIN_CONTACT_SAMPLES = 5
MIN_R2 = 0.8
ONSET_SEARCH_GF = 150.0  # hinge fitted over the record until the reading rises this much...
ONSET_LINE_SAMPLES = 3  # ...and this many samples more


@dataclass
class FieldFit:
    """Field stiffness of one trial and how it was obtained."""

    k_n_per_mm: float  # NaN when unusable
    r2: float
    rms_n: float
    n_contact: int
    onset_mm: float
    tare_gf: float
    usable: bool
    reason: str = ""
    #: why it is unusable, as a code (``reason`` says it in words): "" when usable, else one of
    #: "contact_samples", "window_samples", "no_rise", "no_slope", "poor_fit", "no_fit"
    fault: str = ""
    flags: list[str] = field(default_factory=list)
    displacement_mm: np.ndarray | None = None  # contact samples, from onset
    force_n: np.ndarray | None = None
    se: float = float("nan")  # standard error of the slope (N/mm)
    ci_low: float = float("nan")  # 95 % bootstrap interval (N/mm), AR(1) sieve
    ci_high: float = float("nan")
    window_mm: float | None = None  # fit window from onset (None: whole contact)
    k_first_10mm: float = float("nan")  # slope over the first 10 mm of contact, always

    @property
    def only_poorly_linear(self) -> bool:
        """Unusable only because a straight line fits it poorly: the force rose, with a positive
        slope, over enough contact samples. An elbow (a second body engaging) does this by itself."""
        return self.fault == "poor_fit"

    @property
    def rises(self) -> bool:
        """The contact force rose with a positive slope over enough samples: usable, or unusable
        only for its line's fit (the traces an obstruction elbow is looked for in)."""
        return self.usable or self.only_poorly_linear

    @property
    def n_steps(self) -> int:
        """Protocol steps the simulation may run to cover the same push."""
        return self.n_contact


def _hinge_onset(x: np.ndarray, y: np.ndarray) -> tuple[int, float]:
    """Index of the knee and the flat level of the best flat-then-line fit."""
    best = (math.inf, 0, float(y[0]))
    for i0 in range(0, max(1, len(x) - 3)):
        flat = y[: i0 + 1]
        c = float(flat.mean()) if i0 >= 2 else float(y[0])
        xr, yr = x[i0:] - x[i0], y[i0:] - c
        b = float((xr @ yr) / (xr @ xr)) if xr @ xr > 0 else 0.0
        sse = float(((flat - c) ** 2).sum() + ((yr - b * xr) ** 2).sum())
        if sse < best[0]:
            best = (sse, i0, c)
    return best[1], best[2]


def contact_samples(f_gf: np.ndarray, i0: int) -> np.ndarray:
    """Mask of a record's contact samples: from index ``i0`` up to the rig's stop (the first
    reading at or beyond :data:`FORCE_LIMIT_GF`, which the load cell and stop make unreliable)."""
    f = np.asarray(f_gf, float)
    keep = np.arange(len(f)) >= i0
    over = f >= FORCE_LIMIT_GF
    if over.any():
        keep &= np.arange(len(f)) < int(np.argmax(over))
    return keep


def extract_field_stiffness(trial: RigTrial, window_mm: float | None = None, n_boot: int = 1000,
                            seed: int = 0, max_travel_mm: float | None = None) -> FieldFit:
    """Field stiffness (N/mm) of one trial; see the module docstring for the steps.

    Parameters
    ----------
    window_mm : float, optional
        Fit over the first ``window_mm`` of contact only (default: all of it).
    n_boot, seed : int
        Bootstrap replicates and generator seed of the 95 % interval.
    max_travel_mm : float, optional
        The push a simulation makes: contact running past it is fitted over its first
        ``max_travel_mm`` only (flagged), so both sides fit the same push.
    """
    x, f = trial.displacement_mm, trial.force_gf
    flags: list[str] = []
    # hinge over the early record only: later curvature must not move the knee
    rise = f - np.minimum.accumulate(f)
    end = int(np.argmax(rise > ONSET_SEARCH_GF)) if np.any(rise > ONSET_SEARCH_GF) else len(f)
    # the line part needs a few samples past the rise: a stiff cane passes 150 gf on its
    # first contact sample, and a one-point line would let the knee slide into the flat part
    end = max(min(len(f), end + ONSET_LINE_SAMPLES), min(len(f), 8))
    i0, level = _hinge_onset(x[:end], f[:end])
    if i0 < 2:
        flags.append("no pre-contact baseline: first reading taken as zero force")
        level = float(f[0])
        i0 = 0
    tare = level
    keep = contact_samples(f, i0)
    if np.any(f >= FORCE_LIMIT_GF):
        flags.append("force limit reached")
    xs, fs = x[keep] - x[i0], (f[keep] - tare) * GF_TO_N
    drops = np.diff(f[keep]) < -30.0
    if drops.any():
        flags.append(f"{int(drops.sum())} force drop(s) > 30 gf (slip or obstruction)")
    if (max_travel_mm is not None and (window_mm is None or window_mm > max_travel_mm) and len(xs)
            and float(np.max(xs)) > max_travel_mm):
        window_mm = max_travel_mm
        flags.append(f"contact longer than the simulated push: fitted over its first {max_travel_mm:g} mm")
    w = window(xs, window_mm)
    fit = fit_line(xs[w], fs[w])
    f10 = fit_line(xs[window(xs, 10.0)], fs[window(xs, 10.0)])
    base = dict(n_contact=int(keep.sum()), onset_mm=float(x[i0]), tare_gf=float(tare), flags=flags,
                displacement_mm=xs, force_n=fs, window_mm=window_mm,
                k_first_10mm=f10.slope if f10 is not None else float("nan"))
    reason, fault = "", ""
    if keep.sum() < MIN_CONTACT_SAMPLES:
        reason, fault = f"only {int(keep.sum())} contact samples (< {MIN_CONTACT_SAMPLES})", "contact_samples"
    elif w.sum() < MIN_CONTACT_SAMPLES:
        reason, fault = (f"only {int(w.sum())} samples in the {window_mm:g} mm fit window (< {MIN_CONTACT_SAMPLES})",
                         "window_samples")
    elif (f[keep] - tare).max() <= RIG_FIT_THRESHOLD_GF:
        reason, fault = f"contact force never exceeds {RIG_FIT_THRESHOLD_GF:g} gf after taring", "no_rise"
    elif fit is None or fit.slope <= 0:
        reason, fault = "no positive slope", "no_slope"
    elif fit.r2 < MIN_R2:
        reason, fault = f"poor linear fit (R^2 = {fit.r2:.2f} < {MIN_R2})", "poor_fit"
    if fit is None:
        return FieldFit(float("nan"), float("nan"), float("nan"), usable=False, reason=reason or "no fit",
                        fault=fault or "no_fit", **base)
    rms = float(np.sqrt(np.mean((fs[w] - fit.intercept - fit.slope * xs[w]) ** 2)))
    lo, hi = bootstrap_slope_interval(xs[w], fs[w], n_boot, seed) if not reason else (float("nan"), float("nan"))
    return FieldFit(fit.slope if not reason else float("nan"), fit.r2, rms, usable=not reason, reason=reason,
                    fault=fault, se=fit.se, ci_low=lo, ci_high=hi, **base)
