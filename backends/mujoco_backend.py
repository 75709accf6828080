"""MuJoCo backend: the chain in MJCF with native joint springs and damping.

Configuration, by protocol:

* ``paper`` (harness PID): ``implicit`` integrator at the protocol's 25 us,
  Newton solver, as in the paper. Joint damping is implicit; springs and the
  probe force (a ``motor`` on the probe site) are explicit, stable at 25 us.
* ``fast`` (engine PID): the ``discrete`` integrator (MuJoCo 4.0) at 1 ms with
  the native ``pid`` actuator (kp, ki, kv = protocol gains) on the probe site.
  ``discrete`` folds joint stiffness, damping and the actuator's position and
  velocity gains into the step's effective inertia (M + hD + h^2 K), so the
  whole loop is implicit and stable far above the explicit limit.

The probe acts through a site transmission referenced to a world site placed
at the probe point's rest position with its x axis along the probe
direction, so the actuator length *is* the displacement along that fixed
world direction and the force is applied along it.
"""

from __future__ import annotations

from typing import Any

import mujoco
import numpy as np

from canebench.model.chain import Chain
from canebench.model.geometry import frame_with_x
from canebench.probe.protocol import Protocol

from .base import DynamicBackend, Simulation


def _quat(R: np.ndarray) -> np.ndarray:
    q = np.empty(4)
    mujoco.mju_mat2Quat(q, np.ascontiguousarray(R).ravel())
    return q


def _f(v: Any) -> str:
    return " ".join(repr(float(x)) for x in np.atleast_1d(v))


def chain_to_mjcf(chain: Chain, dt: float, integrator: str, native_pid: bool, gains: tuple[float, float, float]) -> str:
    """MJCF text of ``chain``; the probe is a ``pid`` (native) or ``motor`` actuator."""
    lines = []
    depth = 0
    for j in range(chain.n_links):
        R, p = chain.relative_pose(j)
        ind = "  " * (depth + 2)
        l, r = chain.lengths[j], chain.diameters[j] / 2
        lines.append(f'{ind}<body name="link{j}" pos="{_f(p)}" quat="{_f(_quat(R))}">')
        axes = [("1 0 0", "x", chain.stiffness[j]), ("0 1 0", "y", chain.stiffness[j])]
        if chain.twist_stiffness is not None:
            axes.append(("0 0 1", "z", chain.twist_stiffness[j]))
        for ax, name, k in axes:
            lines.append(f'{ind}  <joint name="j{j}{name}" type="hinge" axis="{ax}" '
                         f'stiffness="{_f(k)}" damping="{_f(chain.damping)}" springref="0"/>')
        lines.append(f'{ind}  <inertial pos="0 0 {_f(l / 2)}" mass="{_f(chain.masses[j])}" '
                     f'diaginertia="{_f(chain.inertias[j])}"/>')
        lines.append(f'{ind}  <geom type="capsule" fromto="0 0 0 0 0 {_f(l)}" size="{_f(r)}" '
                     f'contype="0" conaffinity="0" mass="0"/>')
        if j == chain.push_link:
            lines.append(f'{ind}  <site name="push" pos="{_f(chain.local(j, chain.push_point))}"/>')
        depth += 1
    for j in reversed(range(chain.n_links)):
        lines.append("  " * (j + 2) + "</body>")
    kp, ki, kd = gains
    if native_pid:
        act = (f'<pid name="probe" site="push" refsite="probe_ref" gear="1 0 0 0 0 0" '
               f'kp="{_f(kp)}" ki="{_f(ki)}" kv="{_f(kd)}" input="pos"/>')
    else:
        act = '<motor name="probe" site="push" refsite="probe_ref" gear="1 0 0 0 0 0"/>'
    g = _f(chain.gravity)
    ref_quat = _f(_quat(frame_with_x(chain.direction)))
    return "\n".join([
        '<mujoco model="cane">',
        '  <compiler angle="radian" autolimits="true"/>',
        f'  <option timestep="{_f(dt)}" integrator="{integrator}" solver="Newton" gravity="{g}">',
        '    <flag contact="disable"/>',
        '  </option>',
        '  <worldbody>',
        f'    <site name="probe_ref" pos="{_f(chain.push_point)}" quat="{ref_quat}"/>',
        *lines,
        '  </worldbody>',
        f'  <actuator>{act}</actuator>',
        '</mujoco>',
    ])


class MujocoSimulation(Simulation):
    def __init__(self, chain: Chain, proto: Protocol, native: bool, integrator: str) -> None:
        self.native_pid = native
        self.dt = proto.dt
        self.xml = chain_to_mjcf(chain, proto.dt, integrator, native, (proto.kp, proto.ki, proto.kd))
        self.m = mujoco.MjModel.from_xml_string(self.xml)
        self.d = mujoco.MjData(self.m)
        mujoco.mj_forward(self.m, self.d)
        self._stepped = True  # state changed since the last read: recompute kinematics

    # harness-PID path: step1 computes position/velocity stages, the harness
    # sets the force from them, step2 integrates (valid for Euler/implicit).
    def read(self) -> tuple[float, float]:
        if self._stepped:
            mujoco.mj_step1(self.m, self.d)
            self._stepped = False
        return float(self.d.actuator_length[0]), float(self.d.actuator_velocity[0])

    def step(self, force: float) -> None:
        if self._stepped:
            mujoco.mj_step1(self.m, self.d)
        self.d.ctrl[0] = force
        mujoco.mj_step2(self.m, self.d)
        self._stepped = True

    # native-PID path
    def set_setpoint(self, setpoint: float) -> None:
        self.d.ctrl[0] = setpoint

    def advance(self, n_steps: int) -> None:
        mujoco.mj_step(self.m, self.d, nstep=int(n_steps))
        self._stepped = True

    def force(self) -> float:
        mujoco.mj_forward(self.m, self.d)
        return float(self.d.actuator_force[0])

    def health(self) -> str | None:
        w = self.d.warning
        for kind in (mujoco.mjtWarning.mjWARN_BADQACC, mujoco.mjtWarning.mjWARN_BADQVEL, mujoco.mjtWarning.mjWARN_BADQPOS):
            if w[int(kind)].number > 0:
                return f"MuJoCo {kind.name} warning (the engine reset the state)"
        return None


class MujocoBackend(DynamicBackend):
    name = "mujoco"
    tags = ("dynamic", "implicit-springs", "native-pid")
    engine_module = "mujoco"
    supports_twist = True

    def _mode(self, proto: Protocol) -> tuple[bool, str]:
        native = proto.controller == "engine"
        return native, ("discrete" if native else "implicit")

    def settings(self, proto: Protocol) -> dict[str, Any]:
        native, integ = self._mode(proto)
        return {
            "engine": "mujoco",
            "version": mujoco.__version__,
            "integrator": integ,
            "solver": "Newton",
            "dt": proto.dt,
            "substeps": 1,
            "springs": "implicit (discrete: M + hD + h^2K)" if native else "explicit (implicit integrator is implicit in velocity only)",
            "damping": "implicit",
            "pid": "native pid actuator, implicit gains" if native else "harness PID, explicit motor force, step1/step2 split",
            "why": ("discrete integrator makes springs and PID gains implicit, stable at 1 ms" if native
                    else "paper reference: 40 kHz, implicit integrator, Newton solver"),
        }

    def build(self, chain: Chain, proto: Protocol) -> MujocoSimulation:
        native, integ = self._mode(proto)
        return MujocoSimulation(chain, proto, native, integ)
