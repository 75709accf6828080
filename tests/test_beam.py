"""The beam backend in the harness, and what it says about the chain."""

import numpy as np
import pandas as pd
import pytest

from canebench.model.chain import build_chain
from canebench.cli import main
from canebench.model.config import ModelConfig
from canebench.probe.driver import run_probe
from canebench.probe.protocol import PROTOCOLS
from canebench.registry import get_backend
from canebench.studies.convergence import (chain_convergence, closed_form_ratio, continuum_stiffness,
                                           straight_cantilever)
from canebench.backends.beam_backend import BeamStatic, MeshNotConverged


def test_beam_backend_is_registered_and_probed_like_the_others(bundled_trials):
    t = bundled_trials[0]
    chain = build_chain(t.cane, t.push_id)
    tr = run_probe(get_backend("beam"), chain, PROTOCOLS["fast"], 12)
    assert tr.status == "ok" and len(tr.force) == 12
    assert np.allclose(tr.displacement, 0.5e-3 * np.arange(1, 13))
    assert tr.settings["engine"].startswith("beam")
    # gravity on: the sweep's slope and the gravity-free linear stiffness differ
    # only by the geometric effect of self-weight (a few per cent here)
    assert tr.fit().slope / tr.extras["k_linear"] == pytest.approx(1, abs=0.05)


def test_beam_matches_the_tapered_closed_form_through_the_backend():
    cane = straight_cantilever(True)
    chain = build_chain(cane, "tip", ModelConfig(gravity=0.0))
    k = run_probe(get_backend("beam"), chain, PROTOCOLS["fast"], 3).extras["k_linear"]
    E, L, d0, d1 = 4.57e9, 1.2, 0.012, 0.006
    assert 1 / k == pytest.approx(64 * L**3 / (3 * np.pi * E * d0**3 * d1), rel=1e-4)


def test_chain_over_beam_follows_the_closed_forms_on_a_uniform_cantilever():
    df = chain_convergence([("u", straight_cantilever(False), "tip")], segments=(3, 10, 20),
                           discretizations=("uniform",))
    for r in df.itertuples():
        assert r.compliance_ratio == pytest.approx(closed_form_ratio(r.formula, r.segments), rel=1e-4)
    paper40 = chain_convergence([("u", straight_cantilever(False), "tip")], segments=(40,), formulas=("paper",),
                                discretizations=("uniform",)).ratio.iloc[0]
    assert 1.9 < paper40 < 2.0  # K = 2EI/L: about twice the beam's stiffness


@pytest.mark.parametrize("trial_id", ["b1c2t1", "b4c3t3", "b6c2t3"])
def test_dual_length_chain_within_1pc_of_beam_at_20_uniform_segments(bundled_trials, trial_id):
    t = next(t for t in bundled_trials if t.id == trial_id)
    df = chain_convergence([(t.id, t.cane, t.push_id)], segments=(20,), formulas=("dual_length",),
                           discretizations=("uniform",))
    assert abs(df.ratio.iloc[0] - 1) < 0.01


@pytest.mark.parametrize("trial_id", ["b2c2t3", "b5c1t3", "b1c1t1"])  # two with hairpin folds
def test_beam_mesh_converged_with_its_error_estimate(bundled_trials, trial_id):
    """The beam's rest probe point is the smoothed centreline's at s_push, its
    mesh is converged to 1e-4 against twice the mesh, the estimate is in
    ``extras``, and the stiffness agrees with an independent small-deflection
    solution (Castigliano's integral over the polyline, no shooting)."""
    t = next(t for t in bundled_trials if t.id == trial_id)
    chain = build_chain(t.cane, t.push_id)
    m = BeamStatic(chain)
    assert np.linalg.norm(m.rod.p0 - chain.push_point) < 1e-12
    n, err = m.extras["beam_elements"], m.extras["beam_rel_error"]
    assert n == len(m.rod.h) and 0 <= err <= 1e-4
    k, k2 = m.linear_stiffness(), m.rod.refined().linear_stiffness()
    assert err == pytest.approx(abs(k / k2 - 1), rel=1e-3, abs=1e-9)
    assert k == pytest.approx(continuum_stiffness(chain), rel=1e-4)


def test_beam_refines_until_the_stiffness_settles(bundled_trials):
    t = next(t for t in bundled_trials if t.id == "b1c1t1")
    chain = build_chain(t.cane, t.push_id)
    m = BeamStatic(chain, rtol=1e-7)  # the default mesh is good to ~5e-7 here
    sizes = [n for n, _ in m.mesh_history]
    assert len(sizes) >= 3 and all(b == 2 * a for a, b in zip(sizes, sizes[1:]))
    assert m.extras["beam_elements"] == sizes[-2] and m.extras["beam_rel_error"] <= 1e-7
    ks = [k for _, k in m.mesh_history]
    assert abs(ks[-1] / ks[-2] - 1) < abs(ks[1] / ks[0] - 1)


def test_unconverged_beam_mesh_fails_the_trial_with_the_reason(bundled_trials):
    import dataclasses

    t = next(t for t in bundled_trials if t.id == "b1c1t1")
    chain = build_chain(t.cane, t.push_id)
    with pytest.raises(MeshNotConverged, match="cap of 200"):
        BeamStatic(chain, rtol=1e-13, max_elements=200)
    cfg = {**chain.meta["config"], "beam_rtol": 1e-13, "beam_max_elements": 200}
    chain = dataclasses.replace(chain, meta={**chain.meta, "config": cfg})
    tr = run_probe(get_backend("beam"), chain, PROTOCOLS["fast"], 3)
    assert tr.status == "failed" and "beam mesh not converged" in tr.reason


def test_converge_command_writes_study_and_report(tmp_path):
    out = tmp_path / "conv"
    assert main(["converge", "--trials", "b1c1t1,b2c2t2", "--segments", "5,10,20", "--out", str(out)]) == 0
    df = pd.read_csv(out / "convergence.csv")
    assert set(df.formula) == {"paper", "end_angle", "dual_length", "dual_length+twist"}
    assert set(df.trial) == {"uniform-cantilever", "tapered-cantilever", "b1c1t1", "b2c2t2"}
    for f in ("chain_convergence.png", "rod_convergence.png", "convergence_summary.csv", "convergence.html"):
        assert (out / f).exists(), f
    mesh = pd.read_csv(out / "beam_mesh.csv")
    assert set(mesh.trial) == {"b1c1t1", "b2c2t2"} and mesh["pass"].all()
    assert (mesh.rel_error <= 1e-4).all() and (mesh.rel_error_continuum <= 1e-4).all()
    assert (mesh.rest_offset_m < 1e-12).all()
    assert "Chain against beam" in (out / "convergence.html").read_text()
