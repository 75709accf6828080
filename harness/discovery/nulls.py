"""Where an effect does nothing: its parameters' no-effect values against the search bounds.

A scale of 1 and a pitch of 0 lie inside their bounds; a spring's null (infinitely stiff) lies
beyond its stiffest bound, which stands for it; a flare's null (no excess) is its lower bound.
Used by the interval rule (:func:`.selection.drop_unsupported`) and by the within-cane check's
search for an unnamed effect that takes a trend (:func:`.verdict.within_taken_by`).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..model.effects import EFFECTS, EffectSpec

#: a parameter's interval by (effect, parameter), as :func:`.fit.bootstrap_ci` returns them
Intervals = dict[tuple[str, str], tuple[float, float]]


def at_bound(v: float, bound: float) -> bool:
    """``v`` equals ``bound`` up to the optimizer's rounding."""
    return bool(np.isclose(v, bound, rtol=1e-6, atol=1e-9))


def null_bound(p: Any) -> float:
    """:meth:`~canebench.model.effects.Parameter.null_bound` of ``p``."""
    return p.null_bound()


def bounds_reached(spec: EffectSpec) -> list[tuple[str, float, bool]]:
    """The parameters of ``spec`` fitted at a search bound: ``(parameter, value, at_null)``, where
    ``at_null`` says the bound is the one at which the parameter does nothing (:func:`null_bound`)."""
    pars = EFFECTS[spec.name].parameters
    out = []
    for k, v in spec.params:
        par = pars.get(k)
        if par is None:
            continue
        nb = null_bound(par)
        for b in (par.low, par.high):
            if at_bound(v, b):
                out.append((k, float(v), bool(math.isfinite(nb) and at_bound(b, nb))))
    return out


def covers_null(spec: EffectSpec, ci: Intervals) -> list[str]:
    """The parameters of ``spec`` that switch the effect off and whose interval in ``ci`` reaches
    their null: the value itself where it lies within the search bounds, else the bound on its
    side (a spring's stiffest bound stands for infinitely stiff)."""
    out = []
    for p, _ in spec.params:
        par = EFFECTS[spec.name].parameters[p]
        if not par.switches_off or (spec.name, p) not in ci or math.isnan(par.null):
            continue
        lo, hi = ci[(spec.name, p)]
        side = null_bound(par)
        if math.isnan(side):  # inside the bounds
            reaches = lo <= par.null <= hi
        elif side == par.high:
            reaches = hi >= par.high or at_bound(hi, par.high)
        else:
            reaches = lo <= par.low or at_bound(lo, par.low)
        if reaches:
            out.append(p)
    return out


def ci_of(spec: EffectSpec, ci: Intervals) -> dict[str, list[float]]:
    """``spec``'s intervals in ``ci``, by parameter (those drawn)."""
    return {p: list(ci[(spec.name, p)]) for p, _ in spec.params if (spec.name, p) in ci}
