"""Refinements of the selected model's forms (step 4b of :mod:`.workflow`).

Some parameters change an effect's form in a way the data can seldom resolve: a flare's
``size_exponent`` says whether its excess is one collar for every cane (0) or a share of each
cane's own diameter (1); among canes of one size the two are the same flare. Such a parameter
(``Parameter.refined``) is held at its null while effects are selected, so its freedom never helps
an effect be named, and freed afterwards, on the selected model, where the data ask for it:

* the model refitted with the parameter free must beat the selected one by a likelihood ratio
  significant at :data:`REFINE_ALPHA` (against chi-square with one degree of freedom: the null
  lies on the parameter's bound, where the exact law is half that, so the test is conservative),
* and predict the canes it leaves out better (the summed held-out -log density of
  leave-one-cane-out, :func:`.fit.cross_validate`).

An adopted refinement is re-anchored on the baseline engine (the screen is linear) and then stands
or falls with the model: the adequacy checks judge the refined model. Why it matters: a flare that
is a share of the diameter, fitted with one excess for canes whose bases range from 15 to 30 mm,
leaves the thick canes too soft and the thin too stiff, a trend with stiffness between canes that
the adequacy check (rightly) calls a wrong scaling (the thirteenth independent generator's ds05,
docs/discovery.md). The exponent is bounded to [0, 1]: a support or a stake below the pushes, which
the flare can mimic, stiffens the thin canes more, the other way (q < 0), so it cannot help there.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any, Callable

import numpy as np
from scipy import stats

from ..model.effects import EFFECTS
from .fit import Candidate, CVResult, cross_validate, fit_candidate
from .screenset import Anchored

#: significance of a refinement's likelihood ratio (as strict as the per-cane scope's test)
REFINE_ALPHA = 0.01


class JsonRecord:
    """A dataclass record as ``discovery.json`` holds it (a value not finite as null: strict JSON)."""

    def to_dict(self) -> dict[str, Any]:
        return {k: (None if isinstance(v, float) and not math.isfinite(v) else v)
                for k, v in asdict(self).items()}  # type: ignore[call-overload]


@dataclass
class Refinement(JsonRecord):
    """One refinement tried on the selected model."""

    effect: str
    parameter: str
    #: the refitted value (on the selected model's anchor, before any re-anchoring)
    value: float
    #: 2 (nll selected - nll refined); nll includes the calipers' penalty of a diameter effect, and the
    #: selected model's is the better of its fit and its refit from the refined optimum
    lr: float
    p: float
    #: summed held-out -log density over the canes: selected model, refined model
    cv_loss_selected: float
    cv_loss_refined: float
    adopted: bool
    #: the value after re-anchoring (NaN where not adopted)
    value_adopted: float = math.nan

    def note(self) -> str:
        head = (f"{self.effect}'s {self.parameter} (held at {EFFECTS[self.effect].parameters[self.parameter].null:g} "
                f"in the selection) fitted {self.value:.3g}: likelihood ratio {self.lr:.2f}, p = {self.p:.2g} "
                f"against {REFINE_ALPHA}")
        if math.isfinite(self.cv_loss_refined):  # cross-validated only where the ratio is significant
            head += f"; held-out -log density {self.cv_loss_selected:.2f} -> {self.cv_loss_refined:.2f}"
        if self.adopted:
            return head + f"; adopted ({self.parameter} = {self.value_adopted:.3g} re-anchored on the engine)"
        return head + "; not adopted"


def refinable(cand: Candidate) -> list[tuple[str, str]]:
    """The refinement parameters of ``cand``'s effects that it does not fit yet."""
    return [(n, p) for n in cand.names for p, par in EFFECTS[n].parameters.items()
            if par.refined and (n, p) not in cand.refined]


def refine(cv_cur: CVResult, at: Anchored, lkf: np.ndarray,
           reanchor: Callable[[Anchored, CVResult], tuple[Anchored, CVResult]],
           alpha: float = REFINE_ALPHA) -> tuple[CVResult, Anchored, list[Refinement]]:
    """Try each refinement parameter of the selected model in turn (see the module docstring).

    Parameters
    ----------
    cv_cur, at
        The selected model, cross-validated on the screen anchored at it.
    lkf
        The field's ln k, in the screen's trial order.
    reanchor
        Runs the baseline engine with a model and refits on the new anchor (``.engine_runs.reanchor``).

    Returns
    -------
    (cv, at, refinements)
        The model (refined where adopted) and its anchor, and one record per parameter tried.
    """
    out: list[Refinement] = []
    for n, p in refinable(cv_cur.fit.candidate):
        cand = Candidate.of(cv_cur.fit.candidate.names, cv_cur.fit.candidate.refined + ((n, p),))
        values = {(sp.name, k): v for sp in cv_cur.fit.specs for k, v in sp.params}
        values[(n, p)] = EFFECTS[n].parameters[p].null
        fit = fit_candidate(cand, at, lkf, x0=cand.to_internal(values))
        # the null refitted from the refined optimum too: a better basin of the other parameters that
        # the refined fit found is not the refinement's credit
        sel = cv_cur.fit.candidate
        back = fit_candidate(sel, at, lkf, x0=sel.to_internal({(sp.name, k): v for sp in fit.specs
                                                               for k, v in sp.params if (sp.name, k) in sel.free}))
        nll0 = min(cv_cur.fit.nll, back.nll)
        lr = max(0.0, 2.0 * (nll0 - fit.nll))
        pv = float(stats.chi2.sf(lr, 1))
        value = dict(next(sp for sp in fit.specs if sp.name == n).params)[p]
        cv = cross_validate(cand, at, lkf, full=fit) if pv < alpha else None
        loss0 = float(sum(cv_cur.loss.values()))
        loss1 = float(sum(cv.loss.values())) if cv is not None else math.nan
        rec = Refinement(n, p, float(value), float(lr), pv, loss0, loss1, bool(cv is not None and loss1 < loss0))
        if rec.adopted:
            at, cv_cur = reanchor(at, cv)
            rec.value_adopted = float(dict(next(sp for sp in cv_cur.fit.specs if sp.name == n).params)[p])
        out.append(rec)
    return cv_cur, at, out
