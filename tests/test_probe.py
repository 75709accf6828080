"""Failure detection: a diverging or chattering simulation is marked failed
with its reason, and what was sampled before is kept."""

import math

import pytest

from canebench.backends.base import DynamicBackend, Simulation, StaticBackend, StaticModel
from canebench.model.chain import build_chain
from canebench.probe.driver import run_probe
from canebench.probe.protocol import PROTOCOLS
from canebench.registry import get_backend


class ToySim(Simulation):
    """A massless spring k (N/m) at the probe; misbehaves from step ``bad_at``."""

    native_pid = True

    def __init__(self, mode: str, bad_at: int = 3, dt: float = 1e-3):
        self.dt, self.mode, self.bad_at = dt, mode, bad_at
        self.k, self.sp, self.t = 100.0, 0.0, 0

    def read(self):
        step = self.t * self.dt
        if self.mode == "nan" and step > self.bad_at:
            return math.nan, 0.0
        if self.mode == "chatter" and step > self.bad_at:
            return self.sp + 1e-4 * (-1) ** self.t, 0.5 * (-1) ** self.t  # bounded, fast
        if self.mode == "runaway" and step > self.bad_at:
            return 5.0, 0.0
        return self.sp, 0.0

    def step(self, force):
        self.t += 1

    def set_setpoint(self, sp):
        self.sp = sp

    def advance(self, n):
        self.t += n

    def force(self):
        return self.k * self.read()[0]


class ToyBackend(DynamicBackend):
    name, engine_module = "toy", "math"

    def __init__(self, mode):
        self.mode = mode

    def settings(self, proto):
        return {"engine": "toy"}

    def build(self, chain, proto):
        return ToySim(self.mode)


@pytest.fixture(scope="module")
def chain(bundled_trials):
    return build_chain(bundled_trials[0].cane, bundled_trials[0].push_id)


def test_healthy_toy_gives_its_spring(chain):
    tr = run_probe(ToyBackend("ok"), chain, PROTOCOLS["fast"], 10)
    assert tr.status == "ok" and tr.fit().slope == pytest.approx(100.0)


@pytest.mark.parametrize("mode,words", [("nan", "non-finite"), ("chatter", "unsettled"), ("runaway", "runaway")])
def test_bad_simulations_fail_with_reason_and_keep_samples(chain, mode, words):
    tr = run_probe(ToyBackend(mode), chain, PROTOCOLS["fast"], 10)
    assert tr.status == "failed" and words in tr.reason
    assert len(tr.force) == 3  # the three good steps are kept


def test_static_solver_failure_is_a_failed_trial(chain):
    class Broken(StaticModel):
        def solve(self, d):
            if d > 1e-3:
                raise RuntimeError("no convergence")
            return 1.0

    class B(StaticBackend):
        name, engine_module = "broken", "math"

        def settings(self, proto):
            return {}

        def build(self, chain):
            return Broken()

    tr = run_probe(B(), chain, PROTOCOLS["fast"], 10)
    assert tr.status == "failed" and "no convergence" in tr.reason and len(tr.force) == 2


def test_build_failure_is_a_failed_trial(chain):
    class B(ToyBackend):
        def build(self, chain, proto):
            raise ValueError("cannot compile")

    tr = run_probe(B("ok"), chain, PROTOCOLS["fast"], 5)
    assert tr.status == "failed" and "cannot compile" in tr.reason


def test_real_engine_instability_is_detected(chain):
    """The harness PID is explicit: at 5 ms (far above its ~0.1 ms limit with
    Kd = 20 N s/m on gram-scale links) MuJoCo must blow up, and the harness
    must say so instead of reporting a stiffness."""
    proto = PROTOCOLS["paper"].replace(dt=5e-3)
    tr = run_probe(get_backend("mujoco"), chain, proto, 10)
    assert tr.status == "failed", (tr.force, tr.displacement)
    assert any(w in tr.reason for w in ("unsettled", "runaway", "non-finite", "MuJoCo"))


def test_force_limit_stops_the_trial(chain):
    tr = run_probe(get_backend("pinocchio"), chain, PROTOCOLS["fast"].replace(force_limit_n=0.5), 90)
    assert tr.force[-1] >= 0.5 and all(f < 0.5 for f in tr.force[:-1])
