"""``canebench discover``: the discovery workflow as one function.

1. Baseline: every trial probed on the baseline model through the job runner
   (``beam``: the converged beam reference; ``chain``: the beam-consistent
   chain on Pinocchio; ``paper``: the naive case, whose 2EI/L bias would
   otherwise be blamed on physics) and scored against field stiffness.
2. Obstruction onsets in the field traces (:mod:`.onsets`); trials with one
   are scored up to the onset, in the field and in every simulation.
3. Residual structure (:mod:`.structure`).
4. Forward selection over the library (:mod:`canebench.model.effects`) on the
   screening model (:mod:`.screen`): a candidate must lean the residuals its
   way (cluster-robust score test, sign flips over canes), gain out of sample
   (leave-one-cane-out), lower BIC and the held-out median; repeated until no
   candidate passes.
5. The fitted model (95 % cane-bootstrap intervals) as a model file; the
   baseline and the chosen backends re-run with it; before and after, out of
   sample.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ..data.dataset import Trial
from ..execute.pipeline import field_stage
from ..execute.runner import run_trials
from ..model.config import ModelConfig
from ..model.effects import EFFECTS, EffectSpec
from ..model.presets import PRESETS
from ..probe.protocol import PROTOCOLS
from .fit import Candidate, bootstrap_ci, cross_validate, direction_test_p, sign_flip_p
from .onsets import detect_onset
from .screen import trial_geometry
from .screenset import ScreenSet, predict_log_k
from .structure import between_share, structure_tests

BASELINES = {
    "beam": ("beam", "beam-consistent", "the converged geometrically exact beam (stated modulus, caliper-fit taper)"),
    "chain": ("pinocchio", "beam-consistent", "the beam-consistent chain (dual-length springs, 20 links), exact statics"),
    "paper": ("pinocchio", "paper", "the paper's naive case (K = 2EI/L, greedy 5 mm chain, E = 4.57 GPa)"),
}
#: effects screened by default (obstruction is handled per trial from the traces)
SCREENED = ("modulus_scale", "root_compliance", "rig_compliance", "base_flare", "probe_misalignment")
ALPHA = 0.05  # family-wise, split over the candidates of a step (Bonferroni)
MIN_OBSTRUCTED = 1  # trials with a detected onset needed to name the obstruction
STRUCTURE_ALPHA = 0.01  # Bonferroni-adjusted p below which residual structure counts as unexplained
MIN_REDUCTION = 0.05  # out-of-sample median |log ratio| must fall by at least this fraction


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

    def to_df(self) -> pd.DataFrame:
        return self.trials

    def to_json(self) -> dict[str, Any]:
        tr = [{"trial": r.trial, "obstruction_onset_mm": (None if not np.isfinite(r.obstruction_onset_mm)
                                                          else float(r.obstruction_onset_mm))}
              for r in self.trials.itertuples()]
        return {"baseline": self.baseline, "named": self.named, "unexplained": bool(self.unexplained),
                "gap": self.gap, "trials": tr, "stop_reason": self.stop_reason, "notes": self.notes,
                "selection": self.steps.to_dict("records"), "timing_s": self.timing,
                "between_cane_share": {"before": between_share(self.trials, "r_before"),
                                       "after_cv": between_share(self.trials, "r_after_cv")}}


def _features(trials: list[Trial], geoms: dict, fields: dict) -> pd.DataFrame:
    rows = []
    for t in trials:
        g = geoms.get(t.id)
        fr = fields[t.id]
        curv = math.nan
        if fr.fit is not None and fr.fit.displacement_mm is not None and len(fr.fit.displacement_mm) >= 8:
            x, f = fr.fit.displacement_mm, fr.fit.force_n
            h = len(x) // 2
            a = np.polyfit(x[:h], f[:h], 1)[0]
            b = np.polyfit(x[h:], f[h:], 1)[0]
            curv = float(b / a) if a > 0 else math.nan
        cal_s = []
        if g is not None:
            from ..model.chain import cane_curve, resolve_s

            curve = cane_curve(t.cane, PRESETS["default"])
            cal_s = [resolve_s(curve, c.where, t.cane.source, "calipers") for c in t.cane.calipers]
        rows.append({
            "trial": t.id, "cane": t.cane.id, "bush": t.bush, "trial_no": t.trial_no,
            "height_m": g.height if g else math.nan, "s_push_m": g.s_push if g else math.nan,
            "rel_push": g.s_push / float(np.max(g.s)) if g else math.nan,
            "diameter_mm": float(np.interp(g.s_push, g.s, g.d0)) * 1e3 if g else math.nan,
            "above_lowest_caliper_m": (g.s_push - min(cal_s)) if g and cal_s else math.nan,
            "k_field": fr.k, "curvature": curv,
        })
    return pd.DataFrame(rows)


def _l1_by_cane(r: np.ndarray, canes: np.ndarray) -> np.ndarray:
    uniq, inv = np.unique(canes, return_inverse=True)
    return np.bincount(inv, np.abs(r)) / np.bincount(inv)


def _gap(r: np.ndarray) -> dict[str, float]:
    a = np.abs(r[np.isfinite(r)])
    return {"median_abs_log_ratio": float(np.median(a)) if len(a) else math.nan,
            "worst_abs_log_ratio": float(np.max(a)) if len(a) else math.nan, "n": int(len(a))}


def discover(trials: list[Trial], baseline: str = "beam", backends: list[str] | None = None,
             out: str | Path | None = None, executor: Any = None, candidates: tuple[str, ...] | None = None,
             alpha: float = ALPHA, n_boot: int = 100, seed: int = 0, confirm: bool = True,
             max_effects: int = 3, progress: Any = None) -> DiscoveryResult:
    """Find, name and fit the missing physical effects; see the module docstring.

    Parameters
    ----------
    trials : list of Trial
    baseline : str
        ``beam`` (default), ``chain`` or ``paper`` (:data:`BASELINES`).
    backends : list of str, optional
        Engines re-run before and after with the fitted model (default: the baseline's).
    out : path, optional
        Folder for ``discovery.json``, ``discovery.csv``, ``model.yaml``, figures and the runner's stores.
    candidates : tuple of str, optional
        Effects screened (default :data:`SCREENED`).
    alpha : float
        Family-wise significance of one selection step (Bonferroni over candidates).
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
    outp = Path(out) if out is not None else None
    if outp is not None:
        outp.mkdir(parents=True, exist_ok=True)
    notes: list[str] = []
    timing: dict[str, float] = {}

    # -- field, obstruction onsets
    fields0 = field_stage(trials, proto.fit_window_mm)
    onsets: dict[str, float] = {}
    for tid, fr in fields0.items():
        if fr.fit is not None and fr.fit.usable and fr.fit.displacement_mm is not None:
            o = detect_onset(fr.fit.displacement_mm, fr.fit.force_n)
            if o is not None:
                onsets[tid] = o.onset_mm
    obstruction = ()
    if len(onsets) >= MIN_OBSTRUCTED:
        obstruction = (EffectSpec("obstruction", (), tuple(sorted((k, (("onset_mm", v),)) for k, v in onsets.items())),
                                  "per_trial"),)
    cfg_b = cfg0.replace(effects=obstruction)
    fields = field_stage(trials, proto.fit_window_mm, cfg_b)
    timing["field_s"] = time.perf_counter() - t_start

    # -- baseline simulation through the runner
    t1 = time.perf_counter()
    run = run_trials(trials, [base_backend], proto, cfg_b, outp / "baseline" if outp else None,
                     executor=executor, progress=progress)
    res = run.to_df()
    timing["baseline_s"] = time.perf_counter() - t1
    k_base = dict(zip(res.trial, res.k_sim.where(res.status == "ok")))

    # -- screening geometry
    t2 = time.perf_counter()
    geoms = {t.id: trial_geometry(t, cfg0) for t in trials}
    feats = _features(trials, geoms, fields)
    feats["obstruction_onset_mm"] = [onsets.get(t, math.nan) for t in feats.trial]
    feats["k_base"] = [k_base.get(t, math.nan) for t in feats.trial]
    feats["k_field"] = [fields[t].k for t in feats.trial]
    usable = np.isfinite(feats.k_base) & np.isfinite(feats.k_field) & (feats.k_base > 0) & (feats.k_field > 0)
    if usable.sum() < 6 or feats[usable].cane.nunique() < 3:
        from ..errors import InputError

        raise InputError("--field", "trials", f"only {int(usable.sum())} usable trials on "
                                              f"{feats[usable].cane.nunique()} canes: discovery needs 6 on 3")
    feats["log_k_field"] = np.log(feats.k_field)
    F = feats[usable].reset_index(drop=True)
    ss = ScreenSet.build([geoms[t] for t in F.trial])
    lkf = np.log(F.k_field.to_numpy(float))
    lkb = np.log(F.k_base.to_numpy(float))
    timing["screen_build_s"] = time.perf_counter() - t2

    # -- selection
    t3 = time.perf_counter()
    current: tuple[str, ...] = ()
    cv_cur = cross_validate(Candidate.of(()), ss, lkf, lkb)
    steps = []
    stop = ""
    while True:
        remaining = [c for c in candidates if c not in current]
        if not remaining or len(current) >= max_effects:
            stop = "every candidate is in the model" if not remaining else f"at most {max_effects} effects"
            break
        level = alpha / len(remaining)
        trials_here = []
        rows = {}
        for c in remaining:
            cand = Candidate.of(current + (c,))
            cv = cross_validate(cand, ss, lkf, lkb)
            # per held-out cane: mean |ln k_field/k_pred| before minus after (robust: one bad
            # trace cannot sink a cane, as it would under the Gaussian density)
            diff = _l1_by_cane(cv_cur.residual, ss.canes) - _l1_by_cane(cv.residual, ss.canes)
            # significance: do the current residuals lean the way the effect moves them, cane by cane?
            p = direction_test_p(c, ss, lkf, lkb, cv_cur.fit.specs, cv_cur.fit.s2, cv_cur.fit.t2, seed=seed)
            p_cv = sign_flip_p(diff, seed=seed)  # the held-out gain's own sign test, for the record
            trials_here.append((c, cv, float(diff.mean()), p))
            rows[c] = {"step": len(current) + 1, "model": "+".join(current + (c,)), "candidate": c,
                       "cv_gain_per_cane": float(diff.mean()),
                       "cv_nll_gain": float(np.mean([cv_cur.loss[k] - cv.loss[k] for k in cv.loss])),
                       "p": p, "p_heldout_gain": p_cv, "level": level, "aic": cv.fit.aic, "bic": cv.fit.bic,
                       "cv_median_abs": float(np.median(np.abs(cv.residual))),
                       "params": {s.name: dict(s.params) for s in cv.fit.specs}, "chosen": False}
        # the best of the significant candidates by held-out gain; BIC must agree, and the
        # out-of-sample median |log ratio| must fall by MIN_REDUCTION (a consistent but
        # negligible gain is not a physical effect worth naming)
        med_cur = float(np.median(np.abs(cv_cur.residual)))
        ok = [t for t in trials_here if t[2] > 0 and t[3] < level and t[1].fit.bic < cv_cur.fit.bic
              and np.median(np.abs(t[1].residual)) < (1 - MIN_REDUCTION) * med_cur]
        best = max(ok or trials_here, key=lambda t: t[2])
        c, cv, gain, p = best
        rows[c]["chosen"] = bool(ok)
        steps.extend(rows.values())
        if ok:
            current = current + (c,)
            cv_cur = cv
            continue
        red = 1 - float(np.median(np.abs(cv.residual))) / med_cur if med_cur > 0 else 0.0
        stop = (f"no candidate passes (best by held-out gain: {c}, {gain:.3g} in mean |ln| per cane, score test "
                f"p = {p:.3g} against {level:.3g}, median |ln| {100 * red:+.0f} %"
                f"{'; BIC does not improve' if cv.fit.bic >= cv_cur.fit.bic else ''})")
        break
    timing["selection_s"] = time.perf_counter() - t3

    final = cv_cur
    r_before = lkf - lkb
    r_after = final.residual
    F["r_before"] = r_before
    F["r_after_cv"] = r_after
    F["r_after_in"] = lkf - predict_log_k(ss, lkb, final.fit.specs)
    feats = feats.merge(F[["trial", "r_before", "r_after_cv", "r_after_in"]], on="trial", how="left")

    # -- intervals
    t4 = time.perf_counter()
    named = []
    ci = bootstrap_ci(final.fit, ss, lkf, lkb, n_boot=n_boot, seed=seed) if current else {}
    for spec in final.fit.specs:
        named.append({"effect": spec.name, "scope": "global", "params": dict(spec.params),
                      "ci95": {p: list(ci[(spec.name, p)]) for p, _ in spec.params if (spec.name, p) in ci},
                      "units": {p: EFFECTS[spec.name].parameters[p].unit for p, _ in spec.params}})
    if obstruction:
        named.append({"effect": "obstruction", "scope": "per_trial", "params": {},
                      "local": {k: {"onset_mm": v} for k, v in sorted(onsets.items())}, "ci95": {},
                      "n_trials": len(onsets)})
    timing["bootstrap_s"] = time.perf_counter() - t4

    # -- structure before and after
    sb = structure_tests(F, "r_before", seed=seed)
    sa = structure_tests(F, "r_after_cv", seed=seed)
    unexplained = bool(len(sa) and (sa.p_adj < STRUCTURE_ALPHA).any())
    gap = {"before": _gap(r_before), "after_cv": _gap(r_after), "after_in_sample": _gap(F.r_after_in.to_numpy())}
    model = cfg0.replace(effects=tuple(final.fit.specs) + obstruction)

    # -- confirm on the engines
    engines = pd.DataFrame()
    if confirm:
        t5 = time.perf_counter()
        engines = _confirm(trials, backends or [base_backend], proto, cfg_b, model, F, ss, lkb, final, outp, executor,
                           progress)
        timing["confirm_s"] = time.perf_counter() - t5
        gap["per_backend"] = {r.backend: {k: getattr(r, k) for k in (
            "before_median", "before_worst", "after_median", "after_worst", "after_cv_median", "after_cv_worst",
            "screen_vs_engine_max")} for r in engines.itertuples()}
    timing["total_s"] = time.perf_counter() - t_start
    result = DiscoveryResult(baseline, named, unexplained, gap, feats, pd.DataFrame(steps), sb, sa, model, engines,
                             stop, notes, timing)
    result.notes.append(f"baseline: {base_text}")
    if any(t.cane.provenance.get("assumptions") for t in trials):
        for a in dict.fromkeys(a for t in trials for a in t.cane.provenance.get("assumptions", [])):
            if a.startswith("geometry"):
                result.notes.append(a)
    if outp is not None:
        write_outputs(result, outp, preset, ci)
    return result


def _confirm(trials, backends, proto, cfg_b, model, F, ss, lkb, final, outp, executor, progress) -> pd.DataFrame:
    """Re-run the backends before and after; out-of-sample 'after' from the fold parameters."""
    keep = [t for t in trials if t.id in set(F.trial)]
    rb = run_trials(keep, backends, proto, cfg_b, outp / "before" if outp else None, executor=executor,
                    progress=progress).to_df()
    ra = run_trials(keep, backends, proto, model, outp / "after" if outp else None, executor=executor,
                    progress=progress).to_df()
    # held-out change per trial: the fold's parameters on the screen, relative to the baseline
    fold_change = np.full(len(F), np.nan)
    for cane, specs in final.fold_specs.items():
        m = (F.cane == cane).to_numpy()
        sub = ss.subset(m)
        fold_change[m] = predict_log_k(sub, lkb[m], specs) - lkb[m]
    full_change = predict_log_k(ss, lkb, final.fit.specs) - lkb
    lkf = np.log(F.k_field.to_numpy(float))
    rows = []
    for b in backends:
        kb = rb[rb.backend == b].set_index("trial").k_sim.where(rb[rb.backend == b].set_index("trial").status == "ok")
        ka = ra[ra.backend == b].set_index("trial").k_sim.where(ra[ra.backend == b].set_index("trial").status == "ok")
        lb = np.log(kb.reindex(F.trial).to_numpy(float))
        la = np.log(ka.reindex(F.trial).to_numpy(float))
        before = lb - lkf
        after = la - lkf
        after_cv = lb + fold_change - lkf
        dev = np.abs((la - lb) - full_change)
        rows.append({"backend": b, "before_median": float(np.nanmedian(np.abs(before))),
                     "before_worst": float(np.nanmax(np.abs(before))),
                     "after_median": float(np.nanmedian(np.abs(after))), "after_worst": float(np.nanmax(np.abs(after))),
                     "after_cv_median": float(np.nanmedian(np.abs(after_cv))),
                     "after_cv_worst": float(np.nanmax(np.abs(after_cv))),
                     "screen_vs_engine_max": float(np.nanmax(dev)) if np.isfinite(dev).any() else math.nan,
                     "n_ok_before": int(np.isfinite(lb).sum()), "n_ok_after": int(np.isfinite(la).sum())})
    return pd.DataFrame(rows)


def write_outputs(res: DiscoveryResult, out: Path, preset: str, ci: dict) -> None:
    from ..execute.provenance import provenance
    from ..model.modelfile import write_model_file

    doc = res.to_json()
    backends = sorted(set(res.engines.backend) if len(res.engines) else set()) or [BASELINES[res.baseline][0]]
    prov = provenance(backends, PROTOCOLS["fast"], res.config)
    doc["provenance"] = {k: prov[k] for k in ("canebench", "git_commit", "created", "python", "engines", "protocol",
                                              "model_config")}
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
    write_model_file(out / "model.yaml", res.config, preset, ci95,
                     {"produced_by": "canebench discover", "baseline": res.baseline,
                      **{k: doc["provenance"][k] for k in ("canebench", "git_commit", "created", "engines")}})
    from canebench.reports.build import build_report
    from canebench.reports.discovery import figures

    figures(out)
    build_report(out)
