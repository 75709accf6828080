"""The Exudyn backend's speed measures change cost, not answers.

* the persistent solver advances exactly the steps asked for, calling the
  pre-step hook once per step;
* reusing the Newton matrix within a sample moves the state by no more than
  the Newton tolerance (against a fresh Jacobian at every call);
* the stored matrix handed back to Newton is the matrix, not its factorization;
* the integral force folded into the connector's offset is the PID law;
* the fast step keeps the harness's chatter check at ten reads per window;
* the harness path's in-engine loop is the base-class loop.
"""

from __future__ import annotations

import exudyn as exu
import numpy as np
import pytest

from canebench.backends import exudyn_backend as eb
from canebench.backends.base import Simulation
from canebench.model.chain import Chain, build_chain
from canebench.probe.protocol import PID, PROTOCOLS

FAST = PROTOCOLS["fast"]
PAPER = PROTOCOLS["paper"]


@pytest.fixture(scope="module")
def chain(bundled_trials) -> Chain:
    t = next(t for t in bundled_trials if t.id == "b3c1t2")  # 8 links, curved
    return build_chain(t.cane, t.push_id)


def _sample(sim: eb.ExudynSimulation, k: int, fresh_jacobian: bool = False) -> None:
    """One protocol sample as the driver runs it (bulk, then ten one-step chunks at 10 ms)."""
    per, window = FAST.steps_per_sample(sim.dt), int(round(FAST.settle_window_s / sim.dt))
    sim.set_setpoint(k * FAST.step_m)
    for n in [per - window] + [1] * window:
        if fresh_jacobian:
            sim._jacobian_stale = True
        sim.advance(n)


def test_advance_takes_exactly_the_steps_asked(chain: Chain) -> None:
    sim = eb.ExudynBackend().build(chain, FAST)
    calls = []
    sim.mbs.SetPreStepUserFunction(lambda mbs, t: calls.append(t) or sim._pre_step(mbs, t))
    total = 0
    for n in (7, 1, 30, 2):
        sim.advance(n)
        total += n
        assert len(calls) == total
        assert sim.solver.it.currentTime == pytest.approx(total * sim.dt, rel=1e-12)
        assert sim.mbs.systemData.GetTime() == pytest.approx(total * sim.dt, rel=1e-12)


def test_jacobian_reuse_is_within_newton_tolerance(chain: Chain) -> None:
    reused, fresh = eb.ExudynBackend().build(chain, FAST), eb.ExudynBackend().build(chain, FAST)
    for k in (1, 2, 3):
        _sample(reused, k)
        _sample(fresh, k, fresh_jacobian=True)
        assert reused.read()[0] == pytest.approx(fresh.read()[0], rel=1e-6)
        assert reused.force() == pytest.approx(fresh.force(), rel=1e-6)
    assert reused.jacobians_computed == 3  # one per sample
    assert fresh.jacobians_computed == 3 * (1 + int(round(FAST.settle_window_s / reused.dt)))


def test_stored_jacobian_is_the_unfactorized_matrix(chain: Chain) -> None:
    sim = eb.ExudynBackend().build(chain, FAST)
    _sample(sim, 1)
    # with the dense solver Exudyn factorizes in place: what it holds now is the inverse of what we stored
    np.testing.assert_allclose(sim._jacobian @ sim.solver.GetSystemJacobian(), np.eye(sim._jacobian.shape[0]),
                               atol=1e-8)


def test_integral_on_the_offset_is_the_pid_law(chain: Chain) -> None:
    sim = eb.ExudynBackend().build(chain, FAST)
    assert sim.load is None
    for k in (1, 2):
        _sample(sim, k)
        assert sim.integral != 0.0
        f = sim.mbs.GetObjectOutput(sim.csd, exu.OutputVariableType.Force)
        # the connector's force on the probe is -(its spring force): Kp (sp - x) - Kd v + Ki I
        assert -f[0] == pytest.approx(sim.force(), rel=1e-12)


def test_fast_step_keeps_ten_chatter_reads() -> None:
    window = FAST.settle_window_s / eb.FAST_DT
    assert window == pytest.approx(10)
    assert FAST.step_s / eb.FAST_DT == pytest.approx(round(FAST.step_s / eb.FAST_DT))


def test_harness_loop_is_the_base_loop(chain: Chain) -> None:
    sims = [eb.ExudynBackend().build(chain, PAPER) for _ in range(2)]
    pids = [PID(PAPER, PAPER.dt) for _ in range(2)]
    for p in pids:
        p.setpoint = 0.5e-3
    vmax = (sims[0].run_controlled(pids[0], 400, 40), Simulation.run_controlled(sims[1], pids[1], 400, 40))
    assert vmax[0] == pytest.approx(vmax[1], rel=1e-12)
    np.testing.assert_allclose(sims[0].read(), sims[1].read(), rtol=1e-10, atol=1e-15)
    assert pids[0].integral == pytest.approx(pids[1].integral, rel=1e-12)
