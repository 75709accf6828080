"""The probe driver: one protocol, applied identically to every backend.

The harness owns the setpoint schedule, the PID law (or hands the gains to an
engine's implicit PID), the sampling, the force-limit stop (and, with a
protocol fit window, the stop once the probe is past it) and the checks
that mark a trial failed: non-finite state, an engine's own divergence flag,
runaway force or displacement, and chatter (probe still moving fast at the
end of a step, which is how PyBullet's velocity clamp hides an explosion).
Everything already sampled is kept when a trial fails.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..limits import check_deadline
from ..model.chain import Chain
from ..measure.fit import LineFit, fit_line
from .protocol import PID, Protocol


@dataclass
class ProbeTrace:
    """Samples of one probed trial (SI) and how it ended."""

    displacement: list[float] = field(default_factory=list)
    force: list[float] = field(default_factory=list)
    setpoint: list[float] = field(default_factory=list)
    status: str = "ok"
    reason: str = ""
    wall_s: float = 0.0
    settings: dict[str, Any] = field(default_factory=dict)
    extras: dict[str, Any] = field(default_factory=dict)

    def fail(self, reason: str) -> None:
        self.status, self.reason = "failed", reason

    def fit(self, window_m: float | None = None) -> LineFit | None:
        """Slope of force on displacement, over the first ``window_m`` of the push (all of it by default)."""
        x, f = np.array(self.displacement), np.array(self.force)
        if window_m is not None and len(x):
            keep = x <= window_m + 1e-12  # from the start of the push, as the field fit counts from onset
            x, f = x[keep], f[keep]
        return fit_line(x, f)


class Diverged(Exception):
    pass


def _check(proto: Protocol, k: int, x: float, v: float, f: float, setpoint: float) -> None:
    """Every sample: finite, force within reach of the rig's stop, probe following its setpoint."""
    if not (math.isfinite(x) and math.isfinite(v) and math.isfinite(f)):
        raise Diverged(f"non-finite state (NaN/inf) at step {k}")
    if abs(f) > proto.max_force_factor * proto.force_limit_n:
        raise Diverged(f"force {f:.4g} N at step {k} is past {proto.max_force_factor:g}x the protocol's "
                       f"{proto.force_limit_n:.3g} N limit within one {proto.step_m * 1e3:g} mm step "
                       "(runaway, or a cane far too stiff for the protocol: check the input's units)")
    if x - setpoint > proto.max_overshoot_m:
        raise Diverged(f"overshoot at step {k}: probe at {x * 1e3:.4g} mm, setpoint {setpoint * 1e3:.4g} mm")
    if x < -proto.max_overshoot_m:
        raise Diverged(f"probe moved backwards at step {k}: {x * 1e3:.4g} mm")
    if k >= proto.tracking_from and x < proto.min_tracking * setpoint:
        raise Diverged(f"probe not following its setpoint at step {k}: moved {x * 1e3:.3g} mm against "
                       f"{setpoint * 1e3:.3g} mm (the simulated cane is {setpoint / max(abs(x), 1e-300):.3g}x too "
                       "stiff for the protocol's PID; check the input's units)")


def _past_window(proto: Protocol, x: float) -> bool:
    """The probe is past the protocol's fit window: no later sample enters the slope.

    The stiffness is fitted over the samples within ``fit_window_mm`` of the start
    (:meth:`ProbeTrace.fit`, as the field fit counts from the onset); a push
    pressed on past that only costs time. The sample that crossed is kept (the
    trace shows where the push stopped). Without a window, never.
    """
    return proto.fit_window_mm is not None and x > proto.fit_window_mm * 1e-3 + 1e-12


def _check_range(tr: "ProbeTrace", proto: Protocol) -> None:
    """A slope needs the probe to have moved: at least a fifth of one protocol step.

    The dynamic probe lags its setpoint (its first sample may sit below
    0.5 mm), but a push that covers less than 0.1 mm in total measures the
    solver's tolerance, not the cane (MuJoCo with E = 1e14 moves 1.6e-7 m).
    """
    if tr.status == "ok" and len(tr.displacement) >= 2:
        span = max(tr.displacement) - min(tr.displacement)
        if span < 0.2 * proto.step_m:
            tr.fail(f"probe covered {span * 1e3:.3g} mm over the whole push (setpoint {tr.setpoint[-1] * 1e3:.3g} "
                    "mm): no slope at the rig's resolution (a cane far too stiff, or mis-scaled input)")


def probe_static(model: Any, proto: Protocol, n_steps: int) -> ProbeTrace:
    """Sweep a static model through the protocol's displacement steps."""
    tr = ProbeTrace()
    t0 = time.perf_counter()
    try:
        for k in range(1, n_steps + 1):
            check_deadline()
            sp = k * proto.step_m
            f = float(model.solve(sp))
            _check(proto, k, sp, 0.0, f, sp)
            tr.displacement.append(sp)
            tr.force.append(f)
            tr.setpoint.append(sp)
            if f >= proto.force_limit_n or _past_window(proto, sp):
                break
    except Diverged as exc:
        tr.fail(str(exc))
    except Exception as exc:  # a solver that does not converge fails the trial, not the run
        tr.fail(f"static solve failed at step {len(tr.force) + 1}: {type(exc).__name__}: {exc}")
    _check_range(tr, proto)
    tr.extras.update(getattr(model, "extras", {}))  # e.g. the beam's mesh and its error estimate
    try:
        tr.extras["k_linear"] = float(model.linear_stiffness())
    except NotImplementedError:
        pass
    tr.wall_s = time.perf_counter() - t0
    return tr


def probe_dynamic(sim: Any, proto: Protocol, n_steps: int) -> ProbeTrace:
    """Run the displacement-controlled push on a dynamic simulation."""
    tr = ProbeTrace()
    t0 = time.perf_counter()
    dt = sim.dt
    per = proto.steps_per_sample(dt)
    window = max(1, int(round(proto.settle_window_s / dt)))
    use_native = proto.controller == "engine" and getattr(sim, "native_pid", False)
    tr.extras["controller"] = "engine" if use_native else "harness"
    tr.extras["dt"] = dt  # the step this chain actually ran at (some backends choose it per chain)
    pid = PID(proto, dt)
    # the tail of each step is watched in ten slices (native path)
    chunks = [int(c) for c in np.diff(np.linspace(0, window, 11).round().astype(int)) if c]
    try:
        for k in range(1, n_steps + 1):
            check_deadline()
            sp = k * proto.step_m
            vmax = 0.0
            if use_native:
                sim.set_setpoint(sp)
                sim.advance(per - window)
                for c in chunks:
                    sim.advance(c)
                    x, v = sim.read()
                    vmax = max(vmax, abs(v))
                f = sim.force()
            else:
                pid.setpoint = sp
                vmax = sim.run_controlled(pid, per, window)
                x, v = sim.read()
                f = pid.output(x, v)  # the force that holds the state just read
            # the engine's own divergence flag first: it is the cause when the state it left is odd
            bad = sim.health()
            if bad:
                raise Diverged(f"{bad} (step {k})")
            _check(proto, k, x, v, f, sp)
            if vmax > proto.max_settle_velocity:
                raise Diverged(
                    f"unsettled at step {k}: probe speed {vmax * 1e3:.3g} mm/s in the last "
                    f"{proto.settle_window_s:g} s (chatter or instability)")
            tr.displacement.append(float(x))
            tr.force.append(float(f))
            tr.setpoint.append(sp)
            if f >= proto.force_limit_n or _past_window(proto, x):
                break
    except Diverged as exc:
        tr.fail(str(exc))
    except Exception as exc:  # engine errors (e.g. Exudyn's SolverError) fail the trial only
        tr.fail(f"engine error at step {len(tr.force) + 1}: {type(exc).__name__}: {exc}")
    finally:
        tr.wall_s = time.perf_counter() - t0
    _check_range(tr, proto)
    return tr


#: Fewest samples a push that ends at the rig's stop must have for its slope: the field fit's
#: own floor (:data:`canebench.measure.field.MIN_CONTACT_SAMPLES`), so both sides of a log ratio
#: rest on as many points.
MIN_SAMPLES_TO_STOP = 5
#: Samples aimed at when a push is repeated in finer steps (a margin over the floor for the
#: secant's error on a stiffening or lagging trace).
TARGET_SAMPLES_TO_STOP = 8
#: Finest refinement: a first sample under twice the stop (past it, :func:`_check` fails the
#: trial as a runaway) puts the stop beyond half a step, so the secant asks for at most 16.
MAX_REFINE = 2 * TARGET_SAMPLES_TO_STOP
#: Repeats allowed: one suffices for a line; a trace that stiffens may need another.
MAX_REPEATS = 3


def _stopped_short(tr: ProbeTrace, force_limit_n: float) -> bool:
    """The push ended at the rig's stop before :data:`MIN_SAMPLES_TO_STOP` samples."""
    return tr.status == "ok" and 0 < len(tr.force) < MIN_SAMPLES_TO_STOP and tr.force[-1] >= force_limit_n


def _finer(tr: ProbeTrace, proto: Protocol) -> int:
    """How many times finer a step must be for the push to reach the stop in about
    :data:`TARGET_SAMPLES_TO_STOP` samples, from the secant to its last sample."""
    x, f = tr.displacement[-1], tr.force[-1]
    travel = proto.force_limit_n * x / f if x > 0 and f > 0 else 0.0  # the secant's travel to the stop
    if travel <= 0:
        return MAX_REFINE
    return int(min(MAX_REFINE, max(2, math.ceil(TARGET_SAMPLES_TO_STOP * proto.step_m / travel))))


def run_probe(backend: Any, chain: Chain, proto: Protocol, n_steps: int, repeat_finer: bool = True) -> ProbeTrace:
    """Build ``chain`` in ``backend`` and probe it for ``n_steps`` samples.

    A model so stiff that it reaches the rig's stop within :data:`MIN_SAMPLES_TO_STOP` protocol
    steps (a root-compliant cane's rigid-clamp baseline: 10 N/mm reaches 1000 gf in two 0.5 mm
    steps) is pushed again in finer steps over the same travel, so it still has a slope; the
    field's record cannot be repeated, but the model's can, and the residual lost otherwise is
    its set's largest. The trace's ``extras["step_mm"]`` says which step it ran. A repeat that
    fails leaves the protocol's own push (with ``extras["finer_push"]`` saying why), which is
    what a trial without the repeat would have had. ``repeat_finer=False`` keeps every backend
    on the protocol's own samples (studies that compare engines sample for sample, or time them).
    """
    tr = _probe_once(backend, chain, proto, n_steps)
    step_m, steps = proto.step_m, n_steps
    for _ in range(MAX_REPEATS if repeat_finer else 0):
        if not _stopped_short(tr, proto.force_limit_n):
            break
        n = _finer(tr, proto.replace(step_m=step_m))
        fine = _probe_once(backend, chain, proto.replace(step_m=step_m / n), steps * n)  # the same travel
        fine.wall_s += tr.wall_s
        if fine.status != "ok":
            tr.extras["finer_push"] = f"a push in {step_m / n * 1e3:.3g} mm steps failed: {fine.reason}"
            tr.wall_s = fine.wall_s
            break
        step_m, steps, tr = step_m / n, steps * n, fine
    tr.extras["step_mm"] = step_m * 1e3
    return tr


def _probe_once(backend: Any, chain: Chain, proto: Protocol, n_steps: int) -> ProbeTrace:
    """Build ``chain`` in ``backend`` and probe it once for ``n_steps`` samples."""
    t0 = time.perf_counter()
    if chain.twist_stiffness is not None and not getattr(backend, "supports_twist", False):
        tr = ProbeTrace()
        tr.fail(f"backend {getattr(backend, 'name', type(backend).__name__)!r} does not compile the twist joint "
                "(model option twist_joint): it would probe a different chain")
        tr.settings = backend.settings(proto)
        return tr
    try:
        built = backend.build(chain) if backend.kind == "static" else backend.build(chain, proto)
        # a dynamic backend may answer a protocol with a static model (a quasi-static scheme)
        if hasattr(built, "solve"):
            tr = probe_static(built, proto, n_steps)
        else:
            try:
                tr = probe_dynamic(built, proto, n_steps)
            finally:
                built.close()
    except Exception as exc:
        tr = ProbeTrace()
        tr.fail(f"build failed: {type(exc).__name__}: {exc}")
    tr.wall_s = time.perf_counter() - t0
    tr.settings = backend.settings(proto)
    tr.extras["answer"] = backend.answer(proto) if hasattr(backend, "answer") else getattr(backend, "kind", "")
    return tr
