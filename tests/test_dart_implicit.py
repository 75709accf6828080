"""The DART fast loop with implicit P and D: its step rule predicts stability, and it answers as before.

* the linearized loop (:func:`implicit_pd_spectral_radius`) says where the
  implicit loop goes unstable, and the simulation agrees;
* the stiffness it measures is the explicit loop's and Pinocchio's to the
  agreement gate's tolerances, on bundled chains and on a stiff Morris corner
  (20 links at 8 GPa) whose explicit step is 0.2 ms;
* when the probe is settled the force sampled is the force applied.
"""

from __future__ import annotations

import pytest

from canebench.backends.dart_backend import (DartBackend, DartSimulation, implicit_pd_spectral_radius,
                                             implicit_step)
from canebench.model.chain import build_chain
from canebench.model.config import ModelConfig
from canebench.probe.driver import probe_dynamic, run_probe
from canebench.probe.protocol import PID, PROTOCOLS
from canebench.registry import get_backend

FAST = PROTOCOLS["fast"]


def _chain(bundled_trials, tid: str, **cfg):
    t = next(t for t in bundled_trials if t.id == tid)
    return build_chain(t.cane, t.push_id, ModelConfig(**cfg))


def test_linearized_loop_predicts_where_the_implicit_loop_fails(bundled_trials):
    ch = _chain(bundled_trials, "b1c1t1")
    M, K, D, c = DartSimulation(ch, 1e-3).linear_model()
    rho = {h: implicit_pd_spectral_radius(M, K, D, c, h, FAST.kp, FAST.ki, FAST.kd) for h in (5e-3, 1e-2)}
    assert rho[5e-3] < 1.0 < rho[1e-2]
    for h, ok in ((5e-3, True), (1e-2, False)):
        tr = probe_dynamic(DartSimulation(ch, h, implicit_pd=True), FAST, 3)
        assert (tr.status == "ok") == ok, (h, tr.reason)


@pytest.mark.parametrize("tid", ["b1c1t1", "b4c2t3"])
def test_implicit_loop_measures_what_the_explicit_one_does(bundled_trials, tid):
    ch = _chain(bundled_trials, tid)
    imp = run_probe(DartBackend(), ch, FAST, 30)
    exp_backend = DartBackend()
    exp_backend.implicit_pd = False
    exp = run_probe(exp_backend, ch, FAST, 30)
    pin = run_probe(get_backend("pinocchio"), ch, FAST, 30)
    assert imp.status == exp.status == "ok"
    assert imp.extras["dt"] > exp.extras["dt"] or imp.extras["dt"] == 5e-3
    k_i, k_e, k_p = imp.fit().slope, exp.fit().slope, pin.fit().slope
    assert k_i / k_e - 1 == pytest.approx(0, abs=1e-3)  # the agreement gate's baseline tolerance
    assert k_i / k_p - 1 == pytest.approx(0, abs=5e-3)  # its tolerance against the exact statics


def test_stiff_morris_corner_runs_at_millisecond_steps(bundled_trials):
    from canebench.model.presets import PRESETS

    t = next(t for t in bundled_trials if t.id == "b6c1t1")
    ch = build_chain(t.cane, t.push_id, PRESETS["paper"].replace(segments=20, modulus_pa=8.05e9))  # a Morris corner
    exp_dt, _ = DartBackend().step_for(ch, FAST)
    imp_dt = implicit_step(DartSimulation(ch, 1e-3, implicit_pd=True), FAST)
    assert exp_dt <= 5e-4 and imp_dt >= 5 * exp_dt  # what the explicit loop needed, and the implicit one
    tr = run_probe(DartBackend(), ch, FAST, 10)
    pin = run_probe(get_backend("pinocchio"), ch, FAST, 10)
    assert tr.status == "ok" and tr.extras["dt"] == imp_dt, tr.reason
    assert tr.fit().slope / pin.fit().slope - 1 == pytest.approx(0, abs=5e-3)


def test_settled_force_is_the_applied_force(bundled_trials):
    # hold one setpoint long enough to settle: the PID law at the sampled state (what the driver
    # reports) and the force the loop last applied agree, whatever the error in beta
    ch = _chain(bundled_trials, "b3c2t2")
    sim = DartSimulation(ch, 5e-3, implicit_pd=True)
    sim._beta = 0.9 * sim.beta()  # a deliberately wrong linear response (10 %)
    pid = PID(FAST, sim.dt)
    pid.setpoint = 0.5e-3
    sim.run_controlled(pid, 16000, 20)  # 80 s: ten times the integral's time scale
    x, v = sim.read()
    assert abs(v) < 1e-8
    assert sim._f_prev == pytest.approx(pid.output(x, v), rel=1e-6)
