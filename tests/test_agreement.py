"""The agreement gate: every engine against Pinocchio and the committed
baseline, on a subset fast enough for every submission (the full gate is
``canebench agree``)."""

import dataclasses
from pathlib import Path

import pandas as pd
import pytest

from canebench.studies.agreement import TOL_BASELINE, agreement_table, baseline_path, check, pairwise
from canebench.backends.mujoco_backend import MujocoBackend
from canebench.cli import main
from canebench.model.config import ModelConfig
from canebench.probe.protocol import PROTOCOLS
from canebench.registry import register_backend
from canebench.execute.runner import run_trials

SUBSET = "b1c1t1,b2c2t2,b4c3t3,b6c1t2"
ENGINES = ["mujoco", "dart", "exudyn", "pybullet", "pinocchio"]


@pytest.fixture(scope="module")
def subset_results(bundled_trials):
    trials = [t for t in bundled_trials if t.id in SUBSET.split(",")]
    res = run_trials(trials, ENGINES, PROTOCOLS["fast"], ModelConfig(), jobs=2).results
    return res


@pytest.fixture(scope="module")
def baseline():
    return pd.read_csv(baseline_path("fast"))


def test_committed_baseline_covers_every_bundled_trial_and_engine(baseline):
    # the chain engines, plus the continuum engines and their beam reference (tests/test_continuum.py)
    assert set(baseline.backend) == set(ENGINES) | {"mujoco_rod", "exudyn_beam", "beam"}
    assert baseline.groupby("backend").trial.nunique().eq(54).all()


def test_unmodified_engines_pass_the_gate(subset_results, baseline):
    table = agreement_table(subset_results)
    gate = check(table, baseline)
    assert gate.ok, gate.violations.to_string()
    assert table[table.backend == "pybullet"].rel_to_ref.abs().max() < 1e-2
    for b in ("mujoco", "dart", "exudyn"):
        assert table[table.backend == b].rel_to_ref.abs().max() < 5e-3


def test_pairwise_summary(subset_results):
    pairs = pairwise(subset_results)
    assert len(pairs) == 10 and (pairs.n == 4).all()
    assert (pairs.max_abs_log_ratio < 5e-3).all()


class StiffMujoco(MujocoBackend):
    """A deliberately broken engine: its joint springs are 5 % too stiff."""

    name = "mujoco_stiff"

    def build(self, chain, proto):
        return super().build(dataclasses.replace(chain, stiffness=chain.stiffness * 1.05), proto)


def test_a_broken_backend_fails_the_gate(bundled_trials, baseline):
    register_backend(StiffMujoco)
    trials = [t for t in bundled_trials if t.id in ("b1c1t1", "b2c2t2")]
    res = run_trials(trials, ["mujoco_stiff", "pinocchio"], PROTOCOLS["fast"], ModelConfig()).results
    res["backend"] = res.backend.replace({"mujoco_stiff": "mujoco"})  # it claims to be MuJoCo
    gate = check(agreement_table(res), baseline)
    assert not gate.ok
    v = gate.violations
    assert set(v.check) == {"vs pinocchio", "vs baseline"}
    assert set(v.trial) == {"b1c1t1", "b2c2t2"} and set(v.backend) == {"mujoco"}
    # springs 5 % stiffer make the chain 5 % stiffer: the gate measures it
    assert v[v.check == "vs baseline"].value.between(0.04, 0.06).all()


def test_failures_must_match_the_baseline(subset_results, baseline):
    table = agreement_table(subset_results)
    table.loc[table.backend == "dart", ["status", "reason"]] = ["failed", "unsettled at step 3"]
    v = check(table, baseline).violations
    assert (v[v.backend == "dart"].check == "status").all() and len(v) == 4


def test_agree_cli_passes_and_fails(tmp_path: Path, baseline):
    out = tmp_path / "agree"
    assert main(["agree", "--backends", "mujoco,pinocchio", "--trials", "b1c1t1", "--out", str(out)]) == 0
    assert (out / "agreement.csv").exists() and (out / "pairwise.csv").exists()
    assert (out / "agreement_heatmap.png").exists() and (out / "report.html").exists()
    tampered = baseline.copy()
    tampered.loc[tampered.backend == "mujoco", "k_sim"] *= 1 + 3 * TOL_BASELINE
    bpath = tmp_path / "tampered.csv"
    tampered.to_csv(bpath, index=False)
    assert main(["agree", "--backends", "mujoco,pinocchio", "--trials", "b1c1t1", "--out", str(tmp_path / "b"),
                 "--baseline", str(bpath)]) == 1
    v = pd.read_csv(tmp_path / "b" / "violations.csv")
    assert list(v.check) == ["vs baseline"] and v.backend.iloc[0] == "mujoco"
