"""Geometrically exact static Kirchhoff rod: the continuum reference.

The rod is inextensible and unshearable (Kirchhoff), bends with the local EI(s)
of a solid circular section and twists with GJ = EI / (1 + nu). Its rest
centreline is any smooth curve given by unit tangents t0(s) (s = arc length);
the base (s = 0) is clamped; loads are self-weight (optional) and a point force
F u at s_p in a fixed world direction u. Rotations are unrestricted.

Formulation. Write the material rotation as R(s) = Q(s) R0(s) with R0 the rest
frame, so Q is the rotation of the material relative to rest (Q(0) = I). With
n, m the internal force and moment exerted by (s, L] on [0, s):

    r' = Q t0                       n' = -rho A g
    Q' = Q [w]x                     m' = -r' x n
    w  = (1/EI) (v - (t0.v) t0) + (1/GJ) (t0.v) t0,   v = Q^T m

(the bending stiffness is isotropic, so only t0 is needed, not R0). n(0) is
known (total weight plus F u) and n jumps by -F u at s_p; m(0) is unknown
and fixed by the free end m(L) = 0. The boundary-value problem is solved by
shooting: classical RK4 on a mesh aligned with s_p (error O(h^4), measured in
``tests/test_rod.py``), quaternions for Q, Newton on the unknowns with a
forward-difference Jacobian computed in one batched integration.

Two solves: :meth:`Rod.solve_force` (force given; unknown m(0)) and
:meth:`Rod.solve_displacement` (displacement of the probe point along u
given; unknowns m(0) and F), the latter being the probe protocol's step.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

Array = np.ndarray


def _cross(a: Array, b: Array) -> Array:
    """Cross products of component-major arrays (3, B) (np.cross is slow on small arrays)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def _rotate(q: Array, v: Array, transpose: bool = False) -> Array:
    """Q v (or Q^T v) for unit quaternions q (4, B) and vectors v (3, B) or (3, 1)."""
    u = -q[1:] if transpose else q[1:]
    t = 2.0 * _cross(u, v)
    return v + q[0] * t + _cross(u, t)


def _qmul_pure(q: Array, w: Array) -> Array:
    """q * (0, w) for quaternions q (4, B) and vectors w (3, B)."""
    qw, qx, qy, qz = q
    wx, wy, wz = w
    return np.array([
        -qx * wx - qy * wy - qz * wz,
        qw * wx + qy * wz - qz * wy,
        qw * wy - qx * wz + qz * wx,
        qw * wz + qx * wy - qy * wx,
    ])


@dataclass
class RodSpec:
    """A rod's rest geometry, section and loads.

    Parameters
    ----------
    length : float
    tangent : callable s -> (k, 3) unit rest tangents
    ei : callable s -> (k,) bending stiffness EI(s)
    rho_a : callable s -> (k,) mass per length (kg/m); only with gravity
    nu : float
        Poisson ratio: GJ = EI / (1 + nu) for a solid circular section.
    base : (3,) array
        Clamped base position.
    gravity : (3,) array
    """

    length: float
    tangent: Callable[[Array], Array]
    ei: Callable[[Array], Array]
    rho_a: Callable[[Array], Array] = lambda s: np.zeros_like(np.asarray(s, float))
    nu: float = 0.3
    base: Array = field(default_factory=lambda: np.zeros(3))
    gravity: Array = field(default_factory=lambda: np.zeros(3))


class Rod:
    """A rod discretized for shooting, with the probe point at ``s_probe``.

    Parameters
    ----------
    spec : RodSpec
    s_probe : float
        Arc length of the point force / probe point (0 < s_probe <= L).
    direction : (3,) array
        Fixed world direction u of the force.
    n_elements : int
        RK4 steps over the whole length (split between [0, s_p] and [s_p, L]
        in proportion, at least one each); the mesh-refinement parameter.
    """

    STATE = 13  # r(3), q(4), m(3), n(3)

    def __init__(self, spec: RodSpec, s_probe: float, direction: Array, n_elements: int = 64) -> None:
        L = float(spec.length)
        if not (0 < s_probe <= L * (1 + 1e-12)):
            raise ValueError(f"probe at s = {s_probe} is not on the rod (0, {L}]")
        s_probe = min(float(s_probe), L)
        self.spec, self.L, self.sp = spec, L, s_probe
        self.u = np.asarray(direction, float) / np.linalg.norm(direction)
        n1 = max(1, int(round(n_elements * s_probe / L)))
        n2 = max(1, n_elements - n1) if s_probe < L else 0
        mesh = np.concatenate([np.linspace(0, s_probe, n1 + 1), np.linspace(s_probe, L, n2 + 1)[1:] if n2 else []])
        self.mesh = mesh
        self.i_probe = n1  # mesh index of the probe point
        h = np.diff(mesh)
        stages = np.stack([mesh[:-1], mesh[:-1] + h / 2, mesh[1:]], axis=1)  # (N, 3)
        flat = stages.ravel()
        t0 = spec.tangent(flat)
        t0 = t0 / np.linalg.norm(t0, axis=1, keepdims=True)
        ei = np.asarray(spec.ei(flat), float)
        self.h = h
        self.t0 = t0.reshape(-1, 3, 3)  # (N, stage, xyz)
        self.inv_ei = (1.0 / ei).reshape(-1, 3)
        self.inv_gj = ((1.0 + spec.nu) / ei).reshape(-1, 3)
        g = np.asarray(spec.gravity, float)
        self.g = g
        self.has_weight = bool(np.any(g))
        self.rho_a = np.asarray(spec.rho_a(flat), float).reshape(-1, 3) if self.has_weight else np.zeros((len(h), 3))
        # total weight by Gauss-Legendre on each element (exact for the polynomial sections used here)
        xg, wg = np.polynomial.legendre.leggauss(6)
        sq = (mesh[:-1, None] + (xg[None] + 1) / 2 * h[:, None]).ravel()
        elem_w = (np.asarray(spec.rho_a(sq)).reshape(len(h), -1) @ wg * h / 2) if self.has_weight \
            else np.zeros(len(h))
        self.weight = elem_w.sum() * g
        # weight carried beyond each element midpoint (for the rigid-rod first guess)
        self._w_beyond = (np.cumsum(elem_w[::-1])[::-1] - elem_w / 2)[:, None] * g[None, :]
        # rest state: integrate the unloaded rod once (Q = I, m = n = 0 except weight is off)
        self.rest = self._integrate(np.zeros((1, 3)), np.zeros(1), weightless=True)
        self.p0 = self.rest["r_probe"][0]
        self._t_mid = self.t0[:, 1, :]  # rest tangents at element midpoints
        self.m0 = np.zeros(3)
        self.F = 0.0
        self.iterations: list[int] = []
        self._history: list[tuple[float, Array]] = []

    # ------------------------------------------------------------------ ODE
    def _rhs(self, y: Array, t0: Array, inv_ei: float, inv_gj: float, rho_a: float, weightless: bool) -> Array:
        """Derivative of the state y (13, B): rows r, q, m, n."""
        q, m, n = y[3:7], y[7:10], y[10:13]
        t0c = t0[:, None]
        t = _rotate(q, t0c)  # r' = Q t0
        v = _rotate(q, m, transpose=True)
        tv = t0 @ v
        w = inv_ei * (v - tv * t0c) + inv_gj * tv * t0c
        out = np.empty_like(y)
        out[:3] = t
        out[3:7] = 0.5 * _qmul_pure(q, w)
        out[7:10] = -_cross(t, n)
        out[10:13] = 0.0 if weightless else (-rho_a * self.g)[:, None]
        return out

    def _integrate(self, m0: Array, F: Array, weightless: bool = False, keep: bool = False) -> dict:
        """Shoot from the base for a batch of (m0 (B,3), F (B,)); return end and probe states."""
        B = len(m0)
        weightless = weightless or not self.has_weight
        y = np.zeros((self.STATE, B))
        y[:3] = np.asarray(self.spec.base, float)[:, None]
        y[3] = 1.0
        y[7:10] = m0.T
        Fu = self.u[:, None] * F[None, :]
        y[10:13] = (0.0 if weightless else self.weight[:, None]) + Fu
        traj = [y[:3].T.copy()] if keep else None
        r_probe = None
        for k, h in enumerate(self.h):
            if k == self.i_probe:
                r_probe = y[:3].T.copy()
                y[10:13] -= Fu  # past the point force
            t0, ie, ig, ra = self.t0[k], self.inv_ei[k], self.inv_gj[k], self.rho_a[k]
            k1 = self._rhs(y, t0[0], ie[0], ig[0], ra[0], weightless)
            k2 = self._rhs(y + 0.5 * h * k1, t0[1], ie[1], ig[1], ra[1], weightless)
            k3 = self._rhs(y + 0.5 * h * k2, t0[1], ie[1], ig[1], ra[1], weightless)
            k4 = self._rhs(y + h * k3, t0[2], ie[2], ig[2], ra[2], weightless)
            y = y + (h / 6.0) * (k1 + 2 * k2 + 2 * k3 + k4)
            y[3:7] /= np.sqrt((y[3:7] ** 2).sum(axis=0))
            if keep:
                traj.append(y[:3].T.copy())
        if r_probe is None:  # probe at the tip
            r_probe = y[:3].T.copy()
        out = {"r_probe": r_probe, "m_end": y[7:10].T, "r_end": y[:3].T, "q_end": y[3:7].T}
        if keep:
            out["r"] = np.stack(traj, axis=1)
        return out

    # ------------------------------------------------------------------ solves
    def _newton(self, x0: Array, residual_of: Callable[[dict], Array], unknown_F: bool, F_fixed: float,
                d: float, max_iter: int) -> Array:
        """Newton on the shooting unknowns; forward differences for the
        Jacobian, all nx + 1 trajectories in one batched integration."""
        x = x0.copy()
        nx = len(x)
        for it in range(max_iter):
            step = np.maximum(np.abs(x), 1e-6) * 1e-7
            X = np.repeat(x[None], nx + 1, axis=0)
            X[1:] += np.diag(step)
            F = X[:, 3] if unknown_F else np.full(nx + 1, F_fixed)
            res = residual_of(self._integrate(X[:, :3], F))  # (nx+1, nx)
            r = res[0]
            # converged when the free end carries no moment (relative to the
            # moments in the rod) and the probe sits at its target
            m_ref = (abs(F[0]) + np.linalg.norm(self.weight)) * self.L + np.linalg.norm(x[:3]) + 1e-12
            ok_m = np.max(np.abs(r[:3])) <= 1e-11 * m_ref
            ok_d = nx == 3 or abs(r[3]) <= 1e-13 + 1e-10 * abs(d)
            if ok_m and ok_d:
                self.iterations.append(it)
                return x
            J = ((res[1:] - r) / step[:, None]).T
            dx = np.linalg.solve(J, r)
            x = x - dx
            if not np.all(np.isfinite(x)):
                break
            # the forward-difference Jacobian is exact to ~1e-7, so after an update
            # of relative size 1e-8 the error left is ~1e-15: accept without another shot
            if np.all(np.abs(dx) <= 1e-8 * (np.abs(x) + 1e-12)):
                self.iterations.append(it + 1)
                return x
        raise RuntimeError(f"rod shooting did not converge in {max_iter} Newton iterations")

    def rigid_guess(self, F: float) -> Array:
        """m(0) of the undeformed rod under the loads: m(0) = int t0 x n ds.

        Shooting from a zero guess lets the full load act on the thin tip
        and overflow; this first guess is exact to first order in the strain."""
        mid = 0.5 * (self.mesh[:-1] + self.mesh[1:])
        n = self._w_beyond + np.where(mid < self.sp, F, 0.0)[:, None] * self.u[None, :]
        return (np.cross(self._t_mid, n) * self.h[:, None]).sum(axis=0)

    def solve_force(self, F: float, max_iter: int = 30) -> dict:
        """Equilibrium under probe force ``F`` (N along u); returns the state
        (``r`` holds the deformed centreline at the mesh points)."""
        x0 = self.m0 if self.F or np.any(self.m0) else self.rigid_guess(float(F))
        x = self._newton(x0, lambda o: o["m_end"], False, float(F), 0.0, max_iter)
        self.m0, self.F = x, float(F)
        return self._integrate(x[None], np.array([float(F)]), keep=True)

    def solve_displacement(self, d: float, max_iter: int = 30) -> float:
        """Force (N along u) holding the probe point at displacement ``d`` along u."""
        x = np.concatenate([self.m0, [self.F]])
        hist = self._history
        if len(hist) >= 2 and hist[-1][0] != hist[-2][0]:  # secant predictor along the sweep
            (d1, x1), (d2, x2) = hist[-2], hist[-1]
            x0 = x2 + (x2 - x1) * (d - d2) / (d2 - d1)
        elif not hist:
            x0 = np.concatenate([self.rigid_guess(0.0), [0.0]])
        else:
            x0 = x

        def resid(o: dict) -> Array:
            disp = (o["r_probe"] - self.p0) @ self.u - d
            return np.concatenate([o["m_end"], disp[:, None]], axis=1)

        x = self._newton(x0, resid, True, 0.0, d, max_iter)
        self.m0, self.F = x[:3], float(x[3])
        self._history = (hist + [(d, x)])[-2:]
        return self.F

    def linear_stiffness(self, d: float = 1e-7) -> float:
        """Small-deflection stiffness (N/m) at rest, weight off: F/d at a tiny d."""
        saved = (self.has_weight, self.weight, self.m0, self.F, self._history)
        self.has_weight, self.weight, self.m0, self.F, self._history = False, np.zeros(3), np.zeros(3), 0.0, []
        try:
            return self.solve_displacement(d) / d
        finally:
            self.has_weight, self.weight, self.m0, self.F, self._history = saved
