"""The PyElastica plugin (plugins/canebench-pyelastica): installed by pip from
its folder into a fresh virtual environment, discovered through the
``canebench.backends`` entry point only, and run on one bundled trial.

pip fetches pyelastica and its dependencies (numba, llvmlite, cma) from the
package index; where that is impossible (no index, no network) the test is
skipped with pip's message. The install and the first run (numba compiles
PyElastica's kernels) take 45 s of CPU, 1-2.5 min of wall time on a shared
machine: marked ``slow`` (``pytest -m slow tests/test_pyelastica_plugin.py``).
The default suite keeps the fast checks: the plugin's packaging (its entry
point names a class its module defines), canebench never importing it, and the
model in process where pyelastica is installed.
"""

import os
import re
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest
from venvtools import make_venv, pip_install

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
PLUGIN = REPO / "plugins" / "canebench-pyelastica"


@pytest.fixture(scope="module")
def elastica_env(tmp_path_factory):
    py = make_venv(tmp_path_factory.mktemp("pyelastica-venv"))
    # with its dependencies (pyelastica, numba, llvmlite, cma) from the index; the running
    # environment provides canebench, numpy, scipy and the engines
    r = pip_install(py, str(PLUGIN), timeout=900)
    if r.returncode != 0:
        tail = "\n".join((r.stderr or r.stdout).strip().splitlines()[-6:])
        pytest.skip(f"cannot install the PyElastica plugin here (pip install {PLUGIN.name} failed):\n{tail}")
    return py


def _run(py, *args, timeout=600):
    env = {**os.environ, "NUMBA_CACHE_DIR": str(Path(py).parent.parent / "numba-cache")}
    return subprocess.run([str(py), "-m", "canebench", *args], capture_output=True, text=True, timeout=timeout,
                          env=env)


@pytest.mark.slow
def test_pyelastica_plugin_is_discovered_and_runs_a_trial(elastica_env, tmp_path):
    r = _run(elastica_env, "backends")
    assert r.returncode == 0, r.stderr
    line = next((ln for ln in r.stdout.splitlines() if ln.startswith("pyelastica")), "")
    assert "available" in line and "continuum" in line, r.stdout
    out = tmp_path / "run"
    r = _run(elastica_env, "run", "--backends", "pyelastica,beam", "--trials", "b1c1t1", "--set", "gravity=0",
             "--executor", "serial", "--out", str(out), "--no-report", "--quiet")
    assert r.returncode == 0, r.stdout + r.stderr
    res = pd.read_csv(out / "results.csv").set_index("backend")
    assert res.loc["pyelastica", "status"] in ("ok", "unscored"), res.loc["pyelastica", "reason"]
    assert res.loc["pyelastica", "answer"] == "static"
    # against the beam on the same push: the plugin's 40 elements measured +0.04 % on this cane (small push;
    # +1.3 % at 10 elements, +0.26 % at 20; worst over the 54 canes 0.46 % at 40); 1 % is canebench's agreement
    # tolerance for continuum engines it does not list
    assert abs(res.loc["pyelastica", "k_sim"] / res.loc["beam", "k_sim"] - 1) < 0.01


def test_pyelastica_plugin_package_declares_its_backend():
    import ast
    import tomllib

    meta = tomllib.loads((PLUGIN / "pyproject.toml").read_text())
    eps = meta["project"]["entry-points"]["canebench.backends"]
    assert eps == {"pyelastica": "canebench_pyelastica:PyElasticaBackend"}
    assert "pyelastica>=1.0,<2" in meta["project"]["dependencies"]
    tree = ast.parse((PLUGIN / "canebench_pyelastica" / "__init__.py").read_text())
    cls = next(n for n in tree.body if isinstance(n, ast.ClassDef) and n.name == "PyElasticaBackend")
    attrs = {t.id: n.value for n in cls.body if isinstance(n, ast.Assign) for t in n.targets
             if isinstance(t, ast.Name)}
    assert ast.literal_eval(attrs["name"]) == "pyelastica"
    assert "continuum" in ast.literal_eval(attrs["tags"])
    assert (PLUGIN / "README.md").exists()


def test_pyelastica_plugin_is_absent_from_canebench_itself():
    # registered only through the entry point: nothing in canebench imports the plugin package
    pattern = re.compile(r"^\s*(import|from)\s+canebench_pyelastica", re.M)
    for folder in ("harness", "backends", "reports"):
        for f in (REPO / folder).rglob("*.py"):
            assert not pattern.search(f.read_text()), f
    from canebench.registry import discover

    reg = discover()
    if "pyelastica" in reg:  # installed into this environment by hand: then it came through the entry point
        assert reg["pyelastica"].target.startswith("canebench_pyelastica:")


def test_pyelastica_rod_in_process_against_the_closed_form():
    """The plugin's model without the install (needs pyelastica in this environment, else skipped):
    the uniform cantilever of reference-values sec. 1 at 10 elements, measured -0.65 % (1 % bound)."""
    pytest.importorskip("elastica", reason="pyelastica is not installed in this environment (the venv test "
                                           "above installs it)")
    sys.path.insert(0, str(PLUGIN))
    try:
        from canebench_pyelastica import PyElasticaBackend
    finally:
        sys.path.remove(str(PLUGIN))
    from canebench.model.chain import build_chain
    from canebench.model.config import ModelConfig
    from canebench.probe.driver import run_probe
    from canebench.probe.protocol import PROTOCOLS
    from canebench.studies.convergence import cantilever_stiffness, straight_cantilever

    chain = build_chain(straight_cantilever(False), "tip", ModelConfig(gravity=0.0))
    tr = run_probe(PyElasticaBackend(10), chain, PROTOCOLS["fast"], 3)
    assert tr.status == "ok", tr.reason
    assert abs(tr.fit().slope / cantilever_stiffness(False) - 1) < 0.01
