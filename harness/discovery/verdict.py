"""Is the fitted model an explanation? Step 5 of :mod:`.workflow`: the structure table, the
adequacy checks that withhold names (:data:`INADEQUATE`) and the warnings that only flag.

:func:`judge` runs them on the selection's model and returns a :class:`Verdict`: the names that
stand, the library's best account where they are withheld (``partial``), the checks'
figures and whether the result is ``unexplained``.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np
import pandas as pd

from ..model.effects import EFFECTS
from .adequacy import geometry_draws, level_trend_geometry, within_dispersion, within_trend_geometry
from .checks_text import failure_reasons, fitted_entry
from .fit import Candidate, cross_validate
from .nulls import bounds_reached
from .screenset import Anchored
from .structure import level_trend, structure_flags, structure_tests

STRUCTURE_ALPHA = 0.01  # Bonferroni-adjusted p below which residual structure counts as unexplained
#: the unnamed effects that may take a trend along the canes and keep the names standing
#: (:func:`within_taken_by`): the exemption is for a taper fuller or leaner below the calipers than
#: their line, which is a flare. A spring or a scale that the selection did not name taking the
#: trend is not that story: a fifth generator's trellis tie above the top push (an effect outside
#: the library, the top pushes stiffened most) was taken by a rig spring of 2445 N/m and kept a
#: misnamed modulus scale of 1.70 standing; no other stored result of the self-test (seeds 7-9) or
#: of the fourth and fifth generators had a taker (``tests/scripts/verdict_paths.py``).
WITHIN_TAKERS = ("base_flare",)
#: level of the adequacy check (:func:`.adequacy.level_trend_geometry`: held-out residual against the
#: model's held-out stiffness level, between canes, against a null that carries the caliper-fit
#: geometry's shared error), one pre-declared test beside the structure table's family. Failing it
#: withholds names the selection found significant, a strong claim, so it asks for the observed r
#: to lie beyond every one of the null's 2000 draws (p = 2 / 2001 < 0.002). At 0.01 it withheld a
#: correctly fitted root spring (k_root 16.5 for 15, p = 0.005) in the test suite's hidden-root set;
#: the self-test's out-of-library sets that fail it all give p = 0.001 (docs/discovery.md).
ADEQUACY_ALPHA = 0.002
#: level of the same trend against plain cane permutations (:func:`.structure.level_trend`), a
#: warning that sets ``unexplained`` and withholds nothing. It ignores the shared geometry error
#: and so flags more often than its level; at the check's own 0.002 it flags none of the
#: self-test's nulls, at 0.01 one in ten of the sets where nothing outside the library is hidden.
TREND_WARNING_ALPHA = ADEQUACY_ALPHA
#: the within-cane spread of the held-out residual may be at most this many times the caliper
#: line's own (:func:`.adequacy.within_dispersion`): pooled over every cane, the nulls and library
#: effects of three generators and the real field trials reached 5.6 (a sliding pitched probe;
#: 4.1 with none), a lateral support 20.6. Since the pooled spreads leave out the tenth of canes
#: that scatter most (:data:`.adequacy.TRIM_SHARE`), the independent generator's nulls and library
#: sets reach 3.6 (5.0 with the sliding probe), the real trials 2.8, the lateral support 18.7
WITHIN_EXCESS = 8.0
#: ...and at least this much in ln k: a cane's pushes scatter a few per cent for reasons no
#: geometry carries (the probe's pitch jitter, a push height's click), and where a soft root
#: takes most of the compliance the caliper line's share all but vanishes: the self-test's
#: root + pitch pair (seed 7, set 37), both named right, spread 0.054 at 9.8 times the line's
WITHIN_FLOOR = 0.10
#: why names are withheld (the adequacy checks), in every output that says so
INADEQUATE = ("does not scale across canes, share the stiffness along a cane (in trend or in spread), or bend the "
              "traces as the data do, or needs a value at the end of a parameter's physical range")
#: what sets ``unexplained``, as the CLI and the report say it
UNEXPLAINED_WHY = (f"residual structure, a model that {INADEQUATE}, an effect that passed the selection but not its "
                   f"interval, or a best fit too small to name")


@dataclass
class Verdict:
    """What the checks make of the fitted model (:func:`judge`)."""

    structure_before: pd.DataFrame
    structure_after: pd.DataFrame
    adequacy: dict[str, Any]
    unexplained: bool
    named: list[dict[str, Any]]  # the names that stand (per-trial ones always do)
    partial: list[dict[str, Any]] = field(default_factory=list)  # global names withheld


def judge(F: pd.DataFrame, r_before: np.ndarray, r_after: np.ndarray, lkf: np.ndarray, baseline: Anchored,
          anchor: Anchored, final: Any, current: tuple[str, ...],
          candidates: tuple[str, ...], unsupported: list[dict[str, Any]], named: list[dict[str, Any]],
          diameter_factor: float, shape_of: Callable[[tuple, float], dict[str, Any]], notes: list[str],
          timing: dict[str, float], seed: int = 0) -> Verdict:
    """Run the checks on the selection's model (``final``, cross-validated; ``current`` its effects).

    ``F`` holds the scored trials (``cane``, ``height_m``, the residuals, ``log_k_base`` and
    ``log_k_model_cv``: the levels the structure table's level row takes before and after);
    ``r_before``/``r_after`` are the baseline's and the model's held-out residuals; ``baseline``
    the screen at the baseline's ln k, ``anchor`` at the last anchor (:class:`.screenset.Anchored`).
    ``shape_of(specs, alpha)`` runs the traces' shape check of a model on the engine at level
    ``alpha`` (:func:`.engine_runs.model_shape_check`).
    Notes are appended to ``notes``, durations to ``timing``.
    """
    # the model's ln k under the caliper lines' own errors (.adequacy), for the structure table's
    # within-cane rows and the adequacy checks
    canes_f = F.cane.to_numpy()
    g_before = geometry_draws(baseline, (), diameter_factor, seed=seed)
    g_after = geometry_draws(anchor, tuple(final.fit.specs), diameter_factor, seed=seed)
    # -- structure before and after: within canes against the same geometry null as the checks
    sb = structure_tests(F, "r_before", seed=seed, geometry=g_before, level_col="log_k_base")
    sa = structure_tests(F, "r_after_cv", seed=seed, geometry=g_after, level_col="log_k_model_cv")
    structured = bool(len(structure_flags(sa, STRUCTURE_ALPHA)))  # the curvature row reports only
    # adequacy: a model that fits the mean but not how stiffness scales across canes is incomplete,
    # whatever it named. The structure table's Bonferroni family (12 tests) is too wide to see this
    # one pre-declared trend (the table's own level row is the same r, judged at 0.01 over 12).
    # The null carries the caliper line's error, which level and residual share (.adequacy).
    adequacy = {"test": "between-cane correlation of the held-out residual with the model's ln k, against "
                        "the caliper-fit geometry's shared error (parametric bootstrap, two-sided)",
                "alpha": ADEQUACY_ALPHA,
                "before": level_trend_geometry(canes_f, r_before, baseline.log_k, g_before, seed=seed),
                "after_cv": level_trend_geometry(canes_f, r_after, F.log_k_model_cv.to_numpy(float), g_after,
                                                 seed=seed)}
    trend_fails = bool(adequacy["after_cv"]["p"] < ADEQUACY_ALPHA)
    # within canes: the held-out residual must not trend with push height along a cane (each cane's
    # own modulus drops out of these contrasts; an effect acting on part of a cane shows here)
    height = F.height_m.to_numpy(float)
    adequacy["within_before"] = within_trend_geometry(canes_f, r_before, height, g_before, seed=seed)
    adequacy["within_after_cv"] = within_trend_geometry(canes_f, r_after, height, g_after, seed=seed)
    within_fails = bool(adequacy["within_after_cv"]["p"] < ADEQUACY_ALPHA)
    # and not scatter between a cane's own pushes far beyond what the geometry's error can: an
    # effect whose pattern along the cane changes from cane to cane cancels in the trend
    adequacy["within_dispersion"] = within_dispersion(adequacy["within_after_cv"], WITHIN_EXCESS, WITHIN_FLOOR)
    dispersion_fails = adequacy["within_dispersion"]["fails"]
    # the traces' shape: a model that predicts they bend (a pitched probe's tension) where they do
    # not is not their explanation, whatever it fits of the stiffness (.shape)
    t_s = time.perf_counter()
    adequacy["shape"] = shape_of(final.fit.specs, ADEQUACY_ALPHA)
    timing["shape_s"] = time.perf_counter() - t_s
    shape_p = adequacy["shape"].get("p")
    shape_fails = shape_p is not None and shape_p < ADEQUACY_ALPHA
    # and the traces must not stiffen or soften over the push, on average, beyond what the model does
    lv = adequacy["shape"].get("level") or {}
    shape_level_fails = bool(lv.get("fails"))
    if lv.get("p_floor") is not None and lv["p_floor"] >= ADEQUACY_ALPHA:
        notes.append(f"mean-shape check: {lv['n_canes']} canes' sign flips cannot give p below {lv['p_floor']:.2g}, "
                     f"so it cannot flag at {ADEQUACY_ALPHA}")
    if shape_p is not None and adequacy["shape"]["p_floor"] >= ADEQUACY_ALPHA:
        notes.append(f"shape check: {adequacy['shape']['n_canes']} canes' sign flips cannot give p below "
                     f"{adequacy['shape']['p_floor']:.2g}, so it cannot withhold a name at {ADEQUACY_ALPHA}")
    # a fit pressed against the end of a parameter's physical range (a modulus five times the stated
    # one): the library's effect takes what it can of something else; nothing named accounts for it
    adequacy["at_edge"] = at_physical_edge(tuple(final.fit.specs))
    edge_fails = bool(adequacy["at_edge"])
    if within_fails and not (trend_fails or shape_fails or dispersion_fails or shape_level_fails
                             or edge_fails) and current:
        # the trend along the canes would be the only reason to withhold the names: if an unnamed
        # flare takes it, it is a taper fuller or leaner below the calipers than their line, below
        # the naming rules, not an effect outside the library (WITHIN_TAKERS)
        t_w = time.perf_counter()
        taken, tried = within_taken_by(within_takers(candidates, current, unsupported),
                                       current, anchor, lkf, canes_f, height, diameter_factor,
                                       adequacy["within_after_cv"]["n_trials"], seed, final.fit.candidate.refined)
        adequacy["within_taken_by"], adequacy["within_tried"] = taken, tried
        timing["within_taken_s"] = time.perf_counter() - t_w
        within_fails = taken is None
    adequacy["failed"] = [name for name, fails in (("edge", edge_fails), ("trend", trend_fails),
                                                  ("within", within_fails),
                                                  ("dispersion", dispersion_fails), ("shape", shape_fails),
                                                  ("shape_level", shape_level_fails)) if fails]
    adequacy["inadequate"] = bool(adequacy["failed"])
    # the same trend against a plain cane permutation, blind to the shared geometry error and so
    # biased toward finding one: it names nothing and withholds nothing, it only warns
    # (``unexplained``) that the model may be incomplete
    adequacy["after_cv_permutation"] = level_trend(F, "r_after_cv", "log_k_model_cv", seed=seed)
    trend_warning = adequacy["after_cv_permutation"]["p"] < TREND_WARNING_ALPHA
    # a trend along the canes that an unnamed effect takes still flags: structure remains; so does
    # an effect that passed the selection (the residuals lean its way, significantly) but whose
    # interval reaches no effect: what it took is not explained by anything named
    unexplained = (structured or adequacy["inadequate"] or trend_warning or bool(adequacy.get("within_taken_by"))
                   or bool(unsupported))
    partial: list[dict[str, Any]] = []
    if adequacy["inadequate"]:
        partial = [n for n in named if fitted_entry(n)]
        named = [n for n in named if not fitted_entry(n)]
        what = ", ".join(n["effect"] for n in partial) or "the baseline"
        why = failure_reasons(adequacy)
        notes.append(f"the model ({what}) " + "; and it ".join(why) + ": an effect outside the library, or one the "
                     "library has with the wrong scaling or shape, remains"
                     + (f"; what the library fitted ({what}) took the part of it that it could and is not named: "
                        f"it is reported as partial, with model_partial.yaml" if partial else ""))
    if adequacy.get("within_taken_by") and not adequacy["inadequate"]:
        w, tk = adequacy["within_after_cv"], adequacy["within_taken_by"]
        notes.append(f"within canes the held-out residual {'falls' if w['r'] < 0 else 'rises'} with push height "
                     f"(r = {w['r']:.2f}, p = {w['p']:.2g} < {ADEQUACY_ALPHA}), but with {tk['effect']} ("
                     + ", ".join(f"{k} = {v:.4g}" for k, v in tk["params"].items())
                     + f") added beside the named effects it does not (r = {tk['r']:.2f}, p = {tk['p']:.2g}): a "
                     f"pattern the library can take, below its naming rules; the names stand, flagged unexplained"
                     + (f" ({', '.join(tk['at_bound'])} at its search bound: a fuller base than the calipers' line, "
                        f"or a weak zone between the lower pushes, which three pushes a cane do not tell apart)"
                        if tk["at_bound"] else ""))
    if trend_warning and not adequacy["inadequate"]:
        a = adequacy["after_cv_permutation"]
        notes.append(f"the held-out residual {'falls' if a['r'] < 0 else 'rises'} with the model's stiffness level "
                     f"between canes (r = {a['r']:.2f}, cane-permutation p = {a['p']:.2g}) but no more than the "
                     f"calipers' own error can make it (p = {adequacy['after_cv']['p']:.2g} against that null): the "
                     f"names stand; the model may still be incomplete")
    return Verdict(sb, sa, adequacy, unexplained, named, partial)


def at_physical_edge(specs: tuple[Any, ...]) -> list[dict[str, Any]]:
    """The fitted parameters pressed against the end of their physical range away from their null
    (:attr:`~canebench.model.effects.Parameter.physical_bounds`): ``effect``, ``parameter``,
    ``value``, ``unit`` and the range (``low``, ``high``), one dict each."""
    out = []
    for spec in specs:
        pars = EFFECTS[spec.name].parameters
        for k, v, at_null in bounds_reached(spec):
            if pars[k].physical_bounds and not at_null:
                out.append({"effect": spec.name, "parameter": k, "value": v, "unit": pars[k].unit,
                            "low": pars[k].low, "high": pars[k].high})
    return out


def within_after(cv: Any, at: Anchored, canes: np.ndarray, height: np.ndarray, factor: float,
                 seed: int) -> dict[str, Any]:
    """The within-cane check of a cross-validated model: its held-out residual against push height,
    with the model's own geometry draws in the null (as ``adequacy.within_after_cv``)."""
    g = geometry_draws(at, tuple(cv.fit.specs), factor, seed=seed)
    return within_trend_geometry(canes, cv.residual, height, g, seed=seed)


def within_takers(candidates: tuple[str, ...], current: tuple[str, ...],
                  unsupported: list[dict[str, Any]]) -> tuple[str, ...]:
    """The candidates :func:`within_taken_by` tries: unnamed, in :data:`WITHIN_TAKERS`, and not just
    refused for an interval that reaches no effect (it would be named back by the side door)."""
    refused = {u["effect"] for u in unsupported}
    return tuple(c for c in candidates if c not in current and c in WITHIN_TAKERS and c not in refused)


def within_taken_by(others: tuple[str, ...], current: tuple[str, ...], at: Anchored, lkf: np.ndarray,
                    canes: np.ndarray, height: np.ndarray, factor: float, n_trials: int,
                    seed: int, refined: tuple[tuple[str, str], ...] = ()
                    ) -> tuple[dict[str, Any] | None, list[dict[str, Any]]]:
    """The unnamed library effect that, added to ``current`` (with the refinements it was given,
    ``refined``: :mod:`.refine`), leaves no trend along the canes.

    The within-cane check's null carries the caliper line's random error, not the taper's shape
    below the lowest caliper: three calipers near the push points cannot see a power-law taper's
    curvature, which extrapolated half a metre down makes the base millimetres fuller (or
    leaner) than their line and the lower pushes stiffer (softer) than the model; an independent
    generator's tapers (exponents 0.4-2.2, mostly convex) tripped it and withheld a correct
    modulus scale. That is the library's flare below its naming rules. Each candidate is fitted
    beside the named ones (out of sample) and the check rerun with the augmented model's own
    geometry draws; it takes the trend if the check passes on the same trials with a finite r
    and the candidate does something (no parameter at the search bound nearest its null: a
    spring at its stiffest, no flare). A parameter at its other bound is recorded
    (``at_bound``): the flare that takes a broad taper misfit on thick canes can be pressed to its
    25 mm limit, and so can the one that takes a weak zone between the push points. Three pushes
    a cane do not tell a moderate weak zone from a fuller base; a strong one is taken by nothing.

    Returns
    -------
    (dict or None, list of dict)
        The taker with the largest p (``effect``, ``params``, ``at_bound``, ``r``, ``p``), None if
        none; and every candidate tried, with why it did not take the trend.
    """
    best: dict[str, Any] | None = None
    tried: list[dict[str, Any]] = []
    for c in others:
        cv = cross_validate(Candidate.of(current + (c,), refined), at, lkf)
        spec = next(s for s in cv.fit.specs if s.name == c)
        row: dict[str, Any] = {"effect": c, "params": dict(spec.params), "r": math.nan, "p": math.nan}
        hits = bounds_reached(spec)
        row["at_bound"] = [k for k, _, _ in hits]
        idle = [k for k, _, at_null in hits if at_null]
        if idle:
            row["why_not"] = f"does nothing: {', '.join(idle)} at its bound beside the null"
        else:
            w = within_after(cv, at, canes, height, factor, seed)
            row.update(r=w["r"], p=w["p"])
            if w["n_trials"] != n_trials or not np.isfinite(w["r"]):
                row["why_not"] = f"scored {w['n_trials']} trials of {n_trials}"
            elif w["p"] < ADEQUACY_ALPHA:
                row["why_not"] = "the trend remains"
            elif best is None or w["p"] > best["p"]:
                best = {k: row[k] for k in ("effect", "params", "at_bound", "r", "p")}
        tried.append(row)
    return best, tried
