"""The paper's simulation studies through the runner: naive case, Method of Morris, sweep."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from canebench.cli import main
from canebench.execute.executors import SerialExecutor
from canebench.studies.paper import morris_configs, morris_study, naive_case, sweep_study, variance_between


@pytest.fixture(scope="module")
def trials(bundled_trials):
    return [t for t in bundled_trials if t.cane.id in ("b1c1", "b3c2")]


def test_variance_share_between_groups_closed_forms():
    # groups differ, no spread inside: all variance is between groups
    df = pd.DataFrame({"cane": list("aabb"), "log_ratio": [1.0, 1.0, 3.0, 3.0]})
    assert variance_between(df, "cane")["share_between"] == pytest.approx(1.0)
    # identical group means: none is
    df = pd.DataFrame({"cane": list("aabb"), "log_ratio": [0.0, 2.0, 0.0, 2.0]})
    assert variance_between(df, "cane")["share_between"] == pytest.approx(0.0)
    # a mix: between-SS 4 of total 6 (means 1 and 3 about 2; inside +-1 in group a only)
    df = pd.DataFrame({"cane": list("aabb"), "log_ratio": [0.0, 2.0, 3.0, 3.0]})
    assert variance_between(df, "cane")["share_between"] == pytest.approx(4.0 / 6.0)


def test_naive_case_uses_the_paper_preset_and_ranks_push_heights(tmp_path, trials):
    r = naive_case(trials, ["pinocchio"], tmp_path, SerialExecutor())
    t = r.to_df()
    assert len(t) == 6 and (t.status == "ok").all()
    meta = json.loads((tmp_path / "run.json").read_text())
    assert meta["model_config"]["modulus_pa"] == 4.57e9 and meta["model_config"]["stiffness_formula"] == "paper"
    # rank 1 is the highest push point of each cane
    for _, g in t.groupby("cane"):
        assert g.sort_values("height_rank").height_mm.is_monotonic_decreasing
    assert 0.0 <= r.variance.share_between.iloc[0] <= 1.0


def test_morris_design_and_analysis(tmp_path, trials):
    X, configs = morris_configs()
    assert X.shape == (20, 4) and len(configs) == 20
    assert {c.segments for c in configs} <= set(range(3, 21))
    assert all(-30 <= c.probe_angle_deg <= 30 and 1.82e9 <= c.modulus_pa <= 8.05e9 for c in configs)
    r = morris_study(trials[:1], ["pinocchio"], tmp_path, SerialExecutor())
    df = r.to_df()
    assert set(df.factor) == {"segments", "probe_angle", "modulus", "diameter_factor"}
    assert (df.mu_star >= 0).all() and (df.mu_star_conf >= 0).all()
    # E scales every joint spring: it must move the stiffness; and resuming reuses every point
    assert df.set_index("factor").mu_star["modulus"] > 0
    again = morris_study(trials[:1], ["pinocchio"], tmp_path, SerialExecutor())
    assert again.outcome.n_reused == 20 and again.outcome.n_run == 0
    pd.testing.assert_frame_equal(again.to_df(), df)


def test_sweep_finds_the_grid_minimum(tmp_path, trials):
    r = sweep_study(trials[:2], ["pinocchio"], tmp_path, SerialExecutor(), levels=3)
    grid = pd.read_csv(tmp_path / "sweep.csv")
    assert len(grid) == 2 * 9
    for tid, g in grid.groupby("trial"):
        best = r.best.set_index("trial").loc[tid]
        assert best.abs_log_ratio == pytest.approx(g.log_ratio.abs().min())
    assert set(r.summary) == {"pinocchio"}


def test_study_command_resumes_and_reports(tmp_path):
    out = tmp_path / "naive"
    args = ["study", "naive", "--trials", "b1c1*", "--backends", "pinocchio", "--out", str(out), "--quiet"]
    assert main(args) == 0
    assert (out / "naive.png").exists() and "naive case" in (out / "report.html").read_text()
    assert main(args) == 0  # rerun: everything reused
    assert json.loads((out / "run.json").read_text())["jobs_reused"] == 3
    assert np.isfinite(pd.read_csv(out / "naive.csv").log_ratio).all()


@pytest.mark.field
def test_findings_on_the_real_data(field_dir, tmp_path):
    from canebench.reports.findings import data_checks, findings

    d = data_checks(field_dir)
    # the published rig logs: 0.5 s per 0.5 mm sample (1 mm/s), trials of at most 44 s
    assert d["sample_period_s"] == pytest.approx(0.5, abs=0.01) and d["speed_mm_per_s"] == pytest.approx(1.0, abs=0.02)
    assert d["longest_trial_s"] <= 45 and len(d["trial1_not_highest"]) == 2
    for s in ("naive", "sweep"):
        assert main(["study", s, "--field", str(field_dir), "--trials", "b1*,b5*", "--backends", "pinocchio",
                     "--out", str(tmp_path), "--quiet", "--no-report"]) == 0
    topics = [t for t, _, _ in findings(tmp_path)]
    assert {"naive case", "push height", "where the error lies", "parameter sweep",
            "published data: protocol", "published data: push points"} <= set(topics)


# ---------------------------------------------------------------- Morris across engines


def _indices(values: dict) -> pd.DataFrame:
    rows = []
    for (trial, backend), mu in values.items():
        for f, v in zip(("modulus", "diameter_factor", "segments", "probe_angle"), mu):
            rows.append({"trial": trial, "backend": backend, "factor": f, "mu_star": v, "sigma": 0.1,
                         "mu_star_conf": 0.01, "note": ""})
    return pd.DataFrame(rows)


def test_morris_engine_comparison_by_hand():
    from canebench.studies.paper import morris_engine_comparison, morris_engine_sentence

    ref = (4.0, 3.0, 2.0, 1.0)
    idx = _indices({
        ("t1", "pinocchio"): ref, ("t2", "pinocchio"): ref, ("t3", "pinocchio"): ref,
        ("t1", "dart"): tuple(v * 1.0001 for v in ref), ("t2", "dart"): tuple(v * 1.0001 for v in ref),
        ("t3", "dart"): (np.nan,) * 4,  # not analysed on DART: left out of the comparison
        ("t1", "mujoco"): ref, ("t2", "mujoco"): (4.0, 3.0, 1.0, 2.5), ("t3", "mujoco"): ref,
    })
    e = morris_engine_comparison(idx).set_index("backend")
    assert e.loc["dart", "trials_both"] == 2 and e.loc["dart", "same_order_trials"] == 2
    assert e.loc["dart", "mean_kendall_tau"] == pytest.approx(1.0)
    assert e.loc["dart", "max_rel_mu_star_diff"] == pytest.approx(1e-4)
    assert bool(e.loc["dart", "same_overall_order"])
    # MuJoCo swaps the last two factors on t2: one discordant pair of six, tau = 4/6 there
    assert e.loc["mujoco", "trials_both"] == 3 and e.loc["mujoco", "same_order_trials"] == 2
    assert e.loc["mujoco", "same_top_factor_trials"] == 3
    assert e.loc["mujoco", "mean_kendall_tau"] == pytest.approx((1 + 4 / 6 + 1) / 3)
    assert e.loc["mujoco", "max_rel_mu_star_diff"] == pytest.approx(1.5)  # probe angle 2.5 against 1
    # by mean mu* the order holds on MuJoCo: segments 5/3, probe angle 1.5
    assert e.loc["mujoco", "overall_order"] == "modulus > diameter_factor > segments > probe_angle"
    assert "same on every engine" in morris_engine_sentence(e.reset_index())
    # make MuJoCo's mean order differ: it changes, and the sentence says so
    idx2 = idx.copy()
    idx2.loc[(idx2.backend == "mujoco") & (idx2.factor == "probe_angle"), "mu_star"] = 2.6
    e2 = morris_engine_comparison(idx2)
    assert not e2.set_index("backend").loc["mujoco", "same_overall_order"]
    assert "changes between engines" in morris_engine_sentence(e2)


# ---------------------------------------------------------------- truncation rule, resume, executors


@pytest.mark.field
def test_naive_case_with_the_truncation_rule(field_dir, tmp_path):
    from canebench.data.dataset import load_dataset

    trials = load_dataset(field_dir, "b5c2t3,b2c1t3,b3c3t1")
    r = naive_case(trials, ["pinocchio"], tmp_path, SerialExecutor(), truncate_contacts=True)
    t = r.to_df().set_index("trial")
    print(t[["partial", "k_field", "k_field_full", "log_ratio", "log_ratio_full"]])
    assert bool(t.loc["b5c2t3", "partial"]) and bool(t.loc["b2c1t3", "partial"])
    assert not bool(t.loc["b3c3t1", "partial"])
    # a full trial is scored exactly as without the rule (same field fit, same simulation)
    assert t.loc["b3c3t1", "k_field"] == t.loc["b3c3t1", "k_field_full"]
    assert t.loc["b3c3t1", "log_ratio"] == t.loc["b3c3t1", "log_ratio_full"]
    # a partial trial is scored on its own field slope and a shorter push
    assert t.loc["b2c1t3", "k_field"] != pytest.approx(t.loc["b2c1t3", "k_field_full"], rel=1e-3)
    # b5c2t3 cannot be scored whole (its elbow spoils the line), the partial trial can
    assert np.isnan(t.loc["b5c2t3", "log_ratio_full"]) and np.isfinite(t.loc["b5c2t3", "log_ratio"])
    s = pd.read_csv(tmp_path / "naive_truncation.csv").set_index("backend").loc["pinocchio"]
    assert s.partial == 2 and s.scored_whole == 2 and s.scored_truncated == 3
    again = naive_case(trials, ["pinocchio"], tmp_path, SerialExecutor(), truncate_contacts=True)
    assert again.outcome.n_run == 0  # both passes resume from the store


class _StopAfter:
    """A progress sink that interrupts the run after ``n`` results, as Ctrl-C would."""

    def __init__(self, n: int) -> None:
        self.n, self.seen = n, 0

    def start(self, total, reused, label=""):  # noqa: ANN001
        pass

    def update(self, job, result):  # noqa: ANN001
        self.seen += 1
        if self.seen >= self.n:
            raise KeyboardInterrupt

    def close(self):
        pass


def test_morris_resumes_after_an_interrupt(tmp_path, trials):
    cut = morris_study(trials[:1], ["pinocchio"], tmp_path, SerialExecutor(), progress=_StopAfter(7))
    assert cut.outcome.interrupted and len(cut.outcome.missing) == 13
    assert cut.to_df().mu_star.isna().all()  # not analysed: 7 of 20 points
    done = morris_study(trials[:1], ["pinocchio"], tmp_path, SerialExecutor())
    assert done.outcome.n_reused == 7 and done.outcome.n_run == 13 and not done.outcome.interrupted
    assert done.to_df().mu_star.notna().all()


def test_study_runs_on_the_dask_executor(tmp_path):
    out = tmp_path / "sweep"
    args = ["study", "sweep", "--trials", "b1c1t1", "--backends", "pinocchio", "--executor", "dask", "--jobs", "1",
            "--out", str(out), "--quiet", "--no-report"]
    assert main(args) == 0
    assert len(pd.read_csv(out / "sweep.csv")) == 25
    assert json.loads((out / "run.json").read_text())["executor"] == "dask"


def test_bench_morris_reports_every_engine_against_pinocchio():
    from canebench.studies.bench import bench_morris

    df = bench_morris(["pinocchio"], trials="b1c1t1", paper_runs=0)
    assert list(df.index) == ["pinocchio"] and df.loc["pinocchio", "runs"] == 20
    assert df.loc["pinocchio", "failed"] == 0 and df.loc["pinocchio", "study_cpu_s"] > 0
    assert {"cpu_per_run_s", "vs_pinocchio", "study_wall_2cores_s", "target_s", "meets_target"} <= set(df.columns)
