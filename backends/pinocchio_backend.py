"""Pinocchio backend: the exact static equilibrium of the same chain.

For each displacement step d of the protocol it solves, by Newton's method,

    K q + g(q) - J(q)^T u F = 0,        u . (p(q) - p0) = d

for the joint angles q and the probe force F (u the fixed world probe
direction, p the probe point, J its translational Jacobian). The tangent is
exact: K + dg/dq - F d(J^T u)/dq, the last term from the closed-form Hessian
of u . p(q) for a serial chain of revolute joints. This is the answer the
dynamic engines must converge to. ``linear_stiffness`` is 1 / (u^T J K^-1 J^T u)
at the rest configuration (small deflection, no gravity).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pinocchio as pin

from canebench.model.chain import Chain
from canebench.probe.protocol import Protocol

from .base import StaticBackend, StaticModel


class ConvergenceError(RuntimeError):
    pass


def chain_to_pinocchio(chain: Chain) -> tuple[pin.Model, int]:
    """Pinocchio model (RX then RY, and RZ with the twist joint, per link) and the probe frame id."""
    model = pin.Model()
    model.name = "cane"
    parent = 0
    push_joint = 0
    kinds = [pin.JointModelRX, pin.JointModelRY, pin.JointModelRZ][: chain.joints_per_link]
    for j in range(chain.n_links):
        R, p = chain.relative_pose(j)
        last = parent
        for k, kind in enumerate(kinds):
            pose = pin.SE3(R, p) if k == 0 else pin.SE3.Identity()
            last = model.addJoint(last, kind(), pose, f"j{j}{'xyz'[k]}")
        inertia = pin.Inertia(float(chain.masses[j]), np.array([0.0, 0.0, chain.lengths[j] / 2]),
                              np.diag(chain.inertias[j]))
        model.appendBodyToJoint(last, inertia, pin.SE3.Identity())
        if j == chain.push_link:
            push_joint = last
        parent = last
    model.gravity.linear = np.asarray(chain.gravity, float)
    placement = pin.SE3(np.eye(3), chain.local(chain.push_link, chain.push_point))
    fid = model.addFrame(pin.Frame("push", push_joint, placement, pin.FrameType.OP_FRAME))
    return model, fid


def rest_probe_jacobian(chain: Chain) -> np.ndarray:
    """u . dp/dq at rest, one entry per joint (x0, y0, (z0,) x1, ...): (a_i x (p - o_i)) . u."""
    axes = chain.joint_axes_world()
    origins = np.repeat(chain.nodes[:-1], chain.joints_per_link, axis=0)
    Ju = np.cross(axes, chain.push_point[None, :] - origins) @ np.asarray(chain.direction, float)
    Ju[chain.joints_per_link * (chain.push_link + 1):] = 0.0  # joints beyond the probe's link do not move it
    return Ju


def rest_linear_stiffness(chain: Chain) -> float:
    Ju = rest_probe_jacobian(chain)
    return float(1.0 / (Ju @ (Ju / chain.joint_stiffness_vector())))


class PinocchioStatic(StaticModel):
    def __init__(self, chain: Chain, tol_force: float = 1e-10, max_iter: int = 30) -> None:
        self.chain = chain
        self.model, self.fid = chain_to_pinocchio(chain)
        self._data = None  # created on first solve: see `data`
        nv = self.model.nv
        self.K = chain.joint_stiffness_vector()
        self.u = np.asarray(chain.direction, float)
        self.p0 = chain.push_point.copy()
        # joints that carry the probe point: those up to the push link's last joint
        self.n_act = chain.joints_per_link * (chain.push_link + 1)
        self.axis_index = [k for _, k in chain.joint_layout()]
        self.q = np.zeros(nv)
        self.F = 0.0
        self.tol_force = tol_force
        self.max_iter = max_iter
        self.iterations: list[int] = []

    @property
    def data(self) -> "pin.Data":
        """Pinocchio's workspace, created when first needed.

        pinocchio 4.1's ``Data`` holds second-order derivative tensors of size
        nv^3 whatever is computed: 2.2 GB at 160 links (nv = 320), 16 GB at
        320. Only the nonlinear solve needs it; :meth:`linear_stiffness` does not.
        """
        if self._data is None:
            self._data = self.model.createData()
        return self._data

    # -- kinematics
    def _eval(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        m, d = self.model, self.data
        pin.computeJointJacobians(m, d, q)  # also runs forward kinematics
        pin.updateFramePlacements(m, d)
        p = d.oMf[self.fid].translation.copy()
        J = pin.getFrameJacobian(m, d, self.fid, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)[:3]
        g = pin.computeGeneralizedGravity(m, d, q)
        dg = pin.computeGeneralizedGravityDerivatives(m, d, q)
        return p, self.u @ J, g, dg

    def _axes_origins(self) -> tuple[np.ndarray, np.ndarray]:
        n = self.n_act
        a = np.empty((n, 3))
        o = np.empty((n, 3))
        for i in range(n):
            M = self.data.oMi[i + 1]
            a[i] = M.rotation[:, self.axis_index[i]]  # RX: local x, RY: local y, RZ: local z
            o[i] = M.translation
        return a, o

    def hessian_u_p(self, p: np.ndarray) -> np.ndarray:
        """d^2 (u . p) / dq^2 for the serial revolute chain (current kinematics).

        For i <= j (i ancestor of, or equal to, j) with r_j = p - o_j:
        H_ij = u . [ (a_i x a_j) x r_j + a_j x (a_i x r_j) ].
        """
        a, o = self._axes_origins()
        n = self.n_act
        r = p[None, :] - o  # (n, 3)
        u = self.u
        # scalar triple products turn both terms into a_i . (something of j):
        # u.((a_i x a_j) x r_j) = a_i . (a_j x (r_j x u)),  u.(a_j x (a_i x r_j)) = a_i . (r_j x (u x a_j)),
        # so H = A W^T with O(n) cross products instead of O(n^2)
        w = np.cross(a, np.cross(r, u)) + np.cross(r, np.cross(u[None, :], a))
        h = a @ w.T
        H = np.zeros((self.model.nv, self.model.nv))
        H[:n, :n] = np.triu(h) + np.triu(h, 1).T
        return H

    def solve(self, displacement: float) -> float:
        q, F = self.q.copy(), self.F
        nv = self.model.nv
        for it in range(self.max_iter):
            p, Ju, g, dg = self._eval(q)
            r1 = self.K * q + g - Ju * F
            r2 = self.u @ (p - self.p0) - displacement
            scale = max(1.0, abs(F))
            if np.max(np.abs(r1)) < self.tol_force * scale and abs(r2) < 1e-13:
                self.q, self.F = q, F
                self.iterations.append(it)
                return float(F)
            A = np.zeros((nv + 1, nv + 1))
            A[:nv, :nv] = np.diag(self.K) + dg - F * self.hessian_u_p(p)
            A[:nv, nv] = -Ju
            A[nv, :nv] = Ju
            dx = np.linalg.solve(A, -np.concatenate([r1, [r2]]))
            q = q + dx[:nv]
            F = F + dx[nv]
            if not np.all(np.isfinite(q)):
                break
        raise ConvergenceError(f"Newton did not converge at displacement {displacement * 1e3:.3g} mm")

    def linear_stiffness(self) -> float:
        """1 / (u^T J K^-1 J^T u) at rest, without gravity terms or a Pinocchio ``Data``.

        At rest the probe Jacobian column of a revolute joint is its axis
        crossed with the lever arm to the probe point, both read from the
        chain (checked against Pinocchio's frame Jacobian in the tests), so a
        320-link chain needs a few MB instead of Pinocchio's nv^3 workspace.
        """
        return rest_linear_stiffness(self.chain)


class PinocchioBackend(StaticBackend):
    name = "pinocchio"
    tags = ("static", "reference", "exact")
    engine_module = "pinocchio"
    supports_twist = True

    def settings(self, proto: Protocol) -> dict[str, Any]:
        return {
            "engine": "pinocchio",
            "version": pin.__version__,
            "integrator": "none (static equilibrium)",
            "solver": "Newton on K q + g(q) - J^T u F = 0 with u.(p - p0) = d, exact tangent",
            "dt": None,
            "springs": "exact",
            "damping": "n/a (static)",
            "pid": "n/a: displacement imposed exactly at each protocol step",
            "why": "reference answer the dynamic engines must converge to",
        }

    def build(self, chain: Chain) -> PinocchioStatic:
        return PinocchioStatic(chain)
