"""The DART backend's speed measures change cost, not answers.

* the closed-loop step rule predicts where DART + the explicit harness PID
  actually goes unstable;
* the inlined control loop is the base-class loop, bit for bit;
* the probe ``SimpleFrame`` reads what the ``BodyNode`` accessors read;
* leaving the skeleton out of the constraint solver changes nothing.
"""

from __future__ import annotations

import numpy as np
import pytest

from canebench.backends.base import Simulation
from canebench.backends.dart_backend import DartBackend, DartSimulation, SAFETY, chain_to_dart, closed_loop_limit
from canebench.model.chain import Chain, build_chain
from canebench.probe.driver import probe_dynamic
from canebench.probe.protocol import PID, PROTOCOLS

FAST = PROTOCOLS["fast"]


def _chain(bundled_trials, tid: str) -> Chain:
    t = next(t for t in bundled_trials if t.id == tid)
    return build_chain(t.cane, t.push_id)


@pytest.fixture(scope="module")
def tight(bundled_trials) -> Chain:
    """b6c1t3: a bundled trial whose closed-loop limit (0.91 ms) is just below 1 ms."""
    return _chain(bundled_trials, "b6c1t3")


def test_closed_loop_limit_matches_the_measured_boundary(tight: Chain) -> None:
    lim = closed_loop_limit(DartSimulation(tight, FAST.dt), FAST)
    assert 0.9e-3 < lim < 1e-3
    stable = probe_dynamic(DartSimulation(tight, 0.9e-3), FAST, 2)
    assert stable.status == "ok", stable.reason
    unstable = probe_dynamic(DartSimulation(tight, 1e-3), FAST, 2)
    assert unstable.status == "failed"


def test_step_rule(tight: Chain, bundled_trials) -> None:
    backend = DartBackend()
    dt, lim = backend.step_for(tight, FAST)
    assert dt == 8e-4 and dt <= SAFETY * lim
    # the old 2 m_eff / Kd rule sent this one to 0.25 ms; the implicit damping allows the protocol's 1 ms
    dt, lim = backend.step_for(_chain(bundled_trials, "b3c3t1"), FAST)
    assert dt == FAST.dt and dt <= SAFETY * lim
    assert backend.step_for(tight, PROTOCOLS["paper"])[0] == PROTOCOLS["paper"].dt


def test_inlined_loop_is_the_base_loop(tight: Chain) -> None:
    sims = [DartSimulation(tight, 8e-4) for _ in range(2)]
    pids = [PID(FAST, 8e-4) for _ in range(2)]
    vmax = []
    for sp in (0.5e-3, 1e-3):
        for p in pids:
            p.setpoint = sp
        vmax.append((sims[0].run_controlled(pids[0], 1250, 125),
                     Simulation.run_controlled(sims[1], pids[1], 1250, 125)))
    assert all(a == b for a, b in vmax)
    assert sims[0].read() == sims[1].read()
    assert pids[0].integral == pids[1].integral
    np.testing.assert_array_equal(sims[0].skel.getVelocities(), sims[1].skel.getVelocities())


def test_probe_frame_reads_the_body_point(tight: Chain) -> None:
    sim = DartSimulation(tight, 8e-4)
    for _ in range(500):
        sim.step(0.3)
    p = sim.body.getWorldTransform().multiply(sim.offset)
    v = sim.body.getLinearVelocity(sim.offset)
    # the same point by two accessors: equal to the last bit or two of rounding
    np.testing.assert_allclose(sim.probe.getWorldTransform().translation(), p, rtol=1e-14, atol=1e-16)
    np.testing.assert_allclose(sim.probe.getLinearVelocity(), v, rtol=1e-14, atol=1e-16)
    x, xd = sim.read()
    assert x == pytest.approx(sim.u @ (p - sim.p0), rel=1e-12) and xd == pytest.approx(sim.u @ v, rel=1e-12)


def test_no_constraint_solver_changes_nothing(tight: Chain) -> None:
    world, skel = chain_to_dart(tight)
    ref_world, ref_skel = chain_to_dart(tight)
    ref_world.getConstraintSolver().addSkeleton(ref_skel)  # as DART registers it by default
    for w in (world, ref_world):
        w.setTimeStep(8e-4)
    u = np.asarray(tight.direction, float)
    off = tight.local(tight.push_link, tight.push_point)
    for _ in range(1000):
        for w, s in ((world, skel), (ref_world, ref_skel)):
            s.getBodyNode(tight.push_link).addExtForce(0.3 * u, off, False, True)
            w.step()
    np.testing.assert_array_equal(skel.getPositions(), ref_skel.getPositions())
    np.testing.assert_array_equal(skel.getVelocities(), ref_skel.getVelocities())
