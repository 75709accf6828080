"""PyBullet backend: the chain as a URDF multibody.

Each cane link is two revolute joints (x, then y) with a massless dummy link
between them; ``URDF_USE_INERTIA_FROM_FILE``; default link damping removed
and default velocity motors disabled. PyBullet has **explicit** joint springs
only (TORQUE_CONTROL from Python every step: -K q - c qd), so:

* ``paper``: true dynamics, harness PID, at min(25 us, half the explicit
  stability limit 2/omega_max and 2/lambda_max(M^-1 C) of the whole loop:
  springs, joint damping and the PID's Kp and Kd on the probe), computed from
  PyBullet's own mass matrix and Jacobian at rest. At 25 us most canes are
  *beyond* that limit: PyBullet then does not produce NaN but bounded chatter
  (its 100 rad/s velocity clamp), which is why the step is computed, never
  assumed. A trial whose predicted step count exceeds ``MAX_DYNAMIC_STEPS``
  fails with its predicted cost instead of running for hours.
* ``fast``: a quasi-static scheme with PyBullet's own model: at every
  protocol step, Newton on K q + g(q) - J(q)^T u F = 0 with u.(p - p0) = d,
  g from ``calculateInverseDynamics`` (zero velocity and acceleration), J from
  ``calculateJacobian``, the tangent by central differences of J^T u. The
  protocol's samples are settled states, so this is what the dynamic protocol
  converges to; it costs milliseconds per step instead of hours. The
  tangent (2n residuals by central differences, nearly all the cost) is
  reused across iterations and steps while each iteration at least halves
  the residual, and each step starts from the two previous ones extrapolated
  (:meth:`PybulletQuasiStatic.solve`): the same converged states (same
  residual test) at a fifth of the cost on 20-link chains.
"""

from __future__ import annotations

import contextlib
import os
import sys
import tempfile
from typing import Any

import numpy as np
import pybullet as p
from pybullet_utils import bullet_client
from scipy.spatial.transform import Rotation

from canebench.model.chain import Chain
from canebench.probe.protocol import Protocol
from canebench.probe.stability import choose_step, explicit_limit

from .base import DynamicBackend, Simulation, StaticModel

MAX_DYNAMIC_STEPS = 4_000_000  # about 2 minutes of stepping at ~30 us per step (measured)


def chain_to_urdf(chain: Chain) -> str:
    def f(v):
        return " ".join(repr(float(x)) for x in np.atleast_1d(v))

    # links without <inertial> get 1 kg from PyBullet: give the base and the
    # dummy links an explicit zero inertial
    massless = ('<inertial><mass value="0"/><inertia ixx="0" iyy="0" izz="0" ixy="0" ixz="0" iyz="0"/>'
                '</inertial>')
    parts = ['<?xml version="1.0"?>', '<robot name="cane">', f'  <link name="base">{massless}</link>']
    parent = "base"
    for j in range(chain.n_links):
        R, pos = chain.relative_pose(j)
        rpy = Rotation.from_matrix(R).as_euler("xyz")  # URDF rpy: fixed-axis X, Y, Z
        ixx, iyy, izz = chain.inertias[j]
        parts += [
            f'  <link name="dummy{j}">{massless}</link>',
            f'  <joint name="j{j}x" type="continuous"><parent link="{parent}"/><child link="dummy{j}"/>'
            f'<origin xyz="{f(pos)}" rpy="{f(rpy)}"/><axis xyz="1 0 0"/></joint>',
            f'  <link name="link{j}"><inertial><origin xyz="0 0 {f(chain.lengths[j] / 2)}" rpy="0 0 0"/>'
            f'<mass value="{f(chain.masses[j])}"/><inertia ixx="{f(ixx)}" iyy="{f(iyy)}" izz="{f(izz)}" '
            f'ixy="0" ixz="0" iyz="0"/></inertial></link>',
            f'  <joint name="j{j}y" type="continuous"><parent link="dummy{j}"/><child link="link{j}"/>'
            f'<origin xyz="0 0 0" rpy="0 0 0"/><axis xyz="0 1 0"/></joint>',
        ]
        parent = f"link{j}"
    parts.append("</robot>")
    return "\n".join(parts)


@contextlib.contextmanager
def _quiet_c_stdout():
    """Bullet prints from C (argv, URDF importer) straight to fd 1: hush it."""
    try:
        sys.stdout.flush()
        saved = os.dup(1)
    except (OSError, ValueError):
        yield
        return
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 1)
        yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)
        os.close(devnull)


class _Model:
    """A chain loaded in a private PyBullet DIRECT client."""

    def __init__(self, chain: Chain) -> None:
        self.chain = chain
        with _quiet_c_stdout():
            self.c = bullet_client.BulletClient(connection_mode=p.DIRECT)
        fd, path = tempfile.mkstemp(suffix=".urdf", prefix="canebench_")
        try:
            with os.fdopen(fd, "w") as fh:
                fh.write(chain_to_urdf(chain))
            with _quiet_c_stdout():
                self.body = self.c.loadURDF(path, useFixedBase=True, flags=p.URDF_USE_INERTIA_FROM_FILE)
        finally:
            os.unlink(path)
        self.n = self.c.getNumJoints(self.body)
        self.joints = list(range(self.n))
        for j in [-1] + self.joints:
            self.c.changeDynamics(self.body, j, linearDamping=0.0, angularDamping=0.0, jointDamping=0.0)
        self.c.setJointMotorControlArray(self.body, self.joints, p.VELOCITY_CONTROL, forces=[0.0] * self.n)
        self.c.setGravity(*[float(g) for g in chain.gravity])
        self.link = 2 * chain.push_link + 1
        self.local = chain.local(chain.push_link, chain.push_point)  # in the URDF link frame
        self.u = np.asarray(chain.direction, float)
        self.p0 = chain.push_point.copy()
        self.K = np.repeat(chain.stiffness, 2)
        self.zero = [0.0] * self.n

    def set_q(self, q: np.ndarray, qd: np.ndarray | None = None) -> None:
        for i in self.joints:
            self.c.resetJointState(self.body, i, float(q[i]), 0.0 if qd is None else float(qd[i]))

    def probe_state(self) -> tuple[np.ndarray, np.ndarray]:
        st = self.c.getLinkState(self.body, self.link, computeLinkVelocity=1, computeForwardKinematics=1)
        R = np.array(self.c.getMatrixFromQuaternion(st[5])).reshape(3, 3)
        pt = np.array(st[4]) + R @ self.local
        v = np.array(st[6]) + np.cross(np.array(st[7]), pt - np.array(st[0]))
        return pt, v

    def jacobian_u(self, q: np.ndarray) -> np.ndarray:
        # measured: this build takes the point in the link (joint) frame, not about the COM
        lin, _ = self.c.calculateJacobian(self.body, self.link, list(self.local), list(map(float, q)),
                                          self.zero, self.zero)
        return self.u @ np.array(lin)

    def gravity_torque(self, q: np.ndarray) -> np.ndarray:
        return np.array(self.c.calculateInverseDynamics(self.body, list(map(float, q)), self.zero, self.zero))

    def close(self) -> None:
        try:
            self.c.disconnect()
        except Exception:
            pass


class PybulletQuasiStatic(StaticModel):
    """Displacement-controlled static equilibrium from PyBullet's own model."""

    def __init__(self, chain: Chain, tol: float = 1e-10, max_iter: int = 40) -> None:
        self.m = _Model(chain)
        self.q = np.zeros(self.m.n)
        self.F = 0.0
        self.tol, self.max_iter = tol, max_iter
        self.A: np.ndarray | None = None  # the tangent of the last full Newton step, reused while it converges
        self._last: tuple[float, np.ndarray, float] | None = None  # (displacement, q, F) of the solve before
        self._d = 0.0
        self.n_tangents = 0

    def _residual(self, q: np.ndarray, F: float) -> tuple[np.ndarray, np.ndarray]:
        Ju = self.m.jacobian_u(q)
        return self.m.K * q + self.m.gravity_torque(q) - Ju * F, Ju

    def _tangent(self, q: np.ndarray, F: float, Ju: np.ndarray) -> np.ndarray:
        """The bordered Newton matrix at ``q``: central differences of the residual, the probe constraint."""
        n, h = self.m.n, 1e-7
        A = np.zeros((n + 1, n + 1))
        for i in range(n):
            e = np.zeros(n)
            e[i] = h
            A[:n, i] = (self._residual(q + e, F)[0] - self._residual(q - e, F)[0]) / (2 * h)
        A[:n, n] = -Ju
        A[n, :n] = Ju
        self.n_tangents += 1
        return A

    def solve(self, displacement: float) -> float:
        """Newton on the equilibrium with the probe at ``displacement``.

        The converged state is the same as full Newton's (same residual test);
        cheaper on the way: the start is extrapolated linearly from the two
        previous solves (a push is nearly linear from step to step), and the
        tangent (2n residual evaluations by central differences, all the cost)
        is reused across iterations and protocol steps while each iteration at
        least halves the residual, and recomputed at the current state
        otherwise (modified Newton).
        """
        m, q, F = self.m, self.q.copy(), self.F
        n = m.n
        if self._last is not None and self._d != self._last[0]:
            d0, q0, F0 = self._last
            w = (displacement - self._d) / (self._d - d0)
            q, F = q + w * (q - q0), F + w * (F - F0)
        prev = np.inf
        for _ in range(self.max_iter):
            r1, Ju = self._residual(q, F)
            m.set_q(q)
            r2 = m.u @ (m.probe_state()[0] - m.p0) - displacement
            # getLinkState positions are quantised like float32 (measured: +-1.6e-8 m at
            # 0.8 m from the origin), so the displacement is met to 1e-7 m, 2e-4 of one
            # 0.5 mm protocol step; the force error it allows is below 2e-4 per sample
            if np.max(np.abs(r1)) < self.tol * max(1.0, abs(F)) and abs(r2) < 1e-7:
                self._last = (self._d, self.q, self.F)
                self.q, self.F, self._d = q, F, displacement
                return float(F)
            size = float(np.max(np.abs(r1)) + abs(r2) * np.max(np.abs(m.K)))
            if self.A is None or not size < 0.5 * prev:
                self.A = self._tangent(q, F, Ju)
                prev = np.inf
            else:
                prev = size
            dx = np.linalg.solve(self.A, -np.concatenate([r1, [r2]]))
            q, F = q + dx[:n], F + dx[n]
            if not np.all(np.isfinite(q)):
                break
        raise RuntimeError(f"PyBullet quasi-static Newton did not converge at {displacement * 1e3:.3g} mm")

    def linear_stiffness(self) -> float:
        Ju = self.m.jacobian_u(np.zeros(self.m.n))
        return float(1.0 / (Ju @ (Ju / self.m.K)))


class PybulletSimulation(Simulation):
    native_pid = False

    def __init__(self, chain: Chain, dt: float) -> None:
        self.m = _Model(chain)
        self.dt = dt
        self.m.c.setPhysicsEngineParameter(fixedTimeStep=dt, numSubSteps=0)
        self.c = self.m.c
        self.Kc = self.m.K
        self.cdamp = float(chain.damping)

    def read(self) -> tuple[float, float]:
        pt, v = self.m.probe_state()
        return float(self.m.u @ (pt - self.m.p0)), float(self.m.u @ v)

    def step(self, force: float) -> None:
        m, c = self.m, self.c
        st = c.getJointStates(m.body, m.joints)
        q = np.array([s[0] for s in st])
        qd = np.array([s[1] for s in st])
        c.setJointMotorControlArray(m.body, m.joints, p.TORQUE_CONTROL, forces=list(-self.Kc * q - self.cdamp * qd))
        pt, _ = m.probe_state()
        c.applyExternalForce(m.body, m.link, list(force * m.u), list(pt), p.WORLD_FRAME)
        c.stepSimulation()

    def health(self) -> str | None:
        st = self.c.getJointStates(self.m.body, self.m.joints)
        qd = np.array([s[1] for s in st])
        if not np.all(np.isfinite(qd)):
            return "PyBullet state is not finite"
        if np.any(np.abs(qd) > 99.0):
            return "PyBullet joint speed at its 100 rad/s clamp (diverged into bounded chatter)"
        return None

    def close(self) -> None:
        self.m.close()


def explicit_step(chain: Chain, proto: Protocol) -> tuple[float, float]:
    """(step, limit): the explicit limit of springs + damping + PID in PyBullet."""
    m = _Model(chain)
    try:
        q0 = [0.0] * m.n
        M = np.array(m.c.calculateMassMatrix(m.body, q0))
        Ju = m.jacobian_u(np.zeros(m.n))
    finally:
        m.close()
    K = np.diag(m.K) + proto.kp * np.outer(Ju, Ju)
    C = chain.damping * np.eye(len(Ju)) + proto.kd * np.outer(Ju, Ju)
    lim = explicit_limit(M, K, C)
    return choose_step(lim, ceiling=proto.dt), lim


class PybulletBackend(DynamicBackend):
    name = "pybullet"
    tags = ("dynamic", "explicit-springs", "quasi-static-fast")
    engine_module = "pybullet"

    @classmethod
    def engine_version(cls) -> str:
        from importlib.metadata import version

        return f"{version('pybullet')} (API {p.getAPIVersion()})"

    def settings(self, proto: Protocol) -> dict[str, Any]:
        fast = proto.controller == "engine"
        return {
            "engine": "pybullet",
            "version": self.engine_version(),
            "integrator": ("none: quasi-static Newton on PyBullet's inverse dynamics and Jacobian" if fast
                           else "Bullet Featherstone, semi-implicit Euler"),
            "dt": None if fast else f"min({proto.dt}, 0.5 x explicit limit of the chain)",
            "substeps": 0 if fast else 1,
            "springs": "exact (static)" if fast else "explicit (TORQUE_CONTROL every step)",
            "damping": "n/a (static)" if fast else "explicit",
            "pid": "n/a: displacement imposed at each protocol step" if fast else "harness PID, explicit",
            "why": ("explicit springs need steps of microseconds (hours per trial); the samples are settled "
                    "states, which the quasi-static scheme computes directly" if fast
                    else "true dynamics below the explicit stability limit; never run at 25 us blindly"),
        }

    def answer(self, proto: Protocol) -> str:
        # fast: no Bullet time step is taken; Newton on Bullet's inverse dynamics and Jacobian
        return "quasi-static" if proto.controller == "engine" else "dynamic"

    def build(self, chain: Chain, proto: Protocol) -> Any:
        if proto.controller == "engine":
            return PybulletQuasiStatic(chain)
        dt, lim = explicit_step(chain, proto)
        predicted = proto.max_steps * proto.step_s / dt
        if predicted > MAX_DYNAMIC_STEPS:
            raise RuntimeError(
                f"explicit stability limit {lim:.3g} s needs dt = {dt:g} s: {predicted:.3g} steps for a 90 s trial "
                f"exceeds the budget of {MAX_DYNAMIC_STEPS:.3g}")
        return PybulletSimulation(chain, dt)
