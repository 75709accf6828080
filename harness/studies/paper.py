"""The paper's simulation studies on any set of engines: the naive case, the
Method of Morris and the modulus x diameter-factor sweep.

Each is a plain function that builds a job list, submits it to the one
runner (resumable in its run folder, on any executor), analyses the results
and writes its tables; figures and report sections are built from those
files by :mod:`canebench.reports.paper`. The paper's settings:

* naive case: E = 4.57 GPa for every cane, measured diameters (factor 1),
  K = 2EI/L, the greedy 5 mm chain (the ``paper`` preset);
* Morris: segments 3-20, probe angle -30..30 degrees, modulus 1.82-8.05 GPa,
  diameter factor 0-1; 6 levels, 4 trajectories, one analysis per trial and
  engine on the raw simulated stiffness (SALib, fixed seed);
* sweep: modulus x diameter factor, 5 uniform levels each over the Morris
  bounds; per trial the lowest |log ratio| and where it lies.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ..execute.executors import Executor
from ..execute.pipeline import field_stage, make_jobs
from ..execute.progress import Progress
from ..execute.runner import RunOutcome, run_jobs
from ..model.config import ModelConfig
from ..model.presets import PRESETS
from ..probe.protocol import PROTOCOLS, Protocol

MORRIS_FACTORS = {  # name -> (bounds, the ModelConfig field it sets)
    "segments": ((3, 20), "segments"),
    "probe_angle": ((-30.0, 30.0), "probe_angle_deg"),
    "modulus": ((1.82e9, 8.05e9), "modulus_pa"),
    "diameter_factor": ((0.0, 1.0), "diameter_factor"),
}
MORRIS_LEVELS, MORRIS_TRAJECTORIES, MORRIS_SEED = 6, 4, 20240515
SWEEP_LEVELS = 5


def study_fields(trials: list, proto: Protocol, truncate_contacts: bool = False) -> dict:
    """Field stiffness of each distinct trial: whole trials, or under the contact truncation rule."""
    unique = list({t.id: t for t in trials}.values())
    if truncate_contacts:
        from .contact import contact_fields

        return contact_fields(unique, proto.fit_window_mm)
    return field_stage(unique, proto.fit_window_mm)


def _run(trials: list, backends: list[str], configs: list[ModelConfig], labels: list[dict[str, Any]],
         out: Path, executor: Executor | None, protocol: Protocol | None, progress: Progress | None,
         meta: dict[str, Any], truncate_contacts: bool = False, fields: dict | None = None,
         **kw: Any) -> RunOutcome:
    """Jobs for (trial, configuration) pairs on every backend, through the runner (resumable in ``out``).

    With ``truncate_contacts`` a trial with a detected contact is scored only up to
    it (:func:`canebench.studies.contact.contact_fields`): its field stiffness is the
    partial trial's and its simulation pushes only as far.
    """
    proto = protocol or PROTOCOLS["fast"]
    fields = fields if fields is not None else study_fields(trials, proto, truncate_contacts)
    jobs = make_jobs(trials, backends, proto, configs, fields, labels=labels)
    meta = {**meta, "truncate_contacts": bool(truncate_contacts)}
    return run_jobs(jobs, out, executor, fields=fields, progress=progress, meta=meta, with_traces=False, **kw)


def _save(df: pd.DataFrame, path: Path) -> None:
    from ..execute.store import atomic_csv

    atomic_csv(df, path)


# ---------------------------------------------------------------- naive case


@dataclass
class NaiveResult:
    """Per trial and engine: simulated against field stiffness under the paper's naive model."""

    table: pd.DataFrame  # naive.csv
    by_rank: pd.DataFrame  # |log ratio| by push-height rank (1 = highest) and engine
    variance: pd.DataFrame  # share of the log-ratio variance between canes, per engine
    outcome: RunOutcome
    truncation: pd.DataFrame | None = None  # with truncate_contacts: the error with and without the rule

    def to_df(self) -> pd.DataFrame:
        return self.table


def naive_case(trials: list, backends: list[str], out: Path, executor: Executor | None = None,
               protocol: Protocol | None = None, progress: Progress | None = None,
               meta: dict[str, Any] | None = None, truncate_contacts: bool = False, **kw: Any) -> NaiveResult:
    """The paper's naive case on every engine; writes ``naive.csv``, ``naive_by_rank.csv``, ``naive_variance.csv``.

    With ``truncate_contacts`` every trial with a detected contact is scored only up
    to it (a partial trial, the paper's rule), and the whole trials are scored too
    (same store: the unchanged trials are not simulated twice): ``naive.csv`` holds
    the partial-trial scores beside the whole-trial ones (``k_field_full``,
    ``log_ratio_full``) and ``naive_truncation.csv`` the error with and without the rule.
    """
    cfg = PRESETS["paper"]
    proto = protocol or PROTOCOLS["fast"]
    cols = ["trial", "bush", "cane", "push_point", "backend", "height_mm", "diameter_mm", "k_sim", "k_field",
            "log_ratio", "status", "reason"]
    base_meta = {**(meta or {}), "study": "naive", "model_config": cfg.to_dict()}
    full = None
    if truncate_contacts:  # the whole trials first: the comparison, and most of the jobs
        full = _run(trials, backends, [cfg] * len(trials), [{"study": "naive"}] * len(trials), out, executor, proto,
                    progress, base_meta, **kw)
        if full.interrupted:
            return NaiveResult(full.results.reindex(columns=cols), pd.DataFrame(), pd.DataFrame(), full)
        kw = {**kw, "fresh": False}  # the second pass must reuse what the first stored
    fields = study_fields(trials, proto, truncate_contacts)
    outcome = _run(trials, backends, [cfg] * len(trials), [{"study": "naive"}] * len(trials), out, executor, proto,
                   progress, base_meta, truncate_contacts=truncate_contacts, fields=fields, **kw)
    res = outcome.results
    table = res[cols].copy()
    truncation = None
    if full is not None:
        partial = {t for t, fr in fields.items()
                   if fr.fit is None and fr.reason.startswith("excluded")
                   or fr.fit is not None and any(fl.startswith("partial trial") for fl in fr.fit.flags)}
        table["partial"] = table.trial.isin(partial)
        f = full.results.set_index(["trial", "backend"])
        key = list(zip(table.trial, table.backend))
        table["k_field_full"] = [f.k_field.get(k, np.nan) for k in key]
        table["k_sim_full"] = [f.k_sim.get(k, np.nan) for k in key]
        table["log_ratio_full"] = [f.log_ratio.get(k, np.nan) if f.status.get(k) == "ok" else np.nan for k in key]
        truncation = truncation_summary(table)
        _save(truncation, out / "naive_truncation.csv")
    # push-height rank within each cane: 1 = the highest push point
    table["height_rank"] = table.groupby(["cane", "backend"]).height_mm.rank(ascending=False, method="first")
    ok = table[table.status == "ok"].copy()
    ok["abs_log_ratio"] = ok.log_ratio.abs()
    by_rank = (ok.groupby(["backend", "height_rank"]).abs_log_ratio.agg(["median", "mean", "count"])
               .reset_index())
    variance = pd.DataFrame([{"backend": b, **variance_between(g, "cane")} for b, g in ok.groupby("backend")])
    _save(table, out / "naive.csv")
    _save(by_rank, out / "naive_by_rank.csv")
    _save(variance, out / "naive_variance.csv")
    return NaiveResult(table, by_rank, variance, outcome, truncation)


def truncation_summary(table: pd.DataFrame) -> pd.DataFrame:
    """Per engine: the naive-case error over whole trials against the error under the truncation rule."""
    rows = []
    for b, g in table.groupby("backend"):
        whole = g.log_ratio_full.dropna()
        trunc = g.log_ratio[g.status == "ok"].dropna()
        part = g[g.partial]
        both = part.dropna(subset=["log_ratio", "log_ratio_full"])
        rows.append({"backend": b, "trials": len(g), "partial": int(len(part)),
                     "partial_unscorable": int(part.log_ratio.isna().sum()),
                     "scored_whole": len(whole), "scored_truncated": len(trunc),
                     "median_abs_log_ratio_whole": float(whole.abs().median()) if len(whole) else np.nan,
                     "median_abs_log_ratio_truncated": float(trunc.abs().median()) if len(trunc) else np.nan,
                     "partial_median_abs_whole": float(both.log_ratio_full.abs().median()) if len(both) else np.nan,
                     "partial_median_abs_truncated": float(both.log_ratio.abs().median()) if len(both) else np.nan})
    return pd.DataFrame(rows)


def variance_between(df: pd.DataFrame, group: str, value: str = "log_ratio") -> dict[str, float]:
    """Share of ``value``'s variance between ``group``s (one-way sum-of-squares split)."""
    y = df[value].to_numpy(float)
    if len(y) < 2:
        return {"n": len(y), "share_between": float("nan")}
    grand = y.mean()
    ss_tot = float(((y - grand) ** 2).sum())
    ss_between = float(sum(len(g) * (g[value].mean() - grand) ** 2 for _, g in df.groupby(group)))
    return {"n": len(y), "groups": df[group].nunique(), "share_between": ss_between / ss_tot if ss_tot > 0 else 0.0}


# ---------------------------------------------------------------- Method of Morris


def morris_problem() -> dict[str, Any]:
    return {"num_vars": len(MORRIS_FACTORS), "names": list(MORRIS_FACTORS),
            "bounds": [list(b) for b, _ in MORRIS_FACTORS.values()]}


def morris_configs(base: ModelConfig | None = None) -> tuple[np.ndarray, list[ModelConfig]]:
    """SALib's Morris design (fixed seed) and the model configuration of each row."""
    from SALib.sample import morris as morris_sample

    base = base or PRESETS["paper"]
    X = morris_sample.sample(morris_problem(), N=MORRIS_TRAJECTORIES, num_levels=MORRIS_LEVELS, seed=MORRIS_SEED)
    configs = []
    for row in X:
        ch = {}
        for (name, (_, fld)), v in zip(MORRIS_FACTORS.items(), row):
            ch[fld] = int(round(v)) if name == "segments" else float(v)
        configs.append(base.replace(**ch))
    return X, configs


@dataclass
class MorrisResult:
    """mu*, sigma and mu*_conf per trial, engine and factor (``morris.csv``)."""

    indices: pd.DataFrame
    runs: pd.DataFrame  # every simulated point (morris_runs.csv)
    ranking: pd.DataFrame  # factor ranking by mean mu* per engine
    outcome: RunOutcome
    engines: pd.DataFrame | None = None  # does the ranking change between engines (morris_engines.csv)

    def to_df(self) -> pd.DataFrame:
        return self.indices


def morris_study(trials: list, backends: list[str], out: Path, executor: Executor | None = None,
                 protocol: Protocol | None = None, progress: Progress | None = None,
                 meta: dict[str, Any] | None = None, output: str = "k_sim", truncate_contacts: bool = False,
                 **kw: Any) -> MorrisResult:
    """Method of Morris per trial and engine on ``output`` (``k_sim``, the paper's, or ``log_ratio``)."""
    from SALib.analyze import morris as morris_analyze

    X, configs = morris_configs()
    n = len(configs)
    all_trials = [t for t in trials for _ in range(n)]
    all_configs = [c for _ in trials for c in configs]
    labels = [{"study": "morris", "sample": i} for _ in trials for i in range(n)]
    outcome = _run(all_trials, backends, all_configs, labels, out, executor, protocol, progress,
                   {**(meta or {}), "study": "morris", "design": {"levels": MORRIS_LEVELS,
                    "trajectories": MORRIS_TRAJECTORIES, "seed": MORRIS_SEED, "problem": morris_problem()}},
                   truncate_contacts=truncate_contacts, **kw)
    runs = outcome.results.reindex(columns=["trial", "backend", "sample", "k_sim", "k_field", "log_ratio", "status",
                                            "reason", "cpu_s", "n_links", "dt"])
    problem, rows = morris_problem(), []
    for (tid, b), g in runs.groupby(["trial", "backend"], sort=False):
        g = g.sort_values("sample")
        y = g[output].to_numpy(float)
        if len(g) != n or not np.all(np.isfinite(y)):
            bad = g[~np.isfinite(g[output].to_numpy(float))]
            why = bad.reason.iloc[0] if len(bad) else f"{len(g)} of {n} points"
            for name in problem["names"]:
                rows.append({"trial": tid, "backend": b, "factor": name, "mu_star": np.nan, "sigma": np.nan,
                             "mu_star_conf": np.nan, "note": f"not analysed: {why}"})
            continue
        r = morris_analyze.analyze(problem, X, y, num_levels=MORRIS_LEVELS, seed=MORRIS_SEED)
        for i, name in enumerate(problem["names"]):
            rows.append({"trial": tid, "backend": b, "factor": name, "mu_star": float(r["mu_star"][i]),
                         "sigma": float(r["sigma"][i]), "mu_star_conf": float(r["mu_star_conf"][i]), "note": ""})
    indices = pd.DataFrame(rows)
    ranking = (indices.dropna(subset=["mu_star"]).groupby(["backend", "factor"]).mu_star.mean().reset_index())
    ranking["rank"] = ranking.groupby("backend").mu_star.rank(ascending=False).astype(int)
    engines = morris_engine_comparison(indices)
    _save(indices, out / "morris.csv")
    _save(runs, out / "morris_runs.csv")
    _save(ranking.sort_values(["backend", "rank"]), out / "morris_ranking.csv")
    _save(engines, out / "morris_engines.csv")
    return MorrisResult(indices, runs, ranking, outcome, engines)


def morris_engine_comparison(indices: pd.DataFrame, reference: str = "pinocchio") -> pd.DataFrame:
    """Does the factor ranking change between engines? One row per engine against the reference.

    The reference is Pinocchio when present (the exact statics every dynamic
    engine converges to), else the first engine. Over the trials analysed on
    both: on how many the whole factor order (by mu*) and the top factor agree,
    the mean Kendall tau between the two orders, and the largest relative
    difference of any mu*; and whether the overall ranking (by mean mu*) is the same.
    """
    from scipy.stats import kendalltau

    ok = indices.dropna(subset=["mu_star"])
    backends = sorted(ok.backend.unique())
    if not backends:
        return pd.DataFrame()
    ref = reference if reference in backends else backends[0]
    mu = ok.pivot_table(index=["trial", "factor"], columns="backend", values="mu_star")
    overall = ok.groupby(["backend", "factor"]).mu_star.mean().unstack("factor")
    order = {b: " > ".join(overall.loc[b].sort_values(ascending=False).index) for b in backends}
    rows = []
    for b in backends:
        both = mu[[ref, b]].dropna().unstack("factor")
        trials = both.index
        same = top = 0
        taus = []
        for t in trials:
            a_, b_ = both.loc[t, ref], both.loc[t, b]
            same += list(a_.sort_values(ascending=False).index) == list(b_.sort_values(ascending=False).index)
            top += a_.idxmax() == b_.idxmax()
            taus.append(kendalltau(a_.to_numpy(), b_.to_numpy()).statistic)
        rel = (mu[b] / mu[ref] - 1).abs().dropna()
        rows.append({"backend": b, "reference": ref, "trials_both": len(trials),
                     "trials_analysed": int(ok[ok.backend == b].trial.nunique()),
                     "same_order_trials": int(same), "same_top_factor_trials": int(top),
                     "mean_kendall_tau": float(np.nanmean(taus)) if taus else np.nan,
                     "max_rel_mu_star_diff": float(rel.max()) if len(rel) else np.nan,
                     "median_rel_mu_star_diff": float(rel.median()) if len(rel) else np.nan,
                     "overall_order": order[b], "same_overall_order": order[b] == order[ref]})
    return pd.DataFrame(rows)


def morris_engine_sentence(engines: pd.DataFrame) -> str:
    """One sentence answering "does the factor ranking change between engines?" from ``morris_engines.csv``."""
    if engines is None or not len(engines):
        return "No Morris indices to compare."
    ref = engines.reference.iloc[0]
    others = engines[engines.backend != ref]
    if not len(others):
        return f"Only one engine ({ref}) was run: nothing to compare."
    same = bool(others.same_overall_order.all())
    head = (f"The overall factor ranking (by mean mu*) is the same on every engine: {engines.overall_order.iloc[0]}."
            if same else "The overall factor ranking (by mean mu*) changes between engines: "
            + "; ".join(f"{r.backend}: {r.overall_order}" for r in engines.itertuples()) + ".")
    per = "; ".join(f"{r.backend} {r.same_order_trials}/{r.trials_both} (largest mu* difference "
                    f"{r.max_rel_mu_star_diff:.1e})" for r in others.itertuples())
    return f"{head} Per trial, the full order agrees with {ref}'s on: {per}."


# ---------------------------------------------------------------- parameter sweep


@dataclass
class SweepResult:
    """Every grid point (``sweep.csv``) and per trial the best one (``sweep_best.csv``)."""

    grid: pd.DataFrame
    best: pd.DataFrame
    summary: dict[str, Any] = field(default_factory=dict)
    outcome: RunOutcome | None = None

    def to_df(self) -> pd.DataFrame:
        return self.grid


def sweep_study(trials: list, backends: list[str], out: Path, executor: Executor | None = None,
                protocol: Protocol | None = None, progress: Progress | None = None,
                meta: dict[str, Any] | None = None, levels: int = SWEEP_LEVELS, truncate_contacts: bool = False,
                **kw: Any) -> SweepResult:
    """Modulus x diameter factor over the Morris bounds; the best point per trial and whether it is on a bound."""
    (e_lo, e_hi), _ = MORRIS_FACTORS["modulus"]
    (f_lo, f_hi), _ = MORRIS_FACTORS["diameter_factor"]
    Es, Fs = np.linspace(e_lo, e_hi, levels), np.linspace(f_lo, f_hi, levels)
    grid_cfg = [(float(E), float(f)) for E in Es for f in Fs]
    base = PRESETS["paper"]
    configs = [base.replace(modulus_pa=E, diameter_factor=f) for E, f in grid_cfg]
    all_trials = [t for t in trials for _ in configs]
    labels = [{"study": "sweep", "modulus_pa": E, "diameter_factor": f} for _ in trials for E, f in grid_cfg]
    outcome = _run(all_trials, backends, [c for _ in trials for c in configs], labels, out, executor, protocol,
                   progress, {**(meta or {}), "study": "sweep", "levels": levels}, truncate_contacts=truncate_contacts,
                   **kw)
    res = outcome.results
    grid = res[["trial", "backend", "modulus_pa", "diameter_factor", "k_sim", "k_field", "log_ratio", "status"]]
    ok = grid[grid.status == "ok"].copy()
    ok["abs_log_ratio"] = ok.log_ratio.abs()
    best = ok.loc[ok.groupby(["trial", "backend"]).abs_log_ratio.idxmin()].copy()
    best["modulus_on_bound"] = np.where(np.isclose(best.modulus_pa, e_hi), "high",
                                        np.where(np.isclose(best.modulus_pa, e_lo), "low", ""))
    best["factor_on_bound"] = np.where(np.isclose(best.diameter_factor, f_hi), "high",
                                       np.where(np.isclose(best.diameter_factor, f_lo), "low", ""))
    # still more than 2x too soft at the stiffest corner of the box: the answer lies outside it
    best["too_soft_2x"] = best.log_ratio < -np.log(2)
    summary = {}
    for b, g in best.groupby("backend"):
        summary[b] = {"trials": int(len(g)), "best_at_highest_modulus": int((g.modulus_on_bound == "high").sum()),
                      "best_on_a_bound": int(((g.modulus_on_bound != "") | (g.factor_on_bound != "")).sum()),
                      "still_2x_too_soft": int(g.too_soft_2x.sum()),
                      "median_abs_log_ratio_best": float(g.abs_log_ratio.median())}
    _save(grid, out / "sweep.csv")
    _save(best, out / "sweep_best.csv")
    (out / "sweep_summary.json").write_text(json.dumps(summary, indent=1))
    return SweepResult(grid, best, summary, outcome)
