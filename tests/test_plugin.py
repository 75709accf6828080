"""The example plugin package, installed from scratch, registers itself
through the entry point and runs a trial (no change to canebench)."""

import subprocess
from pathlib import Path

import pandas as pd
import pytest
from venvtools import make_venv, pip_install

HERE = Path(__file__).resolve().parent
REPO = HERE.parent


@pytest.fixture(scope="module")
def plugin_env(tmp_path_factory):
    # the running environment gives canebench and the engines (works when
    # that environment is itself a venv); the plugin is installed the way a
    # user would, by pip, into the new environment only
    py = make_venv(tmp_path_factory.mktemp("plugin-venv"))
    r = pip_install(py, "--no-deps", str(HERE / "plugin_example"))
    assert r.returncode == 0, r.stderr
    return py


def test_plugin_is_discovered_and_runs_a_trial(plugin_env, tmp_path):
    r = subprocess.run([str(plugin_env), "-m", "canebench", "backends"], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert "linear" in r.stdout and "available" in r.stdout
    out = tmp_path / "run"
    r = subprocess.run([str(plugin_env), "-m", "canebench", "run", "--backends", "linear,pinocchio",
                        "--trials", "b1c1t1", "--set", "gravity=0", "--out", str(out), "--no-report"],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    res = pd.read_csv(out / "results.csv").set_index("backend")
    assert res.loc["linear", "status"] in ("ok", "unscored")
    # without gravity the chain is nearly linear over the push: the plugin's
    # linear answer and the exact nonlinear statics agree to within 1 %
    assert abs(res.loc["linear", "k_sim"] / res.loc["pinocchio", "k_sim"] - 1) < 0.01
    # and the plugin's k equals Pinocchio's linear compliance J K^-1 J^T exactly
    assert res.loc["linear", "k_sim"] == pytest.approx(res.loc["pinocchio", "k_linear"], rel=1e-9)


def test_plugin_absent_from_the_main_environment():
    # the main environment never had it: the registry must not invent it
    from canebench.registry import discover

    assert "linear" not in discover()
