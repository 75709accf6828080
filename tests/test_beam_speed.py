"""The rod's fast solve strategy (scalar shots, extrapolated first guesses,
reused Jacobians) changes the cost of a sweep, not its answers."""

import numpy as np
import pytest

from canebench.backends.beam_backend import BeamStatic
from canebench.backends.rod import Rod, _rotate
from canebench.model.chain import build_chain

STEP = 0.5e-3


@pytest.fixture(scope="module")
def chain(bundled_trials):
    t = next(t for t in bundled_trials if t.id == "b1c1t1")
    return build_chain(t.cane, t.push_id)


def _reference_shot(rod: Rod, m0: np.ndarray, F: float) -> dict:
    """The rod's RK4 written independently with numpy arrays (as the rod
    integrated before it switched to scalar arithmetic), from the rod's stage
    coefficients: tangent t0, 1/EI and B = (nu/EI) t0 t0^T (symmetric, its
    six components in the order xx, yy, zz, xy, xz, yz)."""

    def cross(a, b):
        return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])

    def rhs(y, t0, ie, b, ra):
        q, m, n = y[3:7], y[7:10], y[10:13]
        t = _rotate(q[:, None], t0[:, None])[:, 0]
        v = _rotate(q[:, None], m[:, None], transpose=True)[:, 0]
        B = np.array([[b[0], b[3], b[4]], [b[3], b[1], b[5]], [b[4], b[5], b[2]]])
        w = ie * v + B @ v
        qw, qx, qy, qz = q
        dq = 0.5 * np.array([-qx * w[0] - qy * w[1] - qz * w[2], qw * w[0] + qy * w[2] - qz * w[1],
                             qw * w[1] - qx * w[2] + qz * w[0], qw * w[2] + qx * w[1] - qy * w[0]])
        return np.concatenate([t, dq, -cross(t, n), -ra * rod.g])

    Fu = F * rod.u
    y = np.concatenate([rod.spec.base, [1.0, 0, 0, 0], m0, rod.weight + Fu])
    r_probe = None
    for k, h in enumerate(rod.h):
        if k == rod.i_probe:
            r_probe = y[:3].copy()
            y[10:13] -= Fu
        t0, ie, b, ra = rod.t0[k], rod.inv_ei[k], rod.B[k], rod.rho_a[k]
        k1 = rhs(y, t0[0], ie[0], b[0], ra[0])
        k2 = rhs(y + 0.5 * h * k1, t0[1], ie[1], b[1], ra[1])
        k3 = rhs(y + 0.5 * h * k2, t0[1], ie[1], b[1], ra[1])
        k4 = rhs(y + h * k3, t0[2], ie[2], b[2], ra[2])
        y = y + (h / 6.0) * (k1 + 2 * k2 + 2 * k3 + k4)
        y[3:7] /= np.linalg.norm(y[3:7])
    return {"r_probe": y[:3] if r_probe is None else r_probe, "m_end": y[7:10], "r_end": y[:3], "q_end": y[3:7]}


def test_scalar_shot_is_the_same_rk4(chain):
    """On a curved, tapered, weighted cane with the probe inside the rod, the
    scalar shot and an independent numpy RK4 agree to rounding."""
    rod = BeamStatic(chain).rod
    assert rod.has_weight and 0 < rod.i_probe < len(rod.h)
    F = 0.3
    m0 = rod.rigid_guess(F) * 1.1  # not an equilibrium: all terms matter
    ref = _reference_shot(rod, m0, F)
    shot = rod._shoot(m0, F)
    for name in ("r_probe", "r_end", "q_end"):
        np.testing.assert_allclose(getattr(shot, name), ref[name], rtol=0, atol=1e-13)
    np.testing.assert_allclose(shot.m_end, ref["m_end"], rtol=0, atol=1e-13 * np.abs(m0).max())


def test_warm_sweep_matches_cold_solves(chain):
    """Each displacement solved afresh (rigid first guess, no Jacobian kept)
    gives the force the warm-started sweep gives."""
    warm = BeamStatic(chain)
    d = STEP * np.arange(1, 13)
    f_warm = np.array([warm.solve(x) for x in d])
    for x, f in zip(d[[0, 5, 11]], f_warm[[0, 5, 11]]):
        cold = BeamStatic(chain)
        assert cold.solve(x) == pytest.approx(f, rel=1e-8)
        assert cold.rod.shots[0] > 2  # it really did start cold


def test_sweep_costs_about_two_shots_per_step(chain):
    m = BeamStatic(chain)
    for k in range(1, 41):
        m.solve(k * STEP)
    shots = np.array(m.rod.shots)
    # past the start-up of the extrapolation, a step is a first guess and one chord step
    assert np.median(shots[4:]) <= 2
    assert shots[4:].max() <= 6


def test_linear_stiffness_leaves_the_sweep_alone(chain):
    """The rod's linear-stiffness solve in the middle of a sweep changes
    neither the sweep nor itself (BeamStatic's own answer is the one it
    computed while refining the mesh, before any sweep)."""
    a, b = BeamStatic(chain), BeamStatic(chain)
    fa = [a.solve(k * STEP) for k in range(1, 9)]
    fb = [b.solve(k * STEP) for k in range(1, 5)]
    k_mid = b.rod.linear_stiffness()
    fb += [b.solve(k * STEP) for k in range(5, 9)]
    np.testing.assert_allclose(fb, fa, rtol=1e-9)
    assert a.rod.linear_stiffness() == pytest.approx(k_mid, rel=1e-7)
    assert a.linear_stiffness() == pytest.approx(k_mid, rel=1e-7)
