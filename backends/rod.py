"""Geometrically exact static Kirchhoff rod: the continuum reference.

The rod is inextensible and unshearable (Kirchhoff), bends with the local EI(s)
of a solid circular section and twists with GJ = EI / (1 + nu). Its rest
centreline is given by unit tangents t0(s) (s = arc length): a smooth curve,
or a polyline (see below); the base (s = 0) is clamped; loads are self-weight
(optional) and a point force F u at s_p in a fixed world direction u.
Rotations are unrestricted.

Formulation. Write the material rotation as R(s) = Q(s) R0(s) with R0 the rest
frame, so Q is the rotation of the material relative to rest (Q(0) = I). With
n, m the internal force and moment exerted by (s, L] on [0, s):

    r' = Q t0                       n' = -rho A g
    Q' = Q [w]x                     m' = -r' x n
    w  = (1/EI) v + (nu/EI) (t0.v) t0,   v = Q^T m

i.e. w = R0 (kappa - kappa0) is the strain (curvature minus rest curvature)
in the rest frame, (1/EI) across t0 and 1/GJ = (1 + nu)/EI along it (the
bending stiffness is isotropic, so only t0 is needed, not R0). n(0) is known
(total weight plus F u) and n jumps by -F u at s_p; m(0) is unknown and fixed
by the free end m(L) = 0. The boundary-value problem is solved by shooting:
classical RK4 on a mesh aligned with s_p (error O(h^4), measured in
``tests/test_rod.py``), quaternions for Q, Newton on the unknowns with a
forward-difference Jacobian.

Polyline rest shapes. A rod whose intrinsic curvature is a sum of delta
functions is exactly a polyline: straight segments (t0 constant), and at each
vertex a kink, a finite rotation of the rest frame R0. In the equations above
a kink costs nothing: the moment m is continuous, so the strain w is finite
and Q (the rotation relative to rest) is continuous; only the coefficients
t0(s) and (nu/EI) t0 t0^T jump. Mesh nodes need not sit on the vertices: t0
enters the equations linearly (r', m') and through B = (nu/EI) t0 t0^T (w), so
per element the RK4 stages use *moment-matched* coefficients, the values c_a,
c_m, c_b at the element's start, middle and end for which RK4's quadrature
weights (1/6, 2/3, 1/6) reproduce the exact integrals of c(s) xi^k over the
element (k = 0, 1, 2; xi = -1..1 across it), computed segment by segment from
the polyline. With k = 0 the unloaded rod (Q = I) integrates r' = t0 exactly:
the rest centreline passes through the polyline's points at every mesh node,
whatever the mesh, and in particular the rest probe point is the polyline's
point at s_p. Vertices where the polyline turns sharply (more than
``Rod.KINK_NODE_DEG`` = 10 degrees: a digitized hairpin, the corner of a
frame) are also made mesh nodes, a few extra elements: a sharp kink inside
an element still converges, but irregularly (about third order on average,
the error depending on where in the element the kink falls), while between
such nodes the coefficients vary gently and the error falls cleanly at
fourth order, as the mesh-doubling error estimate of the beam backend
assumes (the largest linear-stiffness error over the 54 bundled push points,
against a quadrature of the polyline's small-deflection compliance: 3e-4
at 12 elements, 2e-5 at 24, 1.1e-6 at 48, 8e-8 at 96). A smooth rest shape
samples t0 at the stages instead (the classical RK4).

Speed. A shot is 4 x 48 evaluations of a right-hand side on a 13-vector, so
its cost is interpreter overhead, not arithmetic: numpy costs about a
microsecond per call on such tiny arrays, plain Python floats tens of
nanoseconds per operation. A shot is therefore integrated in scalar Python
arithmetic (:func:`_rhs`, :meth:`Rod._shoot`): the same operations in the
same order as a numpy version of this RK4 (the results agree bit for bit),
some 20 times faster per trajectory. Along a protocol sweep the solve is
warm-started: the first guess is extrapolated from the last four solutions
(cubic in the displacement), and the Newton Jacobian of the previous solve
is reused (chord steps, one shot each) while it still reduces the residual
quickly; a fresh forward-difference Jacobian is computed only when it does
not. A typical step costs two shots (first guess, one chord step) instead of
ten. Convergence is judged on the residual, with the same tolerances as a
plain Newton solve, so the solve strategy changes the cost, not the answer
(beyond the tolerance, far below the discretization error).

Two solves: :meth:`Rod.solve_force` (force given; unknown m(0)) and
:meth:`Rod.solve_displacement` (displacement of the probe point along u
given; unknowns m(0) and F), the latter being the probe protocol's step.
:meth:`Rod.linear_stiffness` is the small-deflection stiffness without the
weight (a central difference of two force-controlled solves, ~1e-10 of
solver noise), and :meth:`Rod.refined` the same rod on a mesh with every
element halved, for mesh-convergence checks.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, NamedTuple, Sequence

import numpy as np

Array = np.ndarray

#: One RK4 stage's coefficients as Python floats: rest tangent t0 (3), 1/EI,
#: the symmetric B = (nu/EI) t0 t0^T (6: xx, yy, zz, xy, xz, yz), and
#: n' = -rho A g (3; zeros when the weight is off).
Stage = tuple[float, ...]

#: the order of B's six components in a stage
_SYM = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))


def _cross(a: Array, b: Array) -> Array:
    """Cross products of component-major arrays (3, B) (np.cross is slow on small arrays)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def _rotate(q: Array, v: Array, transpose: bool = False) -> Array:
    """Q v (or Q^T v) for unit quaternions q (4, B) and vectors v (3, B) or (3, 1)."""
    u = -q[1:] if transpose else q[1:]
    t = 2.0 * _cross(u, v)
    return v + q[0] * t + _cross(u, t)


def _rhs(qw: float, qx: float, qy: float, qz: float, mx: float, my: float, mz: float,
         nx: float, ny: float, nz: float, stage: Stage) -> tuple[float, ...]:
    """Derivatives (r', q', m') of one trajectory at one RK4 stage, in scalar arithmetic.

    The same equations as the module docstring: ``r' = Q t0``, ``q' = q (0, w) / 2``
    with ``w = (1/EI) v + B v``, ``B = (nu/EI) t0 t0^T`` and ``v = Q^T m``, and
    ``m' = -r' x n``. (n' is the stage's constant ``-rho A g``, so the caller
    takes it from ``stage`` directly.) Rotations use the same quaternion formula
    as :func:`_rotate`: ``v + 2 q0 (u x v) + u x (2 u x v)``.

    Parameters
    ----------
    qw, qx, qy, qz : float
        Unit quaternion of Q.
    mx, my, mz, nx, ny, nz : float
        Internal moment and force.
    stage : Stage
        ``(t0x, t0y, t0z, 1/EI, Bxx, Byy, Bzz, Bxy, Bxz, Byz, ...)`` at the
        stage's arc length (moment-matched values on a polyline).

    Returns
    -------
    tuple of 10 floats
        ``r'`` (3), ``q'`` (4), ``m'`` (3).
    """
    tx, ty, tz, ie, bxx, byy, bzz, bxy, bxz, byz = stage[:10]
    # t = Q t0, with u = (qx, qy, qz) and a = 2 u x t0
    ax, ay, az = 2.0 * (qy * tz - qz * ty), 2.0 * (qz * tx - qx * tz), 2.0 * (qx * ty - qy * tx)
    rx = tx + qw * ax + (qy * az - qz * ay)
    ry = ty + qw * ay + (qz * ax - qx * az)
    rz = tz + qw * az + (qx * ay - qy * ax)
    # v = Q^T m: the same formula with u = -(qx, qy, qz)
    ux, uy, uz = -qx, -qy, -qz
    bx, by, bz = 2.0 * (uy * mz - uz * my), 2.0 * (uz * mx - ux * mz), 2.0 * (ux * my - uy * mx)
    vx = mx + qw * bx + (uy * bz - uz * by)
    vy = my + qw * by + (uz * bx - ux * bz)
    vz = mz + qw * bz + (ux * by - uy * bx)
    # strain: bending compliance 1/EI, plus the extra torsional compliance nu/EI along t0
    wx = ie * vx + (bxx * vx + bxy * vy + bxz * vz)
    wy = ie * vy + (bxy * vx + byy * vy + byz * vz)
    wz = ie * vz + (bxz * vx + byz * vy + bzz * vz)
    return (rx, ry, rz,
            0.5 * (-qx * wx - qy * wy - qz * wz),  # q' = q * (0, w) / 2
            0.5 * (qw * wx + qy * wz - qz * wy),
            0.5 * (qw * wy - qx * wz + qz * wx),
            0.5 * (qw * wz + qx * wy - qy * wx),
            -(ry * nz - rz * ny),  # m' = -r' x n
            -(rz * nx - rx * nz),
            -(rx * ny - ry * nx))


class _Shot(NamedTuple):
    """End and probe states of one shot (plain tuples of floats)."""

    r_probe: tuple[float, float, float]
    m_end: tuple[float, float, float]
    r_end: tuple[float, float, float]
    q_end: tuple[float, float, float, float]
    r: list[tuple[float, float, float]] | None  # centreline at the mesh points (``keep`` only)


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
    polyline : (k, 3) array or None
        If given, the rest centreline is exactly this polyline (vertices from
        the base, no zero-length segments; ``length`` its length, ``tangent``
        its piecewise-constant segment directions): straight segments with a
        kink at every vertex, integrated with moment-matched coefficients
        (module docstring). Build it with :func:`polyline_spec`.
    base_compliance : float
        Rotational compliance c (rad/(N m)) of the base about both axes
        perpendicular to the rest tangent there (a root that is not a rigid
        clamp): the base rotates by the rotation vector c (m0 - (m0.t0) t0),
        with m0 the moment the rod exerts on its base; 0 is a clamp.
    """

    length: float
    tangent: Callable[[Array], Array]
    ei: Callable[[Array], Array]
    rho_a: Callable[[Array], Array] = lambda s: np.zeros_like(np.asarray(s, float))
    nu: float = 0.3
    base: Array = field(default_factory=lambda: np.zeros(3))
    gravity: Array = field(default_factory=lambda: np.zeros(3))
    polyline: Array | None = None
    base_compliance: float = 0.0


def polyline_spec(points: Array, ei: Callable[[Array], Array],
                  rho_a: Callable[[Array], Array] = lambda s: np.zeros_like(np.asarray(s, float)),
                  nu: float = 0.3, gravity: Array | None = None) -> RodSpec:
    """The :class:`RodSpec` of a rod whose stress-free centreline is the
    polyline ``points`` (clamped at ``points[0]``), kinks included.

    Exactly repeated vertices are dropped; ``tangent(s)`` is the direction of
    the segment containing s (the later one at a vertex)."""
    P = np.asarray(points, float)
    seg = np.linalg.norm(np.diff(P, axis=0), axis=1)
    P = P[np.concatenate([[True], seg > 0])]
    if len(P) < 2:
        raise ValueError("a polyline rod needs two distinct points")
    d = np.diff(P, axis=0)
    seg = np.linalg.norm(d, axis=1)
    T = d / seg[:, None]
    S = np.concatenate([[0.0], np.cumsum(seg)])

    def tangent(s: Array) -> Array:
        i = np.clip(np.searchsorted(S, np.asarray(s, float), side="right") - 1, 0, len(T) - 1)
        return T[i]

    return RodSpec(float(S[-1]), tangent, ei, rho_a, nu, P[0].copy(),
                   np.zeros(3) if gravity is None else np.asarray(gravity, float), P)


def _vertex_turns(points: Array) -> tuple[Array, Array]:
    """Arc lengths of a polyline's interior vertices and the angle (rad) its
    direction turns by at each."""
    d = np.diff(np.asarray(points, float), axis=0)
    seg = np.linalg.norm(d, axis=1)
    t = d / seg[:, None]
    return np.cumsum(seg)[:-1], np.arccos(np.clip((t[1:] * t[:-1]).sum(axis=1), -1.0, 1.0))


def _polyline_stages(spec: RodSpec, mesh: Array) -> tuple[Array, Array, Array]:
    """Moment-matched stage coefficients of a polyline rod on ``mesh``.

    For c(s) = t0(s) and c(s) = B(s) = (nu/EI(s)) t0 t0^T, per element [a, b]
    (h = b - a, xi = 2 (s - a)/h - 1) the moments M_k = (1/h) int c xi^k ds,
    k = 0, 1, 2, are integrated segment by segment (exactly for t0, by 5-point
    Gauss-Legendre for B, whose 1/EI is smooth); the stage values at a, the
    middle and b that RK4's weights (1/6, 2/3, 1/6) map to the same moments
    are c_a = 3 (M2 - M1), c_m = 3/2 (M0 - M2), c_b = 3 (M2 + M1) (constant c
    gives c everywhere).

    Returns
    -------
    t0 : (N, 3, 3) array
        Stage tangents (element, stage, xyz).
    B : (N, 3, 6) array
        Stage B in the component order of :data:`_SYM`.
    t_mean : (N, 3) array
        Mean rest tangent over each element (its rest chord / h).
    """
    P = np.asarray(spec.polyline, float)
    d = np.diff(P, axis=0)
    S = np.concatenate([[0.0], np.cumsum(np.linalg.norm(d, axis=1))])
    T = d / np.diff(S)[:, None]
    N = len(mesh) - 1
    h = np.diff(mesh)
    # pieces: the mesh and the vertices together; each lies in one element and one segment
    cuts = np.union1d(mesh, S[(S > mesh[0]) & (S < mesh[-1])])
    c0, c1 = cuts[:-1], cuts[1:]
    mid = 0.5 * (c0 + c1)
    e = np.clip(np.searchsorted(mesh, mid, side="right") - 1, 0, N - 1)
    t = T[np.clip(np.searchsorted(S, mid, side="right") - 1, 0, len(T) - 1)]
    a, he = mesh[e], h[e]
    x0, x1 = 2 * (c0 - a) / he - 1, 2 * (c1 - a) / he - 1
    Mt = np.zeros((3, N, 3))
    for k in range(3):  # (1/h) int xi^k ds over a piece = (x1^(k+1) - x0^(k+1)) / (2 (k+1))
        np.add.at(Mt[k], e, t * ((x1 ** (k + 1) - x0 ** (k + 1)) / (2 * (k + 1)))[:, None])
    xg, wg = np.polynomial.legendre.leggauss(5)
    sq = c0[:, None] + (xg[None] + 1) / 2 * (c1 - c0)[:, None]
    xq = 2 * (sq - a[:, None]) / he[:, None] - 1
    wq = wg[None] * ((c1 - c0) / (2 * he))[:, None]  # Gauss weights over a piece, divided by h
    f = spec.nu / np.asarray(spec.ei(sq.ravel()), float).reshape(sq.shape) * wq
    tt = np.stack([t[:, i] * t[:, j] for i, j in _SYM], axis=1)  # (pieces, 6)
    MB = np.zeros((3, N, 6))
    for k in range(3):
        np.add.at(MB[k], e, (f * xq**k).sum(axis=1)[:, None] * tt)

    def stages(M: Array) -> Array:
        return np.stack([3 * (M[2] - M[1]), 1.5 * (M[0] - M[2]), 3 * (M[2] + M[1])], axis=1)

    return stages(Mt), stages(MB), Mt[0]


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
        On a polyline, vertices where it turns sharply are mesh nodes too
        (see ``kink_node_deg``).
    mesh : array, optional
        Explicit mesh node arc lengths instead (increasing from 0 to L, with
        s_p among them); :meth:`refined` uses it.
    kink_node_deg : float, optional
        Polyline vertices turning the centreline by more than this (degrees;
        default :attr:`KINK_NODE_DEG`) are added to the ``n_elements`` mesh
        as nodes (``math.inf``: none).
    """

    STATE = 13  # r(3), q(4), m(3), n(3)
    #: polyline vertices turning by more than this many degrees are made mesh nodes
    KINK_NODE_DEG = 10.0

    def __init__(self, spec: RodSpec, s_probe: float, direction: Array, n_elements: int = 64,
                 mesh: Array | None = None, kink_node_deg: float | None = None) -> None:
        L = float(spec.length)
        if not (0 < s_probe <= L * (1 + 1e-12)):
            raise ValueError(f"probe at s = {s_probe} is not on the rod (0, {L}]")
        s_probe = min(float(s_probe), L)
        self.spec, self.L, self.sp = spec, L, s_probe
        self.u = np.asarray(direction, float) / np.linalg.norm(direction)
        if mesh is None:
            n1 = max(1, int(round(n_elements * s_probe / L)))
            n2 = max(1, n_elements - n1) if s_probe < L else 0
            mesh = np.concatenate([np.linspace(0, s_probe, n1 + 1),
                                   np.linspace(s_probe, L, n2 + 1)[1:] if n2 else []])
            if spec.polyline is not None:
                s_v, turn = _vertex_turns(spec.polyline)
                sharp = s_v[turn > np.radians(self.KINK_NODE_DEG if kink_node_deg is None else kink_node_deg)]
                mesh = np.union1d(mesh, sharp[(sharp > 0) & (sharp < L)])
            self.i_probe = int(np.flatnonzero(mesh == s_probe)[0])  # mesh index of the probe point
        else:
            mesh = np.asarray(mesh, float)
            at = np.flatnonzero(mesh == s_probe)
            if mesh[0] != 0 or mesh[-1] != L or np.any(np.diff(mesh) <= 0) or len(at) != 1:
                raise ValueError("mesh must increase from 0 to the rod's length through the probe point")
            self.i_probe = int(at[0])
        self.mesh = mesh
        h = np.diff(mesh)
        stages = np.stack([mesh[:-1], mesh[:-1] + h / 2, mesh[1:]], axis=1)  # (N, 3)
        flat = stages.ravel()
        ei = np.asarray(spec.ei(flat), float)
        self.h = h
        self.inv_ei = (1.0 / ei).reshape(-1, 3)
        if spec.polyline is not None:
            if abs(np.sum(np.linalg.norm(np.diff(spec.polyline, axis=0), axis=1)) - L) > 1e-12 * L:
                raise ValueError("spec.length is not the polyline's length (build it with polyline_spec)")
            # moment-matched stage coefficients: the rest shape is the polyline at any mesh
            self.t0, self.B, self._t_mean = _polyline_stages(spec, mesh)
        else:
            t0 = spec.tangent(flat)
            t0 = (t0 / np.linalg.norm(t0, axis=1, keepdims=True)).reshape(-1, 3, 3)
            self.t0 = t0  # (N, stage, xyz)
            nu_ei = spec.nu * self.inv_ei
            self.B = np.stack([nu_ei * t0[:, :, i] * t0[:, :, j] for i, j in _SYM], axis=2)
            self._t_mean = t0[:, 1, :]  # rest tangents at element midpoints
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
        # the per-stage coefficients as Python floats for the scalar shot, with
        # and without the weight (n' = -rho A g or 0)
        n_prime = -self.rho_a[:, :, None] * g[None, None, :]  # (N, stage, 3)
        self._elements = self._stage_table(n_prime)
        self._elements_weightless = self._stage_table(np.zeros_like(n_prime))
        self._u = tuple(self.u.tolist())
        self._base = tuple(np.asarray(spec.base, float).tolist())
        self._c_root = float(spec.base_compliance)
        tb = np.asarray(spec.tangent(np.zeros(1)), float).reshape(-1, 3)[0]
        self._t_base = tuple((tb / np.linalg.norm(tb)).tolist())
        self.m0 = np.zeros(3)
        self.F = 0.0
        #: Newton updates (chord and full) per solve, and shots per solve
        self.iterations: list[int] = []
        self.shots: list[int] = []
        self._history: list[tuple[float, Array]] = []
        # Jacobian of the last converged solve, per problem (True: unknown F,
        # i.e. displacement control); reused as a chord Jacobian by the next solve
        self._jacobian: dict[bool, Array] = {}
        self._n_shots = 0
        self._last_shot: tuple[list[float], float, _Shot] | None = None  # (x, F, shot) of the last residual
        # rest state: integrate the unloaded rod once (Q = I, m = n = 0 except weight is off)
        self.rest = self._integrate(np.zeros((1, 3)), np.zeros(1), weightless=True)
        self.p0 = self.rest["r_probe"][0]

    def refined(self) -> "Rod":
        """The same rod and probe on this mesh with every element halved."""
        m = self.mesh
        return Rod(self.spec, self.sp, self.u, mesh=np.sort(np.concatenate([m, 0.5 * (m[:-1] + m[1:])])))

    # ------------------------------------------------------------------ ODE
    def _stage_table(self, n_prime: Array) -> list[tuple[float, Stage, Stage, Stage]]:
        """Per element: ``(h, stage0, stage1, stage2)`` as Python floats (the
        scalar shot would be several times slower on numpy scalars)."""
        coef = np.concatenate([self.t0, self.inv_ei[:, :, None], self.B, n_prime], axis=2)
        return [(h, *map(tuple, c)) for h, c in zip(self.h.tolist(), coef.tolist())]

    def _shoot(self, m0: Sequence[float], F: float, weightless: bool = False, keep: bool = False) -> _Shot:
        """Integrate one trajectory from the base with m(0) = ``m0`` and probe force ``F``.

        Classical RK4 per element (stages at the element's start, middle and
        end), the quaternion renormalized after each step, the point force
        removed from n when the probe point is passed: the discretization of
        the module docstring, in scalar arithmetic (see the module docstring
        for why).

        Parameters
        ----------
        m0 : sequence of 3 floats
            Base moment.
        F : float
            Probe force along u (N).
        weightless : bool
            Leave the weight out (also when the rod has none).
        keep : bool
            Also return the centreline at the mesh points.

        Returns
        -------
        _Shot
        """
        self._n_shots += 1
        weightless = weightless or not self.has_weight
        elements = self._elements_weightless if weightless else self._elements
        F = float(F)
        Fu = [F * c for c in self._u]
        r = list(self._base)
        m = [float(c) for c in m0]
        q = [1.0, 0.0, 0.0, 0.0]
        if self._c_root:
            # base spring: rotation vector c (m - (m.t) t), t the rest tangent at the base
            tx, ty, tz = self._t_base
            mt = m[0] * tx + m[1] * ty + m[2] * tz
            th = [self._c_root * (m[0] - mt * tx), self._c_root * (m[1] - mt * ty), self._c_root * (m[2] - mt * tz)]
            a = math.sqrt(th[0] * th[0] + th[1] * th[1] + th[2] * th[2])
            if a > 0:
                sa = math.sin(0.5 * a) / a
                q = [math.cos(0.5 * a), sa * th[0], sa * th[1], sa * th[2]]
        n = [f if weightless else w + f for w, f in zip(self.weight.tolist(), Fu)]
        traj = [tuple(r)] if keep else None
        r_probe = None
        for k, (h, s0, s1, s2) in enumerate(elements):
            if k == self.i_probe:
                r_probe = tuple(r)
                n = [a - b for a, b in zip(n, Fu)]  # past the point force
            hh = 0.5 * h
            qw, qx, qy, qz = q
            mx, my, mz = m
            nx, ny, nz = n
            # n' = s[5:] is constant over a stage, so only q and m need stage states (r is not read)
            g0, g1, g2 = s0[10:], s1[10:], s2[10:]
            k1 = _rhs(qw, qx, qy, qz, mx, my, mz, nx, ny, nz, s0)
            k2 = _rhs(qw + hh * k1[3], qx + hh * k1[4], qy + hh * k1[5], qz + hh * k1[6],
                      mx + hh * k1[7], my + hh * k1[8], mz + hh * k1[9],
                      nx + hh * g0[0], ny + hh * g0[1], nz + hh * g0[2], s1)
            k3 = _rhs(qw + hh * k2[3], qx + hh * k2[4], qy + hh * k2[5], qz + hh * k2[6],
                      mx + hh * k2[7], my + hh * k2[8], mz + hh * k2[9],
                      nx + hh * g1[0], ny + hh * g1[1], nz + hh * g1[2], s1)
            k4 = _rhs(qw + h * k3[3], qx + h * k3[4], qy + h * k3[5], qz + h * k3[6],
                      mx + h * k3[7], my + h * k3[8], mz + h * k3[9],
                      nx + h * g1[0], ny + h * g1[1], nz + h * g1[2], s2)
            h6 = h / 6.0
            y = [a + h6 * (b + 2 * c + 2 * d + e) for a, b, c, d, e in zip(r + q + m, k1, k2, k3, k4)]
            n = [a + h6 * (b + 2 * c + 2 * c + e) for a, b, c, e in zip(n, g0, g1, g2)]
            r, m = y[:3], y[7:]
            norm = math.sqrt(y[3] * y[3] + y[4] * y[4] + y[5] * y[5] + y[6] * y[6])
            q = [y[3] / norm, y[4] / norm, y[5] / norm, y[6] / norm]
            if keep:
                traj.append(tuple(r))
        if r_probe is None:  # probe at the tip
            r_probe = tuple(r)
        return _Shot(r_probe, tuple(m), tuple(r), tuple(q), traj)

    def _integrate(self, m0: Array, F: Array, weightless: bool = False, keep: bool = False) -> dict:
        """Shoot from the base for a batch of (m0 (B,3), F (B,)); return end and probe states.

        Returns
        -------
        dict
            ``r_probe``, ``m_end``, ``r_end`` (B, 3), ``q_end`` (B, 4) and, with
            ``keep``, ``r`` (B, N + 1, 3): the centreline at the mesh points.
        """
        shots = [self._shoot(m, f, weightless, keep) for m, f in zip(m0, F)]
        out = {name: np.array([getattr(s, name) for s in shots]) for name in ("r_probe", "m_end", "r_end", "q_end")}
        if keep:
            out["r"] = np.array([s.r for s in shots])
        return out

    # ------------------------------------------------------------------ solves
    @staticmethod
    def _keep_jacobian(err: float, err1: float, nx: int) -> bool:
        """Whether a Jacobian that took the residual error from ``err`` to ``err1``
        should serve the next update too (a chord step: one shot).

        Yes if the error fell at least twofold and, at the rate just seen, the
        chord steps still needed cost no more shots than a fresh Jacobian (nx);
        far from the solution, where Newton's quadratic convergence pays, this
        asks for a fresh one."""
        if not err1 <= 0.5 * err:  # (also False for NaN)
            return False
        return err1 <= 1 or math.log(err1) <= nx * math.log(err / err1)

    def _residual(self, x: Array, unknown_F: bool, F_fixed: float, d: float) -> Array:
        """Shooting residual at the unknowns ``x``: m(L) (3) and, for displacement
        control, the probe displacement along u minus ``d``; one shot."""
        F = x[3] if unknown_F else F_fixed
        shot = self._shoot(x[:3], F)
        self._last_shot = (x.tolist(), float(F), shot)
        if not unknown_F:
            return np.array(shot.m_end)
        disp = sum((a - b) * c for a, b, c in zip(shot.r_probe, self.p0.tolist(), self._u)) - d
        return np.array([*shot.m_end, disp])

    def _error(self, x: Array, r: Array, unknown_F: bool, F_fixed: float, d: float) -> float:
        """The residual in units of its tolerance (converged when <= 1): the
        free end carries no moment (relative to the moments in the rod) and the
        probe sits at its target."""
        F = x[3] if unknown_F else F_fixed
        m_ref = (abs(F) + np.linalg.norm(self.weight)) * self.L + np.linalg.norm(x[:3]) + 1e-12
        err = np.max(np.abs(r[:3])) / (1e-11 * m_ref)
        if unknown_F:
            err = max(err, abs(r[3]) / (1e-13 + 1e-10 * abs(d)))
        return float(err)

    def _jacobian_fd(self, x: Array, r: Array, unknown_F: bool, F_fixed: float, d: float) -> Array:
        """Forward-difference Jacobian of the residual at ``x`` (``r``: its
        residual), relative steps of 1e-7; one shot per column."""
        step = np.maximum(np.abs(x), 1e-6) * 1e-7
        J = np.empty((len(x), len(x)))
        for i in range(len(x)):
            xi = x.copy()
            xi[i] += step[i]
            J[:, i] = (self._residual(xi, unknown_F, F_fixed, d) - r) / step[i]
        return J

    def _newton(self, x0: Array, unknown_F: bool, F_fixed: float, d: float, max_iter: int) -> Array:
        """Newton on the shooting unknowns, reusing Jacobians while they work.

        Each update uses the current Jacobian: at first the one of the
        previous solve of the same problem (along a protocol sweep it hardly
        changes between steps), else a forward-difference one (nx shots). An
        update that reduces the residual error fast enough keeps the Jacobian
        for the next update (a chord step: one shot, see
        :meth:`_keep_jacobian`); otherwise the next update gets a fresh
        Jacobian, after going back to the previous point if the Jacobian was
        an old one. Convergence is judged on the residual alone
        (:meth:`_error`), so reusing Jacobians changes the cost, not the
        solution.

        Parameters
        ----------
        x0 : (nx,) array
            First guess: m(0), and F for displacement control.
        unknown_F : bool
            Displacement control (unknowns m(0), F) rather than force control (m(0)).
        F_fixed : float
            The force under force control.
        d : float
            The imposed displacement under displacement control.
        max_iter : int
            Most forward-difference Jacobians (i.e. Newton iterations) to spend.
        """
        shots0 = self._n_shots
        x = np.array(x0, float)
        r = self._residual(x, unknown_F, F_fixed, d)
        err = self._error(x, r, unknown_F, F_fixed, d)
        J = self._jacobian.get(unknown_F)
        fresh = False  # J was evaluated at the current x
        n_jac = updates = 0
        while err > 1:
            if J is None:
                if n_jac == max_iter:
                    raise RuntimeError(f"rod shooting did not converge in {max_iter} Newton iterations")
                J, fresh = self._jacobian_fd(x, r, unknown_F, F_fixed, d), True
                n_jac += 1
            dx = np.linalg.solve(J, r)
            x1 = x - dx
            updates += 1
            if not np.all(np.isfinite(x1)):
                raise RuntimeError(f"rod shooting diverged after {updates} Newton updates")
            # the forward-difference Jacobian is exact to ~1e-7, so after an update
            # of relative size 1e-8 the error left is ~1e-15: accept without another shot
            if fresh and np.all(np.abs(dx) <= 1e-8 * (np.abs(x1) + 1e-12)):
                x = x1
                break
            r1 = self._residual(x1, unknown_F, F_fixed, d)
            err1 = self._error(x1, r1, unknown_F, F_fixed, d)
            if self._keep_jacobian(err, err1, len(x)):
                x, r, err, fresh = x1, r1, err1, False
            elif fresh:  # a plain Newton step: taken whatever it gives, then a new Jacobian
                if not np.isfinite(err1):
                    raise RuntimeError(f"rod shooting overflowed after {updates} Newton updates")
                x, r, err = x1, r1, err1
                self._jacobian[unknown_F], J = J, None
            else:  # an old Jacobian that no longer contracts: keep the better point, new Jacobian
                if err1 < err:
                    x, r, err = x1, r1, err1
                J = None
        if J is not None:
            self._jacobian[unknown_F] = J
        self.iterations.append(updates)
        self.shots.append(self._n_shots - shots0)
        return x

    def rigid_guess(self, F: float) -> Array:
        """m(0) of the undeformed rod under the loads: m(0) = int t0 x n ds.

        Shooting from a zero guess lets the full load act on the thin tip
        and overflow; this first guess is exact to first order in the strain."""
        mid = 0.5 * (self.mesh[:-1] + self.mesh[1:])
        n = np.where(mid < self.sp, F, 0.0)[:, None] * self.u[None, :]
        if self.has_weight:  # (off during linear_stiffness)
            n = n + self._w_beyond
        return (np.cross(self._t_mean, n) * self.h[:, None]).sum(axis=0)

    def solve_force(self, F: float, max_iter: int = 30) -> dict:
        """Equilibrium under probe force ``F`` (N along u); returns the state
        (``r`` holds the deformed centreline at the mesh points)."""
        x0 = self.m0 if self.F or np.any(self.m0) else self.rigid_guess(float(F))
        x = self._newton(np.asarray(x0, float), False, float(F), 0.0, max_iter)
        self.m0, self.F = x, float(F)
        return self._integrate(x[None], np.array([float(F)]), keep=True)

    #: solutions along the sweep the first guess is extrapolated from (4:
    #: cubic). On the bundled canes at 0.5 mm steps a cubic first guess
    #: already meets the residual tolerance within a factor of a few (a
    #: quadratic one misses it by ~1e3), so one chord step usually finishes
    PREDICTOR_POINTS = 4

    def _predict(self, d: float) -> Array:
        """First guess of (m(0), F) at displacement ``d``: the Lagrange polynomial
        through the last solutions of the sweep (distinct displacements only),
        evaluated at ``d``; the rigid-rod guess on the first step."""
        hist = self._history
        if not hist:
            return np.concatenate([self.rigid_guess(0.0), [0.0]])
        pts: list[tuple[float, Array]] = []
        for dk, xk in reversed(hist):  # newest first; a repeated d adds nothing
            if all(dk != dj for dj, _ in pts):
                pts.append((dk, xk))
        if len(pts) == 1:
            return np.concatenate([self.m0, [self.F]])
        x0 = np.zeros_like(pts[0][1])
        for i, (di, xi) in enumerate(pts):
            weight = 1.0
            for j, (dj, _) in enumerate(pts):
                if j != i:
                    weight *= (d - dj) / (di - dj)
            x0 += weight * xi
        return x0

    def solve_displacement(self, d: float, max_iter: int = 30) -> float:
        """Force (N along u) holding the probe point at displacement ``d`` along u."""
        x = self._newton(self._predict(d), True, 0.0, d, max_iter)
        self.m0, self.F = x[:3], float(x[3])
        self._history = (self._history + [(d, x)])[-self.PREDICTOR_POINTS:]
        return self.F

    def linear_stiffness(self, d: float = 1e-5, jacobian: Array | None = None) -> float:
        """Small-deflection stiffness (N/m) at rest, weight off: the central
        difference 2 P / (delta(P) - delta(-P)) of the probe deflection under
        force control, with P = 3 EI(0) d / s_p^3 (a deflection of order d).

        Force control because its first guess, the rigid-rod moment, is exact
        to first order in the strain, so a solve is a forward-difference
        Jacobian and one Newton step; the solve at -P starts from minus the
        solution at P, with its Jacobian (a chord step). The central difference
        cancels the geometric nonlinearity to O(delta^2) (~1e-10 relative at
        d = 1e-5 m), and the solves' moment tolerance (1e-11 relative) leaves
        ~1e-10 of solver noise: small enough to measure mesh convergence far
        below 1e-4. A separate problem from the sweep (no weight, undeformed),
        so it starts afresh: no history and no Jacobian carried over (but
        ``jacobian``, if given: this problem's Jacobian on another mesh of the
        same rod, :attr:`linear_jacobian`, used as a chord Jacobian), and it
        leaves the sweep's state as it found it."""
        saved = (self.has_weight, self.weight, self.m0, self.F, self._history, self._jacobian)
        self.has_weight, self.weight, self.m0, self.F, self._history = False, np.zeros(3), np.zeros(3), 0.0, []
        self._jacobian = {} if jacobian is None else {False: np.asarray(jacobian, float)}
        try:
            P = 3.0 * float(np.asarray(self.spec.ei(np.array([0.0])), float)[0]) * d / self.sp**3
            p0 = self.p0.tolist()
            delta = []
            x = self.rigid_guess(P)
            for F in (P, -P):
                x = self._newton(x, False, F, 0.0, 30)
                last = self._last_shot  # the solve's last shot, if it was at x
                r = (last[2] if last and last[0] == x.tolist() and last[1] == F else self._shoot(x, F)).r_probe
                delta.append(sum((a - b) * c for a, b, c in zip(r, p0, self._u)))
                x = -x  # the first guess at -P
            #: the force-control Jacobian of the linear problem (for :meth:`linear_stiffness` on a refined mesh)
            self.linear_jacobian = self._jacobian.get(False)
            return 2 * P / (delta[0] - delta[1])
        finally:
            self.has_weight, self.weight, self.m0, self.F, self._history, self._jacobian = saved
