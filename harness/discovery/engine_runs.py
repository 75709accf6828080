"""Runs of the engines inside discovery: the baseline engine on the scored trials, re-run with a
fitted model to re-anchor the screen (:func:`reanchor`), at extra probe pitches (:func:`pitch_table`)
and for the traces' shape (:func:`model_shape_check`); and every chosen backend before and after
(:func:`confirm`). Each goes through the job runner, in its own folder of the output.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ..data.dataset import Trial
from ..execute.runner import run_trials
from ..model.config import ModelConfig
from ..model.effects import EffectSpec
from .fit import Candidate, CVResult, cross_validate
from .screenset import PITCH_GRID_DEG, Anchored
from .shape import SHARE as SHAPE_SHARE, shape_check, shape_level, trace_shapes


def ok_log_k(res: pd.DataFrame, backend: str, order: pd.Series) -> np.ndarray:
    """ln k_sim of ``backend``'s ok results, in the trial order ``order`` (NaN where not ok)."""
    r = res[res.backend == backend].set_index("trial")
    return np.log(r.k_sim.where(r.status == "ok").reindex(order).to_numpy(float))


@dataclass
class BaselineEngine:
    """The baseline engine on the scored trials (``F``'s, in its order), with any obstruction
    onsets always applied; a run's stores go to ``out / name`` (nowhere without ``out``)."""

    trials: list[Trial]
    F: pd.DataFrame
    backend: str
    proto: Any
    cfg0: ModelConfig
    obstruction: tuple[EffectSpec, ...]
    out: Path | None
    executor: Any
    progress: Any

    def run(self, specs: tuple[EffectSpec, ...], name: str) -> Any:
        """The runner's outcome with the effects ``specs`` (and the obstruction)."""
        keep = set(self.F.trial)
        effects = tuple(specs) + self.obstruction
        return run_trials([t for t in self.trials if t.id in keep], [self.backend], self.proto,
                          self.cfg0.replace(effects=effects), self.out / name if self.out else None,
                          executor=self.executor, progress=self.progress)

    def log_k(self, specs: tuple[EffectSpec, ...], name: str) -> np.ndarray:
        """ln k with the effects ``specs``, in ``F``'s order; NaN where the engine failed."""
        return ok_log_k(self.run(specs, name).to_df(), self.backend, self.F.trial)


def reanchor(engine: BaselineEngine, at: Anchored, cv_cur: Any, lkf: np.ndarray, log: list[dict[str, Any]],
             step: int, round_no: int, max_runs: int = 3, xtol: float = 0.005) -> tuple[Anchored, Any]:
    """Run the baseline engine with the current model and make it the screen's anchor; refit.

    Returns the screen anchored there and the model cross-validated again on it.

    Repeated (at most ``max_runs`` engine runs) until the refit changes the predicted ln k of
    every trial by less than ``xtol``. A trial the engine fails on keeps the previous anchor's
    linear prediction. Every run is logged with how far the engine was from the screen's
    prediction there. The anchor comes from parameters fitted on all canes, so the held-out
    predictions share its linearization point (a second-order leak: the point moves the
    prediction only through the screen's curvature).
    """
    for it in range(1, max_runs + 1):
        specs = tuple(cv_cur.fit.specs)
        lk_eng = engine.log_k(specs, f"anchor_{round_no}_{it}")
        lk_lin = at.predict(specs)
        good = np.isfinite(lk_eng)
        dev = lk_eng - lk_lin
        new_lka = np.where(good, lk_eng, lk_lin)
        entry = {"step": step, "round": round_no, "run": it, "params": {sp.name: dict(sp.params) for sp in specs},
                 "engine": engine.backend, "n_failed": int((~good).sum()),
                 "engine_minus_screen_median": float(np.median(dev[good])) if good.any() else math.nan,
                 "engine_minus_screen_max_abs": float(np.max(np.abs(dev[good]))) if good.any() else math.nan}
        if not np.all(np.isfinite(new_lka)):
            # a trial the engine failed on whose linear prediction is undefined too: keep the
            # previous anchor rather than poison every later fit
            entry["kept_previous_anchor"] = True
            log.append(entry)
            break
        at = Anchored(at.screen.anchored(specs), new_lka)
        cv_cur = cross_validate(Candidate.like(tuple(sp.name for sp in specs), cv_cur), at, lkf)
        # converged when the refit moves the predictions, not the parameters, by less than xtol
        # (a weakly identified parameter, e.g. a very stiff rig, can move far and change nothing)
        move = float(np.max(np.abs(at.predict(cv_cur.fit.specs) - at.log_k)))
        entry["refit_move_ln_k"] = move
        log.append(entry)
        if move < xtol:
            break
    return at, cv_cur


def pitch_table(engine: BaselineEngine, at: Anchored) -> tuple[Anchored, dict[str, Any]]:
    """Run the baseline engine at the extra probe pitches :data:`PITCH_GRID_DEG`; the screen with
    each trial's engine-minus-screen ln k there (:meth:`.ScreenSet.with_pitch_table`), at the same anchor.

    A pitched probe loads the cane along its axis as well (tension pitched up, compression
    down), which stiffens or softens it beyond the linear screen's 1/cos^2; without the table
    a 30 degree pitch on 1000 gf traces was fitted as -37.5 degrees and lost to a modulus
    scale (both level shifts to the linear screen). Cost: one baseline run per extra pitch.
    """
    table = np.zeros((len(engine.F), len(PITCH_GRID_DEG)))
    for j, pitch in enumerate(PITCH_GRID_DEG):
        if pitch == 0.0:
            continue
        spec = EffectSpec("probe_misalignment", (("angle_deg", float(pitch)),))
        lk_eng = engine.log_k((spec,), f"pitch_{pitch:+.0f}")
        table[:, j] = lk_eng - at.predict((spec,))
    failed = ~np.all(np.isfinite(table), axis=1)
    # None where the engine failed on every trial at a pitch: discovery.json is strict JSON
    summary = {"grid_deg": list(PITCH_GRID_DEG), "engine": engine.backend, "n_failed": int(failed.sum()),
               "median_engine_minus_screen": [float(np.median(c[np.isfinite(c)])) if np.isfinite(c).any()
                                              else None for c in table.T],
               "max_abs_engine_minus_screen": [float(np.max(np.abs(c[np.isfinite(c)]))) if np.isfinite(c).any()
                                               else None for c in table.T]}
    return Anchored(at.screen.with_pitch_table(table), at.log_k), summary


def model_shape_check(engine: BaselineEngine, base_run: Any, specs: tuple[EffectSpec, ...], seed: int,
                      alpha: float) -> dict[str, Any]:
    """:func:`.shape.shape_check` of the fitted model ``specs`` (one more run of the baseline engine).

    ``base_run`` is the baseline run (its traces carry the field's rows too). Trials with an
    obstruction onset are left out (their field trace has an elbow the engines' traces lack: the
    obstruction only shortens the fit window), and so are trials on which the baseline or the
    model run did not end ``ok`` (a run that failed partway has a trace, but not the push's).
    Without effects only the traces' mean shape is checked (:func:`.shape.shape_level`, on the
    baseline's traces), and ``p`` is None.
    """
    F, backend = engine.F, engine.backend
    no_obstruction = ~np.isfinite(F.obstruction_onset_mm.to_numpy(float))
    if not specs:
        # nothing fitted: the baseline is the model, and only the traces' mean shape is checked
        free = F[no_obstruction]
        shapes = trace_shapes(list(free.trial), base_run.traces, base_run.traces, base_run.traces, backend)
        return {"p": None, "n_trials": 0, "share": SHAPE_SHARE, "reason": "no effect fitted", "engine": backend,
                "level": shape_level(free.cane.to_numpy(), shapes, alpha, seed=seed)}
    model = engine.cfg0.replace(effects=tuple(specs) + engine.obstruction)
    run = engine.run(specs, "shape_model")
    # F holds only trials the baseline run scored ok (a finite k_base): the model run is the one to check
    ok = np.isfinite(ok_log_k(run.results, backend, F.trial))
    free = F[ok & no_obstruction]
    cane_of = dict(zip(F.trial, F.cane))

    def measured(trial: str, x_mm: np.ndarray, f_n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        x, f = model.applied_effects(cane_of[trial], trial).measured(x_mm * 1e-3, f_n)
        return np.asarray(x) * 1e3, np.asarray(f)

    shapes = trace_shapes(list(free.trial), base_run.traces, base_run.traces, run.traces, backend, measured)
    out = shape_check(free.cane.to_numpy(), shapes, seed=seed)
    out["level"] = shape_level(free.cane.to_numpy(), shapes, alpha, seed=seed)
    out["n_trials_not_ok"] = int((~ok).sum())
    out["test"] = ("one-sided: do the traces show at least the share of the fitted model's change in their "
                   "stiffening over the push (its run on the baseline engine against the baseline's)?")
    out["engine"] = backend
    return out


def _stat(f: Any, x: np.ndarray) -> float:
    """``f`` of |x| over its finite values; NaN, without a warning, when an engine failed on every trial."""
    a = np.abs(x[np.isfinite(x)])
    return float(f(a)) if len(a) else math.nan


def confirm(trials: list[Trial], backends: list[str], *, proto: Any, base_config: ModelConfig,
            model: ModelConfig, F: pd.DataFrame, final: CVResult, anchor: Anchored, baseline: Anchored,
            out: Path | None, executor: Any, progress: Any) -> pd.DataFrame:
    """Re-run the backends before and after; out-of-sample 'after' from the fold parameters.

    Parameters
    ----------
    trials, backends
        The dataset's trials (those in ``F`` are run) and the backends to confirm on.
    proto, base_config, model
        The probe protocol, the baseline model configuration ("before") and the fitted one ("after").
    F
        The scored trials (``trial``, ``cane``, ``k_field``), in the screens' order.
    final
        The cross-validated fit (``fit.specs`` and, per held-out cane, ``fold_specs``).
    anchor
        The screen at the last engine anchor: the fit's prediction, per fold and overall.
    baseline
        The screen from the baseline run, no effects: the linear screen's change without re-anchoring.
    out
        Where the runs' stores go (``out / "before"``, ``out / "after"``); nowhere when None.

    Returns
    -------
    pandas.DataFrame
        One row per backend: median and worst |ln k_sim / k_field| before, after and after out of
        sample, how far each engine's change is from the screen's, and the ok counts.
    """
    lkb0 = baseline.log_k
    keep = [t for t in trials if t.id in set(F.trial)]
    rb = run_trials(keep, backends, proto, base_config, out / "before" if out else None, executor=executor,
                    progress=progress).to_df()
    ra = run_trials(keep, backends, proto, model, out / "after" if out else None, executor=executor,
                    progress=progress).to_df()
    # held-out change per trial: the fold's parameters on the screen, relative to the baseline
    fold_change = np.full(len(F), np.nan)
    for cane, specs in final.fold_specs.items():
        m = (F.cane == cane).to_numpy()
        fold_change[m] = anchor.subset(m).predict(specs) - lkb0[m]
    full_change = anchor.predict(final.fit.specs) - lkb0
    # the linear screen alone, from the baseline run (no re-anchoring): how far the engines' change is
    # from what the screen would have said (for the anchor engine the anchored figure is close to
    # 0 by construction; this one is not)
    lin_change = baseline.predict(final.fit.specs) - lkb0
    lkf = np.log(F.k_field.to_numpy(float))
    rows = []
    for b in backends:
        lb = ok_log_k(rb, b, F.trial)
        la = ok_log_k(ra, b, F.trial)
        before = lb - lkf
        after = la - lkf
        after_cv = lb + fold_change - lkf
        dev = np.abs((la - lb) - full_change)
        dev0 = np.abs((la - lb) - lin_change)
        rows.append({"backend": b, "before_median": _stat(np.median, before), "before_worst": _stat(np.max, before),
                     "after_median": _stat(np.median, after), "after_worst": _stat(np.max, after),
                     "after_cv_median": _stat(np.median, after_cv), "after_cv_worst": _stat(np.max, after_cv),
                     "screen_vs_engine_max": _stat(np.max, dev), "linear_screen_vs_engine_max": _stat(np.max, dev0),
                     "n_ok_before": int(np.isfinite(lb).sum()), "n_ok_after": int(np.isfinite(la).sum())})
    return pd.DataFrame(rows)
