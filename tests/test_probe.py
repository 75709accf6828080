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


class Spring(StaticModel):
    """A linear spring k (N/m) at the probe."""

    def __init__(self, k):
        self.k = k

    def solve(self, d):
        return self.k * d


class SpringBackend(StaticBackend):
    name, engine_module = "spring", "math"

    def __init__(self, k):
        self.k = k

    def settings(self, proto):
        return {}

    def build(self, chain):
        return Spring(self.k)


def test_a_push_that_reaches_the_stop_in_two_steps_is_repeated_in_finer_steps(chain):
    """10 N/mm reaches the rig's 1000 gf (9.81 N) at the second 0.5 mm step: two samples, no
    slope. The push is repeated in steps fine enough for at least five samples before the stop,
    as many as the field fit asks of a record, and the slope is the spring's."""
    proto = PROTOCOLS["fast"]
    tr = run_probe(SpringBackend(1.0e4), chain, proto, 26)
    assert tr.status == "ok", tr.reason
    assert tr.extras["step_mm"] < 0.5 and len(tr.force) >= 5, (tr.extras, tr.force)
    assert tr.force[-1] >= proto.force_limit_n and all(f < proto.force_limit_n for f in tr.force[:-1])
    assert tr.displacement[0] == pytest.approx(tr.extras["step_mm"] * 1e-3)  # the finer step from the start
    assert tr.fit().slope == pytest.approx(1.0e4)
    # the floor is five samples, the field fit's: a stop at the fourth is repeated, at the fifth not
    four = run_probe(SpringBackend(5.0e3), chain, proto, 26)  # 10 N at 2.0 mm, 7.5 N at 1.5 mm
    assert four.extras["step_mm"] < 0.5 and len(four.force) >= 5, four.extras
    five = run_probe(SpringBackend(4.0e3), chain, proto, 26)  # 10 N at 2.5 mm, 8 N at 2.0 mm
    assert five.extras["step_mm"] == 0.5 and len(five.force) == 5
    # a trace cut short by its step count (the field record's length), not by the stop, is left alone
    short = run_probe(SpringBackend(1.0e4), chain, proto, 1)
    assert short.extras["step_mm"] == 0.5 and len(short.force) == 1
    # and a study that compares engines sample for sample may keep the protocol's own push
    same = run_probe(SpringBackend(1.0e4), chain, proto, 26, repeat_finer=False)
    assert same.extras["step_mm"] == 0.5 and len(same.force) == 2


def test_a_failed_finer_push_leaves_the_protocols_own(chain):
    """A model that solves only on the protocol's 0.5 mm grid: its four-sample push (a slope from
    four points, as before the repeat existed) is kept, and the failed repeat is said."""

    class Picky(StaticModel):
        def solve(self, d):
            if abs(d / 0.5e-3 - round(d / 0.5e-3)) > 1e-6:
                raise RuntimeError("no convergence")
            return 5.0e3 * d

    class B(SpringBackend):
        def build(self, chain):
            return Picky()

    tr = run_probe(B(0.0), chain, PROTOCOLS["fast"], 26)
    assert tr.status == "ok" and tr.extras["step_mm"] == 0.5 and len(tr.force) == 4
    assert "no convergence" in tr.extras["finer_push"] and tr.fit().slope == pytest.approx(5.0e3)


class LagSim(ToySim):
    """A spring whose probe reaches only a fraction of its setpoint (a PI law lagging a stiff cane)."""

    def __init__(self, k, frac):
        super().__init__("ok")
        self.k, self.frac = k, frac

    def read(self):
        return self.frac * self.sp, 0.0


def test_a_dynamic_engine_stiff_enough_to_stop_early_is_repeated_too(chain):
    """The same floor on the engine's own PID path: a 15 N/mm spring reaches 7.5 N at the first
    0.5 mm sample and the stop at the second, so the push is redone finer; so is a 30 N/mm one
    whose probe lags to half its setpoint (it too stops at the second sample)."""

    class Stiff(ToyBackend):
        def __init__(self, k, frac):
            self.k, self.frac = k, frac

        def build(self, chain, proto):
            return LagSim(self.k, self.frac)

    for k, frac in ((1.5e4, 1.0), (3.0e4, 0.5)):
        tr = run_probe(Stiff(k, frac), chain, PROTOCOLS["fast"], 20)
        assert tr.status == "ok" and len(tr.force) >= 5 and tr.extras["step_mm"] < 0.5, (k, tr.reason, tr.extras)
        assert tr.fit().slope == pytest.approx(k)


def test_a_stiff_cane_keeps_its_slope_on_the_engines(bundled_trials):
    """A bundled cane made 60x stiffer (about 15 N/mm as a chain) reaches the stop at the second
    protocol step. Repeated in finer steps, the beam reference's slope is its own small-deflection
    stiffness (to 1 %: the push to 1000 gf is under a millimetre on a cane hundreds long), and
    MuJoCo's chain agrees with Pinocchio's exact statics of the same chain to 2 % (at the
    protocol's own step they agree to 0.3 % in median on the bundled trials)."""
    from canebench.model.config import ModelConfig

    t = next(t for t in bundled_trials if t.id == "b1c1t3")
    stiff = ModelConfig(modulus_pa=60 * t.cane.material.flexural_modulus)
    ch = build_chain(t.cane, t.push_id, stiff)
    proto = PROTOCOLS["fast"]
    beam = run_probe(get_backend("beam"), ch, proto, 40)
    assert beam.status == "ok" and beam.extras["step_mm"] < 0.5 and len(beam.force) >= 5, (beam.reason, beam.extras)
    assert beam.fit().slope == pytest.approx(beam.extras["k_linear"], rel=0.01)
    pin = run_probe(get_backend("pinocchio"), ch, proto, 40)
    mj = run_probe(get_backend("mujoco"), ch, proto, 40)
    assert pin.status == "ok" and pin.extras["step_mm"] < 0.5 and len(pin.force) >= 5, (pin.reason, pin.extras)
    # the engine's PI law lags a stiff cane (its ramp error is k v / Ki), so MuJoCo's probe creeps
    # to the stop in more than five samples at the protocol's own step: it needs no repeat
    assert mj.status == "ok" and len(mj.force) >= 5, (mj.reason, mj.extras)
    assert mj.fit().slope == pytest.approx(pin.fit().slope, rel=0.02)
