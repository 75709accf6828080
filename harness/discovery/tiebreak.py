"""A close call between a modulus scale and a probe pitch, decided by the traces' shape.

Both move every trial's stiffness by nearly the same factor (a pitch theta by about -2 ln cos
theta, on canes of any geometry much alike), so the selection's BIC can barely tell them apart: a
close call (:data:`.selection.CLOSE_BIC`). The traces can. A pitched probe pulls (pushed up) or
compresses (down) the cane along its axis, and the trace stiffens or softens over the push as it
bends; a modulus scale leaves its shape alone (:mod:`.shape`: no other library effect changes a
trace's shape). So where the selection chose one of the two by less than ``CLOSE_BIC`` over the
other, each model is run on the baseline engine and the traces' mean stiffening beyond it
(:func:`.shape.shape_level`, averaged over the canes) is compared: the rival is named instead when
its model leaves the traces at least :data:`SHAPE_TIE_MARGIN` nearer to its own shape, and its
interval (drawn by the caller) does not reach no effect.

The fourteenth independent generator's +38 degree pitch (docs/independent-generator-14, ds05) was
named a modulus scale of 1.72 by a BIC 0.26 lower, while the traces stiffened 0.184 beyond the
scale's model on average over 14 canes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from .fit import Candidate, CVResult, cross_validate
from .refine import JsonRecord
from .screenset import Anchored

#: the two effects a shape decides between (the only library effect that changes a trace's shape
#: is the pitch; its look-alike in stiffness is the scale)
SHAPE_PAIR = frozenset({"modulus_scale", "probe_misalignment"})
#: how much nearer zero (in stiffening over the push, dimensionless) the rival's mean excess must
#: lie: twice the standard error of a mean over 14 canes whose means scatter 0.15 (the independent
#: generators' and the real trials' cane-to-cane scatter of the traces' shape is 0.1-0.2)
SHAPE_TIE_MARGIN = 0.08


@dataclass
class ShapeTie(JsonRecord):
    """One close call the traces were asked to decide."""

    chosen: str
    rival: str
    bic_gap: float
    #: the traces' mean stiffening over the push beyond each model (over the canes)
    excess_chosen: float
    excess_rival: float
    swapped: bool
    why: str = ""

    def note(self) -> str:
        head = (f"{self.chosen} won its step over {self.rival} by a BIC only {self.bic_gap:.2f} lower; the traces "
                f"stiffen over the push {self.excess_chosen:+.3f} beyond the {self.chosen} model and "
                f"{self.excess_rival:+.3f} beyond the {self.rival} model (mean over canes)")
        if self.swapped:
            return head + f": {self.rival} is named instead (a pitch changes a trace's shape; a modulus scale does not)"
        return head + f": {self.chosen} stands" + (f" ({self.why})" if self.why else "")


def close_shape_call(current: tuple[str, ...], close_calls: list[dict[str, Any]]) -> tuple[str, str, float] | None:
    """The close call between the scale and the pitch still standing in ``current``: (chosen, rival,
    BIC gap), or None."""
    for cc in close_calls:
        if len(cc["chosen"]) != 1 or cc["chosen"][0] not in current:
            continue
        for rival, gap in cc["rivals"]:
            if rival not in current and {cc["chosen"][0], rival} == SHAPE_PAIR:
                return cc["chosen"][0], rival, float(gap)
    return None


def shape_tie_break(current: tuple[str, ...], close_calls: list[dict[str, Any]], cv_cur: CVResult,
                    at: Anchored, at_empty: Anchored, lkf: np.ndarray,
                    shape_of: Callable[[tuple, float], dict[str, Any]],
                    reanchor: Callable[[Anchored, CVResult], tuple[Anchored, CVResult]],
                    alpha: float) -> tuple[tuple[str, ...], CVResult, Anchored, ShapeTie | None]:
    """Decide a close call between the scale and the pitch by the traces' shape (module docstring).

    The rival's model is fitted from the empty model's anchor (``at_empty``, where the selection
    fitted it, with the pitch table's nonlinear excess that tells a pitch up from one down) and
    re-anchored on the engine: fitted from the chosen model's anchor instead, a +38 degree pitch's
    bootstrap reached -45 (a scale's anchor is blind to the pitch's sign).

    Returns the model (the rival's in place of the chosen where the traces decide for it), its
    cross-validation and anchor, and the record (None where there was no such close call).
    """
    call = close_shape_call(current, close_calls)
    if call is None:
        return current, cv_cur, at, None
    chosen, rival, gap = call
    alt = tuple(rival if c == chosen else c for c in current)
    at_alt, cv_alt = reanchor(at_empty, cross_validate(Candidate.like(alt, cv_cur), at_empty, lkf))
    m_cur = (shape_of(tuple(cv_cur.fit.specs), alpha).get("level") or {}).get("mean")
    m_alt = (shape_of(tuple(cv_alt.fit.specs), alpha).get("level") or {}).get("mean")
    if m_cur is None or m_alt is None:
        return current, cv_cur, at, ShapeTie(chosen, rival, gap, math.nan if m_cur is None else m_cur,
                                             math.nan if m_alt is None else m_alt, False,
                                             "too few traces to compare their shapes")
    swap = abs(m_cur) - abs(m_alt) > SHAPE_TIE_MARGIN
    rec = ShapeTie(chosen, rival, gap, float(m_cur), float(m_alt), swap,
                   "" if swap else f"the {rival} model does not leave the traces {SHAPE_TIE_MARGIN:g} nearer its shape")
    return (alt, cv_alt, at_alt, rec) if swap else (current, cv_cur, at, rec)


def fold_pitch_sign(fit: Any, draws: np.ndarray) -> np.ndarray:
    """``draws`` (:func:`.fit.bootstrap_draws` of ``fit``) with each pitch draw given the fitted pitch's
    sign. Stiffness alone hardly tells a pitch up from one down (-2 ln cos theta is even), so a cane
    resample can land on the mirror branch, and the percentile interval then spans zero: on the
    fourteenth generator's +38 degree pitch, 100 draws gave [-45, 38]. Where the traces' shape decided
    for the pitch, it also fixed the sign (the model it named stiffens the traces as they do), so only
    the size is left to the resampling."""
    out = np.array(draws, float, copy=True)
    for j, (n, p) in enumerate(fit.candidate.free):
        if (n, p) == ("probe_misalignment", "angle_deg"):
            sign = math.copysign(1.0, dict(next(sp for sp in fit.specs if sp.name == n).params)[p])
            out[:, j] = sign * np.abs(out[:, j])
    return out
