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
