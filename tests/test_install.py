"""A non-editable install (``pip install .``) into a fresh virtual environment
contains every subpackage and runs a trial: setup.py's package discovery
cannot leave a new subpackage out of the wheel."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pandas as pd
import pytest
from venvtools import make_venv, pip_install

REPO = Path(__file__).resolve().parent.parent
ROOTS = {"harness": "canebench", "backends": "canebench/backends", "canes": "canebench/canes",
         "reports": "canebench/reports"}


def repo_packages() -> set[str]:
    out = set()
    for folder, target in ROOTS.items():
        for init in (REPO / folder).rglob("__init__.py"):
            rel = init.parent.relative_to(REPO / folder)
            out.add(str(Path(target) / rel).replace("/.", ""))
    return {p.rstrip("/") for p in out}


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    py = make_venv(tmp_path_factory.mktemp("wheel-venv"))
    r = pip_install(py, "--no-deps", str(REPO))
    assert r.returncode == 0, r.stdout + r.stderr
    return py


def test_wheel_holds_every_subpackage(installed):
    code = ("import canebench, json, pathlib; root = pathlib.Path(canebench.__file__).parent; "
            "print(json.dumps({'file': canebench.__file__, 'pkgs': sorted(str(p.parent.relative_to(root.parent)) "
            "for p in root.rglob('__init__.py'))}))")
    r = subprocess.run([str(installed), "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    # imported from the new environment, not from the source tree
    assert str(installed.parent.parent) in d["file"] and "site-packages" in d["file"]
    missing = repo_packages() - set(d["pkgs"])
    assert not missing, f"packages left out of the wheel: {sorted(missing)}"


def test_installed_package_runs_a_trial(installed, tmp_path):
    out = tmp_path / "run"
    r = subprocess.run([str(installed), "-m", "canebench", "run", "--backends", "pinocchio", "--trials", "b1c1t1",
                        "--out", str(out), "--no-report", "--quiet"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    res = pd.read_csv(out / "results.csv")
    assert list(res.status) == ["ok"] and res.k_sim.iloc[0] > 0
