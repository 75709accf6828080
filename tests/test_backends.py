"""MuJoCo against the exact Pinocchio statics, and Pinocchio against itself."""

import numpy as np
import pytest

from canebench.model.chain import build_chain
from canebench.model.config import ModelConfig
from canebench.probe.driver import run_probe
from canebench.probe.protocol import PROTOCOLS
from canebench.registry import get_backend
from canebench.execute.runner import run_trials

# Agreement tolerance of the issue: 0.5 % in stiffness. What separates a
# dynamic run from the static sweep is the PID's lag (the dynamic samples
# cover a slightly shifted displacement range of a mildly nonlinear curve)
# and viscous creep forces; both are measured at < 0.1 % on the bundled set.
AGREE = 5e-3


@pytest.fixture(scope="module")
def chain(bundled_trials):
    t = next(t for t in bundled_trials if t.id == "b3c2t2")
    return build_chain(t.cane, t.push_id)


def test_pinocchio_hessian_matches_finite_differences(chain):
    from canebench.backends.pinocchio_backend import PinocchioStatic

    m = PinocchioStatic(chain)
    rng = np.random.default_rng(3)
    q = rng.normal(0, 0.05, m.model.nv)
    p, Ju, _, _ = m._eval(q)
    H = m.hessian_u_p(p)
    h = 1e-6
    Hfd = np.empty_like(H)
    for i in range(m.model.nv):
        e = np.zeros(m.model.nv)
        e[i] = h
        Hfd[:, i] = (m._eval(q + e)[1] - m._eval(q - e)[1]) / (2 * h)
    np.testing.assert_allclose(H, Hfd, atol=1e-7 * np.abs(H).max())
    np.testing.assert_allclose(H, H.T, atol=1e-12)


def test_pinocchio_equilibrium_residual(chain):
    from canebench.backends.pinocchio_backend import PinocchioStatic
    import pinocchio as pin

    m = PinocchioStatic(chain)
    F = m.solve(0.02)
    p, Ju, g, _ = m._eval(m.q)
    # independent check with Pinocchio's RNEA at zero velocity/acceleration
    tau_g = pin.rnea(m.model, m.data, m.q, np.zeros(m.model.nv), np.zeros(m.model.nv))
    np.testing.assert_allclose(m.K * m.q + tau_g - Ju * F, 0, atol=1e-9 * max(1, F))
    assert m.u @ (p - chain.push_point) == pytest.approx(0.02, abs=1e-12)


def test_small_push_matches_linear_compliance_without_gravity(bundled_trials):
    from canebench.backends.pinocchio_backend import PinocchioStatic

    t = bundled_trials[0]
    ch = build_chain(t.cane, t.push_id, ModelConfig(gravity=0.0))
    m = PinocchioStatic(ch)
    d = 1e-6
    assert m.solve(d) / d == pytest.approx(m.linear_stiffness(), rel=1e-5)


def test_mjcf_carries_the_chain(chain):
    import mujoco

    sim = get_backend("mujoco").build(chain, PROTOCOLS["fast"])
    np.testing.assert_allclose(sim.m.jnt_stiffness, np.repeat(chain.stiffness, 2))
    np.testing.assert_allclose(sim.m.dof_damping, chain.damping)
    np.testing.assert_allclose(sim.m.body_mass[1:], chain.masses)
    np.testing.assert_allclose(sim.m.opt.gravity, chain.gravity)
    mujoco.mj_forward(sim.m, sim.d)
    # rest configuration: the probe site sits at the chain's push point
    np.testing.assert_allclose(sim.d.site_xpos[sim.m.site("push").id], chain.push_point, atol=1e-12)
    assert sim.read()[0] == pytest.approx(0.0, abs=1e-12)


def test_mujoco_fast_agrees_with_pinocchio_on_every_bundled_trial(bundled_trials):
    res = run_trials(bundled_trials, ["mujoco", "pinocchio"], PROTOCOLS["fast"], ModelConfig(), jobs=2).results
    k = res.pivot(index="trial", columns="backend", values="k_sim")
    assert len(k) == 54 and k.notna().all().all()
    rel = (k.mujoco / k.pinocchio - 1).abs()
    assert rel.max() < AGREE, rel.sort_values().tail()
    assert set(res.status) <= {"ok", "unscored"}


@pytest.mark.parametrize("trial_id", ["b1c1t1", "b5c3t3"])
def test_mujoco_paper_protocol_agrees_short(bundled_trials, trial_id):
    """40 kHz reference protocol, first 6 steps (the full runs are -m slow)."""
    t = next(t for t in bundled_trials if t.id == trial_id)
    ch = build_chain(t.cane, t.push_id)
    k = {}
    for b, p in (("mujoco", "paper"), ("mujoco", "fast"), ("pinocchio", "fast")):
        tr = run_probe(get_backend(b), ch, PROTOCOLS[p], 6)
        assert tr.status == "ok", tr.reason
        k[(b, p)] = tr.fit().slope
    assert k[("mujoco", "paper")] / k[("pinocchio", "fast")] - 1 == pytest.approx(0, abs=AGREE)
    assert k[("mujoco", "fast")] / k[("mujoco", "paper")] - 1 == pytest.approx(0, abs=AGREE)


@pytest.mark.slow
def test_mujoco_paper_protocol_agrees_on_every_bundled_trial(bundled_trials):
    res = run_trials(bundled_trials, ["mujoco", "pinocchio"], PROTOCOLS["paper"], ModelConfig(), jobs=2).results
    k = res.pivot(index="trial", columns="backend", values="k_sim")
    rel = (k.mujoco / k.pinocchio - 1).abs()
    assert rel.max() < AGREE, rel.sort_values().tail()


def test_rest_jacobian_equals_pinocchio_frame_jacobian(bundled_trials):
    """linear_stiffness reads the rest Jacobian from the chain; Pinocchio's own must agree."""
    import pinocchio as pin

    from canebench.backends.pinocchio_backend import PinocchioStatic, rest_probe_jacobian

    for tid in ("b1c1t1", "b2c2t3", "b6c3t2"):
        t = next(t for t in bundled_trials if t.id == tid)
        ch = build_chain(t.cane, t.push_id, ModelConfig(segments=9))
        m = PinocchioStatic(ch)
        q0 = np.zeros(m.model.nv)
        pin.computeJointJacobians(m.model, m.data, q0)
        pin.updateFramePlacements(m.model, m.data)
        J = m.u @ pin.getFrameJacobian(m.model, m.data, m.fid, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)[:3]
        np.testing.assert_allclose(rest_probe_jacobian(ch), J, atol=1e-12)
