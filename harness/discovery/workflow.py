"""``canebench discover``: the discovery workflow, one function (:func:`discover`) over its stages.

1. Baseline: every trial probed on the baseline model through the job runner
   (``beam``: the converged beam reference; ``chain``: the beam-consistent
   chain on Pinocchio; ``paper``: the naive case, whose 2EI/L bias would
   otherwise be blamed on physics) and scored against field stiffness.
2. Obstruction onsets in the field traces (:mod:`.onsets`); trials with one
   are scored up to the onset, in the field and in every simulation. A trial
   whose soft contact the field stage took for the tare (its contact knee is
   then the second body's onset) cannot be scored and is left out.
3. Residual structure (:mod:`.structure`).
4. Forward selection over the library (:mod:`canebench.model.effects`) on the
   screening model (:mod:`.screen`): a candidate must lean the residuals its
   way (cluster-robust score test, sign flips over canes), gain out of sample
   (leave-one-cane-out: the held-out mean |ln| per cane falls by 5 %), lower
   BIC, and change the model by at least :data:`.selection.MIN_CHANGE` (materiality).
   Of those that pass, the one with the lowest BIC is named (the held-out
   L1 gain mostly scores the level an effect moves, which several share),
   unless a single effect that fails materiality alone fits better still:
   then the residual's best account is too small to name, nothing is named
   at that step, the search stops, and the result is ``unexplained``
   (``too_small_to_name`` in discovery.json).
   After each named effect the baseline engine is re-run with the model so
   far and the screen re-anchored on it (:func:`.engine_runs.reanchor`): the screen is
   linear, the engines are not. The pair with the best BIC is tested jointly
   when it beats every single's BIC: two effects can cancel to first order,
   and a third that mimics their sum can pass alone (beside a single that
   passed, the pair's BIC must lie :data:`.selection.PAIR_OVER_SINGLE_BIC` below it and each member
   gain out of sample beside the other). Each
   step's alpha is split in halves between the single effects (Bonferroni)
   and the pair (one score test over every pair's joint directions).
   Repeated until nothing passes (or the best fit is too small to name). After each addition a backward pass
   (:func:`.selection.backward`) drops any earlier effect whose removal (the others
   refitted) changes the model by less than :data:`.selection.MIN_CHANGE`: an effect
   named early can go stale once a later one explains its share. No forward
   step returns to a model already held, so the search terminates. Then an
   effect whose 95 % cane-bootstrap interval (widened for the number of canes,
   :func:`.fit.small_sample_widening`) reaches its no-effect value (a
   parameter with ``switches_off``: a scale of 1, a pitch of 0, a spring at its
   stiffest bound, no flare) is not named (``unsupported``; one at a time,
   with a partner it entered beside as a pair, :func:`.selection.drop_unsupported`),
   the rest refitted and re-anchored without it, the backward pass run, and
   the intervals drawn again; nothing takes its place, and the result is
   ``unexplained`` (the residuals leaned its way significantly).
   Before the intervals, each parameter held at its null during the selection
   (``Parameter.refined``: a flare's ``size_exponent``, one collar for every cane or a share of
   each cane's diameter) is freed where the selected model's likelihood ratio and held-out density
   ask for it (:mod:`.refine`); an adopted one is re-anchored and the backward pass run again.
   After them, a modulus scale and a pitch that the BIC barely told apart (a close call) are put to
   the traces' shape, which a pitch changes and a scale does not (:mod:`.tiebreak`).
5. Adequacy (:func:`.adequacy.level_trend_geometry`): the held-out residual
   must not trend with the model's own stiffness level between canes beyond
   what the caliper-fit geometry's own error makes it do. A model that fails
   this does not scale across canes as the data do: an effect outside the
   library (or one the library has with the wrong scaling) is at work, and
   whatever the library fitted took the part of it that it could. Its effects
   are then not named: they are reported as ``partial`` (the library's best
   account, with its gap and a model file of its own) and the result is
   ``unexplained``. The same holds for a model that leaves a trend with push height within
   canes (:func:`.adequacy.within_trend_geometry`: an effect acting on part of a cane; unless,
   where it alone would withhold, an unnamed flare fitted beside the named ones takes the trend:
   then it is a taper fuller or leaner than the calipers' line, the names stand and the result is
   ``unexplained``, :func:`.verdict.within_taken_by`), for a model that leaves a cane's own pushes
   scattered about it far beyond what the caliper line's error can
   (:func:`.adequacy.within_dispersion`: an effect whose pattern along the cane changes from cane
   to cane, which cancels in the trend), and for
   a model whose predicted change in the traces' shape (a
   pitched probe's tension stiffens a trace as it goes) the traces do not show
   (:func:`.shape.shape_check`, on one more run of the baseline engine with the fitted model),
   and a model whose traces bend less, or more, than the field's, on average over the canes,
   beyond an allowance (:func:`.shape.shape_level`: a creeping material, a probe that slides;
   with nothing fitted it is run on the baseline's traces and flags without names to withhold),
   and a model that needs a parameter at the end of its physical range, away from its null
   (:func:`.verdict.at_physical_edge`: a modulus five times the stated one takes what it can of
   something no modulus is).
   Two warnings also set ``unexplained`` and leave the names
   standing: the structure table (:func:`.structure.structure_tests`) showing
   something significant, and the same level trend against a plain cane
   permutation (:func:`.structure.level_trend`), which ignores the shared
   geometry error and so flags more often than its level.
6. Each named effect that may be a cane's own (a root, a collar) is tested for a
   value per cane (:mod:`.per_cane`: a hierarchy with one parameter more, its
   spread between canes tested by the likelihood ratio at
   :data:`.per_cane.PER_CANE_ALPHA`); a per-cane one carries each cane's value.
7. The fitted model (95 % cane-bootstrap intervals, widened for the number of
   canes; per-cane values where step 6 found them) as a model file; the baseline
   and the chosen backends re-run with its global values; before and after, out
   of sample.

Where each stage lives: step 2 in :mod:`.contacts`, step 4 in :mod:`.selection` (with the no-effect values in
:mod:`.nulls`, the refinements in :mod:`.refine`, the scale-or-pitch tie-break in :mod:`.tiebreak`),
step 5 in :mod:`.verdict`, every engine run after the baseline's in
:mod:`.engine_runs`, step 6 in :mod:`.per_cane`; this module wires them together and writes the outputs.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ..data.dataset import Trial
from ..execute.runner import run_trials
from ..measure.fit import halves_slope_ratio
from ..model.config import ModelConfig
from ..model.effects import COV_LN_MAX, EFFECTS, AppliedEffects, EffectSpec
from ..model.presets import PRESETS
from ..probe.protocol import PROTOCOLS
from . import engine_runs
from .checks_text import lookalike_notes
from .contacts import FieldContacts, read_contacts
from .fit import bootstrap_ci, bootstrap_draws, intervals_from_draws
from .nulls import ci_of, covers_null
from .per_cane import PER_CANE_ALPHA, Cov2, PerCaneTest, per_cane_test, varying_parameter
from .refine import refine
from .screenset import Anchored, ScreenSet
from .selection import ALPHA, CLOSE_BIC, MIN_CHANGE, backward, drop_unsupported, forward_select
from .structure import between_share
from .tiebreak import fold_pitch_sign, shape_tie_break
from .verdict import ADEQUACY_ALPHA, INADEQUATE, judge

BASELINES = {
    "beam": ("beam", "beam-consistent", "the converged geometrically exact beam (stated modulus, caliper-fit taper)"),
    "chain": ("pinocchio", "beam-consistent", "the beam-consistent chain (dual-length springs, 20 links), exact statics"),
    "paper": ("pinocchio", "paper", "the paper's naive case (K = 2EI/L, greedy 5 mm chain, E = 4.57 GPa)"),
}
#: effects screened by default (obstruction is handled per trial from the traces)
SCREENED = ("modulus_scale", "root_compliance", "rig_compliance", "base_flare", "probe_misalignment")


@dataclass
class DiscoveryResult:
    baseline: str
    named: list[dict[str, Any]]
    unexplained: bool
    gap: dict[str, Any]
    trials: pd.DataFrame
    steps: pd.DataFrame
    structure_before: pd.DataFrame
    structure_after: pd.DataFrame
    config: ModelConfig
    engines: pd.DataFrame = field(default_factory=pd.DataFrame)
    stop_reason: str = ""
    notes: list[str] = field(default_factory=list)
    timing: dict[str, float] = field(default_factory=dict)
    #: engine runs the screen was re-anchored on after each named effect (see :func:`.engine_runs.reanchor`)
    anchors: list[dict[str, Any]] = field(default_factory=list)
    #: the adequacy check before and after (:func:`.adequacy.level_trend_geometry`)
    adequacy: dict[str, Any] = field(default_factory=dict)
    #: the library's best account when the adequacy check withheld its names (same form as ``named``)
    partial: list[dict[str, Any]] = field(default_factory=list)
    #: that account as a model (``model_partial.yaml``), None when nothing was withheld
    partial_config: ModelConfig | None = None
    #: the baseline engine's nonlinear excess over the screen at extra probe pitches (:func:`.engine_runs.pitch_table`)
    pitch_table: dict[str, Any] = field(default_factory=dict)
    #: effects the selection passed but whose 95 % interval reaches no effect, not named
    #: (``effect``, ``params``, ``ci95``, ``units``, ``covers_null``; a pair partner that went with one has an
    #: empty ``covers_null`` and ``dropped_with``; :func:`.selection.drop_unsupported`)
    unsupported: list[dict[str, Any]] = field(default_factory=list)
    #: the single effect too small to name whose better fit stopped the search (:attr:`.selection.Selection.too_small`)
    too_small_to_name: dict[str, Any] | None = None
    #: the named effects found to differ per cane, by name (:mod:`.per_cane`)
    per_cane: dict[str, PerCaneTest] = field(default_factory=dict)
    #: the refinements tried on the selected model (:func:`.refine.refine`), adopted or not
    refinements: list[dict[str, Any]] = field(default_factory=list)
    #: a close call between a scale and a pitch put to the traces' shape (:mod:`.tiebreak`), or None
    shape_tie: dict[str, Any] | None = None

    def model_file_config(self) -> ModelConfig:
        """The fitted model as ``model.yaml`` holds it: :attr:`config` (what the engines confirmed,
        the out-of-sample gap's) with each per-cane effect's canes' values (``local``) beside its
        global value, which a cane not in the data takes."""
        return self.config.replace(effects=tuple(self.per_cane[s.name].spec(s) if s.name in self.per_cane else s
                                                 for s in self.config.effects))

    def to_df(self) -> pd.DataFrame:
        return self.trials

    def to_json(self) -> dict[str, Any]:
        tr = []
        for r in self.trials.itertuples():
            row = {"trial": r.trial, "obstruction_onset_mm": (None if not np.isfinite(r.obstruction_onset_mm)
                                                              else float(r.obstruction_onset_mm))}
            if np.isfinite(getattr(r, "early_contact_mm", math.nan)):
                row["early_contact_mm"] = float(r.early_contact_mm)
                row["excluded"] = True  # a soft contact before the field stage's knee: not scored
            why = getattr(r, "not_scored", "")
            row["scored"] = not (isinstance(why, str) and why)
            if not row["scored"]:
                row["not_scored"] = why
            tr.append(row)
        return {"baseline": self.baseline, "named": self.named, "unexplained": bool(self.unexplained),
                "partial": self.partial, "unsupported": self.unsupported,
                "too_small_to_name": self.too_small_to_name, "refinements": self.refinements,
                "shape_tie": self.shape_tie,
                "gap": self.gap, "trials": tr,
                "stop_reason": self.stop_reason,
                "notes": self.notes,
                # NaN (a column a row does not have) as null: strict JSON
                "selection": self.steps.astype(object).where(self.steps.notna(), None).to_dict("records"),
                "anchors": self.anchors, "pitch_table": self.pitch_table, "adequacy": self.adequacy,
                "timing_s": self.timing,
                "between_cane_share": {"before": between_share(self.trials, "r_before"),
                                       "after_cv": between_share(self.trials, "r_after_cv")}}


def _features(trials: list[Trial], geoms: dict, fields: dict) -> pd.DataFrame:
    rows = []
    for t in trials:
        g = geoms.get(t.id)
        fr = fields[t.id]
        curv = math.nan
        if fr.fit is not None and fr.fit.displacement_mm is not None:
            curv = halves_slope_ratio(fr.fit.displacement_mm, fr.fit.force_n)
        cal_s = []
        length = math.nan
        if g is not None:
            from ..model.chain import cane_curve, resolve_s

            curve = cane_curve(t.cane, PRESETS["default"])
            cal_s = [resolve_s(curve, c.where, t.cane.source, "calipers") for c in t.cane.calipers]
            length = float(curve.length)
        rows.append({
            "trial": t.id, "cane": t.cane.id, "bush": t.bush, "trial_no": t.trial_no,
            "height_m": g.height if g else math.nan, "s_push_m": g.s_push if g else math.nan,
            # the whole cane's length (the screen's quadrature stops at the push point)
            "rel_push": g.s_push / length if g else math.nan,
            "diameter_mm": float(np.interp(g.s_push, g.s, g.d0)) * 1e3 if g else math.nan,
            "above_lowest_caliper_m": (g.s_push - min(cal_s)) if g and cal_s else math.nan,
            "k_field": fr.k, "curvature": curv,
        })
    return pd.DataFrame(rows)


def _gap(r: np.ndarray) -> dict[str, float]:
    a = np.abs(r[np.isfinite(r)])
    return {"median_abs_log_ratio": float(np.median(a)) if len(a) else math.nan,
            "worst_abs_log_ratio": float(np.max(a)) if len(a) else math.nan, "n": int(len(a))}


def _check_settings(alpha: float, n_boot: int, min_change: float, max_effects: int) -> None:
    """Refuse settings no discovery can use, before any work (each named by its CLI option)."""
    from numbers import Integral, Real

    from ..errors import InputError

    def real(v: Any) -> bool:  # numpy's scalars are registered with the numbers ABCs; a bool is not a setting
        return isinstance(v, Real) and not isinstance(v, bool)

    def count(v: Any) -> bool:
        return isinstance(v, Integral) and not isinstance(v, bool) and v >= 1

    if not (real(alpha) and 0.0 < alpha < 1.0):  # also refuses NaN
        raise InputError("--alpha", "alpha", f"must lie strictly between 0 and 1, got {alpha!r}")
    if not count(n_boot):
        raise InputError("--bootstrap", "bootstrap", f"the cane resamples of the intervals must be a positive "
                                                     f"integer, got {n_boot!r}")
    if not (real(min_change) and math.isfinite(min_change) and min_change >= 0.0):
        raise InputError("--min-change", "min_change", f"must be a finite change in ln k >= 0, got {min_change!r}")
    if not count(max_effects):
        raise InputError("max_effects", "max_effects", f"must be a positive integer, got {max_effects!r}")


def _engines(baseline: str, base_backend: str, backends: list[str] | None) -> tuple[list[str], dict[str, str]]:
    """The engines to confirm on (each once) and those skipped, with the reason.

    Raises :class:`~canebench.errors.UnknownBackend` on a name the registry does not hold, and
    :class:`~canebench.errors.BackendUnavailable` when the baseline's own engine cannot run
    (nothing can be scored without it); any other engine that cannot run is skipped, as
    ``canebench run`` skips it.
    """
    from ..errors import BackendUnavailable
    from ..registry import select

    _, base_skipped = select([base_backend])
    if base_skipped:
        raise BackendUnavailable(f"baseline {baseline!r} runs on backend {base_backend!r}, which is unavailable: "
                                 f"{base_skipped[base_backend]}")
    return select(backends or [base_backend])


def discover(trials: list[Trial], baseline: str = "beam", backends: list[str] | None = None,
             out: str | Path | None = None, executor: Any = None, candidates: tuple[str, ...] | None = None,
             alpha: float = ALPHA, n_boot: int = 100, seed: int = 0, confirm: bool = True,
             max_effects: int = 3, progress: Any = None, min_change: float = MIN_CHANGE) -> DiscoveryResult:
    """Find, name and fit the missing physical effects; see the module docstring.

    Parameters
    ----------
    trials : list of Trial
    baseline : str
        ``beam`` (default), ``chain`` or ``paper`` (:data:`BASELINES`).
    backends : list of str, optional
        Engines re-run before and after with the fitted model (default: the baseline's). A name
        the registry does not hold raises before any work; an engine that is not installed is
        skipped, with a note saying why.
    out : path, optional
        Folder for ``discovery.json``, ``discovery.csv``, ``model.yaml``, figures and the runner's stores.
    candidates : tuple of str, optional
        Effects screened (default :data:`SCREENED`).
    alpha : float
        Family-wise significance of one selection step: split in halves between the single
        candidates (Bonferroni) and the pair test when a pair can still be added.
    min_change : float
        Materiality: the smallest mean |change in ln k| over the trials that naming an effect must
        make to the fitted model (:data:`.selection.MIN_CHANGE`).
    """
    t_start = time.perf_counter()
    from ..execute.progress import Progress

    progress = progress or Progress()
    if baseline not in BASELINES:
        from ..errors import InputError

        raise InputError("--baseline", "baseline", f"unknown baseline {baseline!r}; known: {', '.join(BASELINES)}")
    base_backend, preset, base_text = BASELINES[baseline]
    cfg0 = PRESETS[preset]
    proto = PROTOCOLS["fast"]
    candidates = tuple(candidates or SCREENED)
    for c in candidates:
        if c not in EFFECTS:
            from ..errors import InputError

            raise InputError("--candidates", c, f"unknown effect; registered: {', '.join(EFFECTS)}")
    _check_settings(alpha, n_boot, min_change, max_effects)
    # a mistyped engine stops the run here, before minutes of work; one not installed is skipped
    confirm_on, skipped = _engines(baseline, base_backend, backends)
    outp = Path(out) if out is not None else None
    if outp is not None:
        outp.mkdir(parents=True, exist_ok=True)
    notes: list[str] = [f"backend {b} skipped: {why}" for b, why in skipped.items()]
    timing: dict[str, float] = {}

    # -- field, obstruction onsets (no simulation)
    fc = read_contacts(trials, proto.fit_window_mm, cfg0)
    obstruction, cfg_b = fc.obstruction, fc.config
    timing["geometry_s"] = fc.geometry_s
    timing["field_s"] = time.perf_counter() - t_start - timing["geometry_s"]

    # -- baseline simulation through the runner
    t1 = time.perf_counter()
    run = run_trials(trials, [base_backend], proto, cfg_b, outp / "baseline" if outp else None,
                     executor=executor, progress=progress)
    res = run.to_df()
    timing["baseline_s"] = time.perf_counter() - t1
    k_base = dict(zip(res.trial, res.k_sim.where(res.status == "ok")))

    # -- screening features (the geometry was built with the field stage)
    t2 = time.perf_counter()
    sim_why = dict(zip(res.trial, res.reason.fillna("").astype(str))) if "reason" in res else {}
    feats = _trial_table(trials, fc, k_base, sim_why)
    usable = feats.not_scored == ""
    # an elbow is reported wherever it is found; an obstructed trial that is not scored (its trace is
    # still no line up to the elbow, or the engine failed) is marked so in the obstruction's values
    unscored, left = not_scored_note(feats.trial, feats.not_scored, fc.onsets if obstruction else {})
    if left:
        notes.append(left)
    if usable.sum() < 6 or feats[usable].cane.nunique() < 3:
        from ..errors import InputError

        raise InputError("--field", "trials", f"only {int(usable.sum())} usable trials on "
                                              f"{feats[usable].cane.nunique()} canes: discovery needs 6 on 3"
                         + (f"; {left}" if left else ""))
    feats["log_k_field"] = np.log(feats.k_field)
    F = feats[usable].reset_index(drop=True)
    ss = ScreenSet.build([fc.geoms[t] for t in F.trial])
    lkf = np.log(F.k_field.to_numpy(float))
    lkb0 = np.log(F.k_base.to_numpy(float))
    timing["screen_build_s"] = time.perf_counter() - t2
    notes.append(f"calipers: readings scatter {1e3 * ss.cal_sigma:.2f} mm about each cane's fitted line (pooled); "
                 f"a diameter effect's change at the calipers is scored against it, so a flare stays below them")
    # the baseline engine's answer (the "before") and the linear screen alone; ``at`` follows the
    # anchor, and its screen carries the pitch table
    at0 = at = Anchored(ss, lkb0)
    pitch_table: dict[str, Any] = {}
    engine = engine_runs.BaselineEngine(trials, F, base_backend, proto, cfg0, obstruction, outp, executor, progress)
    if "probe_misalignment" in candidates:
        t_p = time.perf_counter()
        at, pitch_table = engine_runs.pitch_table(engine, at)
        timing["pitch_table_s"] = time.perf_counter() - t_p
        if pitch_table["n_failed"]:
            notes.append(f"pitch table: the engine failed on {pitch_table['n_failed']} trial(s) at some pitch; "
                         "those trials' pitch is screened linearly (1/cos^2 only)")
    at_empty = at  # the empty model's screen and anchor

    # -- selection
    t3 = time.perf_counter()
    anchors: list[dict[str, Any]] = []

    def reanchor(at_, cv_):
        # each engine re-anchoring round gets its own folder: a drop can return to an earlier size
        return engine_runs.reanchor(engine, at_, cv_, lkf, anchors, len(cv_.fit.specs),
                                    len({a["round"] for a in anchors}) + 1)

    sel = forward_select(candidates, at, lkf, reanchor, alpha, max_effects, min_change, seed)
    current, cv_cur, at, steps, stop = sel.current, sel.cv, sel.at, sel.steps, sel.stop
    timing["selection_s"] = time.perf_counter() - t3

    # -- refinements of the selected effects' forms (a flare that grows with the cane): an adopted one
    # can leave an effect selected to make up for the form held fixed with nothing to do, so the
    # backward pass runs again (every refit keeps the refinement: .selection passes it on)
    refinements: list[dict[str, Any]] = []
    if current:
        t_r = time.perf_counter()
        cv_cur, at, tried = refine(cv_cur, at, lkf, lambda at_, cv_: reanchor(at_, cv_))
        refinements = [r.to_dict() for r in tried]
        notes.extend(r.note() for r in tried)
        if any(r.adopted for r in tried):
            steps.append({"step": len(current), "model": "+".join(current), "candidate": "refined: " + ", ".join(
                f"{r.effect}.{r.parameter}" for r in tried if r.adopted), "bic": cv_cur.fit.bic,
                "params": {sp.name: dict(sp.params) for sp in cv_cur.fit.specs}, "chosen": True})
            current, cv_cur, at, gone = backward(current, (), cv_cur, at, lkf, min_change,
                                                 lambda at_, cv_: reanchor(at_, cv_), steps, len(current))
            if gone:
                notes.append("stale once the refinement was adopted, dropped: " + ", ".join(gone))
                sel.entered[:] = [g2 for g in sel.entered if (g2 := tuple(c for c in g if c not in gone))]
                sel.close_calls[:] = [cc for cc in sel.close_calls if not set(cc["chosen"]) & set(gone)]
        timing["refine_s"] = time.perf_counter() - t_r

    # -- intervals, and the names they do not support
    t4 = time.perf_counter()

    def draw_ci(fit_, at_):
        return bootstrap_ci(fit_, at_, lkf, n_boot=n_boot, seed=seed)

    ci = draw_ci(cv_cur.fit, at) if current else {}
    current, cv_cur, at, ci, unsupported, stale = drop_unsupported(
        current, tuple(sel.entered), cv_cur, at, lkf, ci, draw_ci, reanchor, at_empty, min_change, steps)
    notes.extend(_not_named_notes(unsupported, stale, sel.too_small, bool(current), min_change))
    if unsupported:
        stop += "; not named, for an interval that reaches no effect: " + ", ".join(
            u["effect"] + ("" if u["covers_null"] else f" (with {u['dropped_with']})") for u in unsupported)

    # -- a close call between a modulus scale and a pitch, decided by the traces' shape (.tiebreak)
    shapes: dict[tuple, dict[str, Any]] = {}

    def shape_of(specs, level):
        # one engine run per model: the tie-break's chosen model is, where it stands, the one judged
        key = (tuple(specs), level)
        if key not in shapes:
            shapes[key] = engine_runs.model_shape_check(engine, run, specs, seed, level)
        return shapes[key]

    shape_tie = None
    if current:
        t_s = time.perf_counter()
        alt, cv_t, at_t, shape_tie = shape_tie_break(current, sel.close_calls, cv_cur, at, at_empty, lkf, shape_of,
                                                     lambda at_, cv_: reanchor(at_, cv_), ADEQUACY_ALPHA)
        if shape_tie is not None and shape_tie.swapped:
            # the traces fixed the pitch's sign: its interval is of its size (.tiebreak.fold_pitch_sign)
            ci_t = intervals_from_draws(cv_t.fit, fold_pitch_sign(cv_t.fit, bootstrap_draws(
                cv_t.fit, at_t, lkf, n_boot=n_boot, seed=seed)), len(np.unique(at_t.screen.canes)))
            if covers_null(next(sp for sp in cv_t.fit.specs if sp.name == shape_tie.rival), ci_t):
                shape_tie.swapped, shape_tie.why = False, f"the {shape_tie.rival}'s interval reaches no effect"
            else:
                current, cv_cur, at, ci = alt, cv_t, at_t, ci_t
                for cc in sel.close_calls:  # the close call now reads the other way
                    if cc["chosen"] == (shape_tie.chosen,):
                        cc.update(chosen=(shape_tie.rival,), rivals=[(shape_tie.chosen, -shape_tie.bic_gap)],
                                  by_shape=True)
                steps.append({"step": len(current), "model": "+".join(current),
                              "candidate": f"{shape_tie.chosen}->{shape_tie.rival} (trace shape)",
                              "bic": cv_cur.fit.bic, "params": {sp.name: dict(sp.params) for sp in cv_cur.fit.specs},
                              "chosen": True})
        if shape_tie is not None:
            notes.append(shape_tie.note())
        timing["shape_tie_s"] = time.perf_counter() - t_s

    final = cv_cur
    r_before = lkf - lkb0
    r_after = final.residual
    F["r_before"] = r_before
    F["r_after_cv"] = r_after
    F["log_k_model"] = at.predict(final.fit.specs)  # the fitted model's own stiffness
    F["log_k_base"] = lkb0
    F["r_after_in"] = lkf - F.log_k_model
    # the held-out prediction: the level the held-out residual is compared with (both from the fold
    # that left the cane out, so neither carries the cane's own measurement)
    F["log_k_model_cv"] = lkf - r_after
    feats = feats.merge(F[["trial", "r_before", "r_after_cv", "r_after_in", "log_k_model", "log_k_model_cv"]],
                        on="trial", how="left")

    named = _named_entries(final.fit.specs, ci, at)
    notes.extend(mark_close_calls(named, sel.close_calls))
    if obstruction or fc.early:
        named.append(_obstruction_entry(fc, unscored))
    notes.extend(_contact_notes(fc))
    timing["bootstrap_s"] = time.perf_counter() - t4

    # -- is it an explanation?
    verdict = judge(F, r_before, r_after, lkf, at0, at, final, current, candidates, unsupported, named,
                    cfg0.diameter_factor, shape_of, notes, timing, seed)
    named, partial, adequacy = verdict.named, verdict.partial, verdict.adequacy
    notes.extend(lookalike_notes(named, partial, list(1e3 * F.groupby("cane").s_push_m.min().dropna())))
    fitted = tuple(final.fit.specs)
    # -- per-cane scope of the named effects that may be each cane's own (a root, a collar)
    t_pc = time.perf_counter()
    per_cane = scope_per_cane(named, final.fit, at, lkf, min_change, cfg0.diameter_factor, seed,
                              plants=dict(zip(feats.cane, feats.bush)))
    if per_cane:
        notes.append(per_cane_note(per_cane))
    timing["per_cane_s"] = time.perf_counter() - t_pc
    gap = {"before": _gap(r_before), "after_cv": _gap(r_after), "after_in_sample": _gap(F.r_after_in.to_numpy())}
    partial_config = None
    if partial:
        # nothing named: the model is the baseline (with any obstruction), its gap the before; the
        # library's best account keeps its own figures
        gap["partial_after_cv"], gap["partial_after_in_sample"] = gap["after_cv"], gap["after_in_sample"]
        gap["after_cv"] = gap["after_in_sample"] = _gap(r_before)
        partial_config = cfg0.replace(effects=fitted + obstruction)
        fitted = ()
    model = cfg0.replace(effects=fitted + obstruction)

    # -- confirm on the engines
    engines = pd.DataFrame()
    if confirm and not confirm_on:
        notes.append("no engine to confirm on: every one asked for is skipped (above)")
    if confirm and confirm_on:
        t5 = time.perf_counter()
        # with the names withheld the engines run the library's best account: what it would do on
        # every engine is worth seeing; the named model's "after" is the "before"
        engines = engine_runs.confirm(trials, confirm_on, proto=proto, base_config=cfg_b,
                                      model=partial_config or model, F=F, final=final,
                                      anchor=at, baseline=at0,
                                      out=outp, executor=executor, progress=progress)
        timing["confirm_s"] = time.perf_counter() - t5
        gap["per_backend"] = {r.backend: {"model": "partial" if partial else "named", **{k: getattr(r, k) for k in (
            "before_median", "before_worst", "after_median", "after_worst", "after_cv_median", "after_cv_worst",
            "screen_vs_engine_max", "linear_screen_vs_engine_max")}} for r in engines.itertuples()}
    timing["total_s"] = time.perf_counter() - t_start
    # the best account of what the residual leans toward was too small to name: it stays unexplained
    result = DiscoveryResult(baseline, named, verdict.unexplained or sel.too_small is not None, gap, feats,
                             pd.DataFrame(steps), verdict.structure_before, verdict.structure_after, model, engines,
                             stop, notes, timing, anchors, adequacy, partial, partial_config,
                             pitch_table, unsupported, sel.too_small, per_cane, refinements,
                             shape_tie.to_dict() if shape_tie is not None else None)
    result.notes.append(f"baseline: {base_text}")
    if any(t.cane.provenance.get("assumptions") for t in trials):
        for a in dict.fromkeys(a for t in trials for a in t.cane.provenance.get("assumptions", [])):
            if a.startswith("geometry"):
                result.notes.append(a)
    if outp is not None:
        write_outputs(result, outp, preset, ci)
    return result


def _trial_table(trials: list[Trial], fc: FieldContacts, k_base: dict[str, float],
                 sim_why: dict[str, str]) -> pd.DataFrame:
    """One row per trial: the screen's features, the contacts found, both stiffnesses and, for a
    trial left out of the scoring, why (``not_scored``; empty where it is scored)."""
    onsets, early = fc.onsets, fc.early
    feats = _features(trials, fc.geoms, fc.fields)
    feats["obstruction_onset_mm"] = [onsets[t] if t in onsets else early[t].onset_mm if t in early else math.nan
                                     for t in feats.trial]
    feats["early_contact_mm"] = [early[t].contact_mm if t in early else math.nan for t in feats.trial]
    feats["k_base"] = [k_base.get(t, math.nan) for t in feats.trial]
    feats["k_field"] = [fc.fields[t].k for t in feats.trial]
    # a trial left out of the scoring says why, in the table, the JSON and the notes: a trace too
    # short to fit (a very stiff cane that reaches the rig's stop in a few steps) must not vanish.
    # The reason is the one test of whether a trial is scored, so the two cannot disagree.
    feats["not_scored"] = [not_scored_reason(t, fc.fields.get(t), early, k_base, sim_why) for t in feats.trial]
    return feats


def _not_named_notes(unsupported: list[dict], stale: Iterable[str], too_small: dict | None, named_any: bool,
                     min_change: float) -> list[str]:
    """The notes on what passed the selection but is not named: an interval that reaches no effect
    (:func:`.selection.drop_unsupported`), an effect gone stale after that, a best fit too small to
    name (:attr:`.selection.Selection.too_small`). ``named_any``: whether anything is still named."""
    notes = []
    for u in unsupported:
        beside = f", beside {u['dropped_with']}, which it entered the model with as a pair" if "dropped_with" in u else ""
        if u["covers_null"]:
            notes.append(f"{u['effect']} passed the selection ("
                         + ", ".join(f"{k} = {v:.4g}" for k, v in u["params"].items()) + f") but is not named{beside}: its "
                         + "; ".join(f"95 % interval of {k}, [{u['ci95'][k][0]:.4g}, {u['ci95'][k][1]:.4g}], reaches "
                                     f"its no-effect value" for k in u["covers_null"])
                         + ("; the rest refitted without it" if named_any else "; nothing else is in the model")
                         + ", and the result flagged unexplained: the residuals leaned its way significantly, and "
                           "nothing named takes that")
        else:
            notes.append(f"{u['effect']} is not named{beside}: it failed the selection alone, and the pair no "
                         f"longer stands")
    if stale:
        notes.append(f"dropped as stale once an effect was not named: {', '.join(stale)}")
    if too_small:
        ts = too_small
        notes.append(f"{ts['effect']} (" + ", ".join(f"{k} = {v:.4g}" for k, v in ts["params"].items())
                     + f") fitted the residual best at step {ts['step']} (BIC {ts['bic']:.1f}; the residuals lean "
                     f"its way, p = {ts['p']:.2g}) but changes the model by {ts['net_change_mean_abs']:.3g} in mean "
                     f"|ln k|, under {min_change:.3g}: too small to name; {', '.join(ts['outranked'])} passed every "
                     f"rule but {'fits' if len(ts['outranked']) == 1 else 'fit'} worse, and nothing is named in its "
                     f"place; the result is flagged unexplained")
    return notes


def _named_entries(specs: Iterable[EffectSpec], ci: dict, at: Anchored) -> list[dict[str, Any]]:
    """``discovery.json``'s ``named`` entries of the global effects fitted, with their intervals, what
    each alone changes ln k by on the scored trials, and, for an effect on the diameter, how much the
    calipers would have read differently."""
    screen = at.screen
    without = at.predict(())
    named = []
    for spec in specs:
        named.append({"effect": spec.name, "scope": "global", "params": dict(spec.params),
                      "ci95": ci_of(spec, ci),
                      "units": spec.units()})
        # the effect's size in the quantity the data measure: an effect's two parameters can trade off (a
        # flare's excess against its length) where the stiffening they give together is well fixed by the data
        change = at.predict((spec,)) - without
        change = change[np.isfinite(change)]
        if len(change):
            named[-1]["ln_k_change"] = {"median": float(np.median(change)), "min": float(np.min(change)),
                                        "max": float(np.max(change))}
        fx1 = AppliedEffects([spec.instance()])
        if fx1.changes_diameter and len(screen.cal_s):
            # what the calipers would have read differently (mm), against their own scatter
            named[-1]["at_calipers_mm"] = {"max": 1e3 * float(np.max(np.abs(screen.caliper_change(fx1)))),
                                           "caliper_scatter": 1e3 * screen.cal_sigma}
    return named


def scope_per_cane(named: list[dict[str, Any]], fit: Any, at: Anchored, log_k_field: np.ndarray,
                   min_change: float, diameter_factor: float, seed: int,
                   alpha: float = PER_CANE_ALPHA,
                   plants: Mapping[str, Any] | None = None) -> dict[str, PerCaneTest]:
    """Test each named effect that may be each cane's own for a value per cane (:mod:`.per_cane`),
    at ``alpha`` split over the effects tested; a per-cane one gets ``scope`` ``per_cane`` and its
    canes' values (``local``) in place. Every tested entry carries ``per_cane_test``. ``plants``
    (cane -> bush) clusters the spread's error by plant."""
    tested = [n for n in named if n["scope"] == "global" and varying_parameter(n["effect"])]
    out: dict[str, PerCaneTest] = {}
    for n in tested:
        t = per_cane_test(at, log_k_field, tuple(fit.specs), n["effect"], alpha / len(tested), min_change,
                          diameter_factor, fit.s2, fit.t2, seed, plants)
        if t is None:
            continue
        # kept global, the canes' values (shrunk toward the median) say nothing a reader needs
        n["per_cane_test"] = {k: v for k, v in t.to_dict().items()
                              if t.per_cane or k not in ("values", "ln_sd_each")}
        if t.per_cane:
            n["scope"] = "per_cane"
            n["local"] = {c: {t.parameter: v} for c, v in t.values.items()}
            out[n["effect"]] = t
    return out


def per_cane_note(per_cane: Mapping[str, PerCaneTest]) -> str:
    """The note on the effects whose value differs between canes."""
    return "; ".join(
        f"{t.effect}: {t.reason}; each cane's {t.parameter} ({min(t.values.values()):.4g} to "
        f"{max(t.values.values()):.4g} {t.unit}; their median {t.median:.4g}) is in model.yaml (local); a cane "
        f"not in the data takes the global fit's value, the one the engines confirm and the interval and the "
        f"gap out of sample are of; a population export (canebench export --field DIR --model model.yaml "
        f"--population N) draws each new cane's {t.parameter} from median {t.median:.4g} and ln sd "
        f"{t.ln_sd:.2f} (between_canes){_spread_error_text(t)}"
        for t in per_cane.values())


def _spread_error_text(t: PerCaneTest) -> str:
    """How a population treats the spread's own error: drawn within it (its standard errors, where the
    clustering by plant widened them, and where they were cut to what a population draws within), or why not."""
    if t.cov_ln is None:
        return ("; their sampling error is not known (the hierarchy's information is not positive definite: the "
                "spread is not pinned apart from the canes' own levels), so a population draws from them as if exact")
    se = _se(t.cov_ln)
    drawn = t.drawable_cov()
    if drawn is None:
        return (f"; their standard errors ({se[0]:.2f} in ln median, {se[1]:.2f} in ln ln sd) are not a covariance a "
                f"population can draw within, so it draws from them as if exact")
    text = (f", each first drawn within its sampling error (standard errors {se[0]:.2f} in ln median, {se[1]:.2f} in "
            f"ln ln sd{_clustered_text(t)}")
    if drawn != t.cov_ln:
        cut = _se(drawn)
        text += (f"; a population draws within {cut[0]:.2f} and {cut[1]:.2f}, the most it allows, as its spread can "
                 f"overflow beyond")
    return text + ")"


def _se(cov: Cov2) -> tuple[float, float]:
    """The standard errors of (ln median, ln ln sd) in a spread's covariance."""
    return math.sqrt(cov[0][0]), math.sqrt(cov[1][1])


def _clustered_text(t: PerCaneTest) -> str:
    """Which standard errors the clustering by plant widened, and from what; and the plants without
    whose canes the spread is not found, which leave ln ln sd's error unbounded."""
    if t.cov_ln_model is None or t.cov_ln is None:
        return ""
    names = ("ln median", "ln ln sd")
    wide = [f"{names[i]} from {_se(t.cov_ln_model)[i]:.2f}" for i in (0, 1) if t.cov_ln[i][i] > t.cov_ln_model[i][i]]
    text = f"; clustered by plant (a jackknife over {t.n_plants} plants), which widened {' and '.join(wide)}" if wide else ""
    if t.spread_lost_without:
        text += (f"; without the canes of plant {', '.join(t.spread_lost_without)} no spread is found, so ln ln sd's "
                 f"error has no bound and is taken as {math.sqrt(COV_LN_MAX[1]):.2f}, the most a population draws within")
    return text


def _obstruction_entry(fc: FieldContacts, unscored: dict[str, str]) -> dict[str, Any]:
    """The per-trial obstruction's ``named`` entry: each onset, a moved contact's cut, and the trials
    left out (an early contact, or an obstructed trial that is not scored, with its reason)."""
    local = {k: ({"onset_mm": v, "excluded": True, "reason": unscored[k]} if k in unscored else {"onset_mm": v})
             for k, v in fc.onsets.items()}
    for k, rc in fc.recontact.items():  # the contact the record up to the elbow puts earlier
        local[k].update(contact_mm=rc.fit.onset_mm, record_end_mm=rc.record_end_mm)
    local.update({k: {"onset_mm": e.onset_mm, "contact_mm": e.contact_mm, "excluded": True}
                  for k, e in fc.early.items()})
    return {"effect": "obstruction", "scope": "per_trial", "params": {},
            "local": dict(sorted(local.items())), "ci95": {}, "n_trials": len(fc.onsets),
            "n_excluded_early_contact": len(fc.early), "n_excluded_unscored": len(unscored)}


def _contact_notes(fc: FieldContacts) -> list[str]:
    """The notes on contacts moved before an elbow and on ramps read as drift."""
    notes = []
    if fc.recontact:
        notes.append(f"{len(fc.recontact)} obstructed trial(s) touch earlier than the field stage's contact knee, "
                     "which an elbow inside its search pulled late: onset and field stiffness from the record up to "
                     "the elbow (" + ", ".join(f"{k}: contact {fc.fields0[k].fit.onset_mm - rc.fit.onset_mm:.1f} mm "
                                               "earlier" for k, rc in sorted(fc.recontact.items())) + ")")
    if fc.drifts:
        notes.append(f"{len(fc.drifts)} trial(s) rise slowly before their contact knee, and the model's level for the "
                     "cane (its other pushes', and all pushes') is nearer the slope after the knee than that ramp: "
                     "read as the load cell drifting before contact, not as a contact before an obstruction; scored "
                     f"as usual ({', '.join(sorted(fc.drifts))})")
    return notes


def mark_close_calls(named: list[dict], close_calls: list[dict]) -> list[str]:
    """Give each named effect that won its step by less than :data:`.selection.CLOSE_BIC` its
    ``close_rivals`` (``candidate``, ``bic_above``), in place; returns one note per such step.

    ``close_calls`` is :attr:`.selection.Selection.close_calls` (the selection forgets those of
    effects its backward pass drops). A step whose chosen effects were all dropped later (the
    intervals) is not reported: nothing named rests on it; nor is a rival that is named itself.
    """
    notes = []
    names = {n["effect"] for n in named}
    for cc in close_calls:
        kept = [n for n in named if n["effect"] in cc["chosen"]]
        rivals = [(c, d) for c, d in cc["rivals"] if not set(c.split("+")) <= names]
        if not kept or not rivals:
            continue
        for n in kept:
            n["close_rivals"] = [{"candidate": c, "bic_above": float(d), **({"decided_by": "trace shape"}
                                                                            if cc.get("by_shape") else {})}
                                 for c, d in rivals]
        if cc.get("by_shape"):
            continue  # named against the BIC by the traces' shape: the tie-break's note says so
        notes.append(f"{'+'.join(cc['chosen'])} was chosen at step {cc['step']} by the lowest BIC, but "
                     + ", ".join(f"{c} passed every rule too, only {d:.2f} above" for c, d in rivals)
                     + f" (under {CLOSE_BIC:g}: a Bayes factor under e, which the data barely support); read the "
                       "name with that rival beside it")
    return notes


def not_scored_note(trials: Iterable[str], not_scored: Iterable[str],
                    onsets: Mapping[str, float]) -> tuple[dict[str, str], str]:
    """The trials left out of the scoring, once: ``(unscored, note)``.

    ``not_scored`` holds each trial's reason (empty where it is scored) and ``onsets`` the named
    obstruction's onsets. ``unscored`` is the obstructed trials among those left out, with their
    reasons (the obstruction's values mark them excluded); ``note`` counts and lists every trial
    left out, an obstructed one with its onset, or is empty when every trial is scored.
    """
    rows = list(zip(trials, not_scored))
    left = [(t, why) for t, why in rows if isinstance(why, str) and why]
    unscored = {t: why for t, why in left if t in onsets}
    if not left:
        return unscored, ""
    return unscored, f"{len(left)} of {len(rows)} trials not scored: " + "; ".join(
        f"{t} ({f'obstruction at {onsets[t]:.1f} mm; ' if t in onsets else ''}{why})" for t, why in left)


def not_scored_reason(tid: str, fr: Any, early: dict, k_base: dict[str, float], sim_why: dict[str, str]) -> str:
    """Why trial ``tid`` has no residual: a contact before the field stage's knee, no usable field
    slope (the field fit's own reason), or no baseline stiffness (the engine's reason); ``""`` when
    it has one (a positive, finite field and baseline stiffness and no early contact)."""
    if tid in early:
        return (f"a soft contact from {early[tid].contact_mm:.1f} mm of travel and a second body "
                f"{early[tid].onset_mm:.1f} mm after it: the trace's slope is the second body's")
    k_f = fr.k if fr is not None else math.nan
    if not (np.isfinite(k_f) and k_f > 0):
        why = (fr.reason or (fr.fit.reason if fr.fit is not None else "")) if fr is not None else ""
        return f"no field stiffness: {why or 'no field fit'}"
    k_b = k_base.get(tid, math.nan)
    if not (np.isfinite(k_b) and k_b > 0):
        return f"no baseline stiffness: {sim_why.get(tid) or 'the engine gave none'}"
    return ""


def write_outputs(res: DiscoveryResult, out: Path, preset: str, ci: dict) -> None:
    from ..execute.provenance import provenance
    from ..model.modelfile import write_model_file

    doc = res.to_json()
    backends = sorted(set(res.engines.backend) if len(res.engines) else set()) or [BASELINES[res.baseline][0]]
    prov = provenance(backends, PROTOCOLS["fast"], res.config)
    doc["provenance"] = {k: prov[k] for k in ("canebench", "git_commit", "git_dirty", "created", "python", "engines",
                                              "protocol", "model_config")}
    (out / "discovery.json").write_text(json.dumps(doc, indent=2, default=float))
    res.trials.to_csv(out / "discovery.csv", index=False)
    res.steps.to_csv(out / "discovery_steps.csv", index=False)
    res.structure_before.assign(when="before").to_csv(out / "discovery_structure.csv", index=False)
    if len(res.structure_after):
        res.structure_after.assign(when="after_cv").to_csv(out / "discovery_structure.csv", mode="a", header=False,
                                                           index=False)
    if len(res.engines):
        res.engines.to_csv(out / "discovery_engines.csv", index=False)
    ci95 = {}
    for n in res.named:
        if n["ci95"]:
            ci95[n["effect"]] = n["ci95"]
    made = {"produced_by": "canebench discover", "baseline": res.baseline,
            **{k: doc["provenance"][k] for k in ("canebench", "git_commit", "git_dirty", "created", "engines")}}
    write_model_file(out / "model.yaml", res.model_file_config(), preset, ci95, made)
    if res.partial_config is not None:
        write_model_file(out / "model_partial.yaml", res.partial_config, preset,
                         {n["effect"]: n["ci95"] for n in res.partial if n["ci95"]},
                         {**made, "partial": f"the library's best account; its names were withheld: it "
                                             f"{INADEQUATE} (discovery.json, adequacy)"})
    from canebench.reports.build import build_report
    from canebench.reports.discovery import figures

    figures(out)
    build_report(out)
