"""Planar large-deflection rod (inextensible elastica) for the indep13 test bed.

Written from scratch for this bed (no canebench code read).

Discretisation
--------------
The centreline from the base (node 0) up to the highest loaded point is cut
into N straight inextensible segments; unknowns are the segment angles
theta_i (measured from +x in the x-z plane).  Rotational springs sit at the
nodes 0..N-1 (Voronoi placement): the interior node j carries
K_j = 1 / int_{dual cell} ds / EI(s), the base node the half cell
[0, h_1/2] in series with an optional root spring k_root.  The natural shape
(segment angles of the unloaded curve) gives the natural curvature.  For a
uniform cantilever this chain's tip compliance is PL^3/(3EI) (1 + 1/(2n^2))
(reference-values.md section 5), so it converges at O(1/n^2).

The moment law at a node can be linear, M = K dtheta, or strain-softening
(M = K [(1-beta) dtheta + beta dy tanh(dtheta/dy)]) for the OOL set.

Loads
-----
All point interactions act along fixed unit vectors in the plane:
* the probe: displacement-controlled along d at node p, with an optional
  series rig compliance c = 1/k_rig:  (r_p - r_p0).d + c F = u,  F the probe
  force (pushing positive), the load cell reads F;
* 'gap spring' (obstruction): V = k/2 max(0, delta - gap)^2;
* 'anchor spring' (stick phase of a frictional rub): V = k/2 (delta - a)^2;
* 'constant force' (slip phase): V = f delta.
Equilibrium is solved by Newton on the KKT system (angles + probe force),
continuation in u, step halving on failure.
"""
from __future__ import annotations

import numpy as np


# --------------------------------------------------------------------------
# chain construction
# --------------------------------------------------------------------------
class Chain:
    """A discretised planar rod.

    s_nodes : arc lengths of the nodes (increasing, s_nodes[0] = 0)
    xz      : (N+1, 2) node positions of the unloaded rod
    EI_fn   : callable s -> EI (N m^2), vectorised
    k_root  : base rotational spring (N m/rad), None = rigid clamp
    soft    : None or (beta, eps_y, d_fn): strain-softening moment law
    """

    def __init__(self, s_nodes, xz, EI_fn, k_root=None, soft=None, nquad=6):
        s = np.asarray(s_nodes, float)
        xz = np.asarray(xz, float)
        assert s.ndim == 1 and xz.shape == (len(s), 2) and len(s) >= 2
        self.s = s
        self.r0 = xz.copy()
        dv = np.diff(xz, axis=0)
        self.h = np.hypot(dv[:, 0], dv[:, 1])          # chord lengths
        self.th0 = np.arctan2(dv[:, 1], dv[:, 0])       # natural angles
        # unwrap so natural angle differences are small
        self.th0 = np.unwrap(self.th0)
        N = len(self.h)
        self.N = N
        # compliance integrals over dual cells (Gauss-Legendre per half cell)
        xg, wg = np.polynomial.legendre.leggauss(nquad)

        def int_inv_EI(a, b):
            if b <= a:
                return 0.0
            m, hw = 0.5 * (a + b), 0.5 * (b - a)
            return float(np.sum(wg * hw / EI_fn(m + hw * xg)))

        ds = np.diff(s)
        K = np.empty(N)
        lens = np.empty(N)
        c0 = int_inv_EI(s[0], s[0] + 0.5 * ds[0])
        if k_root is not None:
            c0 += 1.0 / k_root
        K[0] = 1.0 / c0
        lens[0] = 0.5 * ds[0]
        for j in range(1, N):
            a, b = s[j] - 0.5 * ds[j - 1], s[j] + 0.5 * ds[j]
            K[j] = 1.0 / int_inv_EI(a, b)
            lens[j] = b - a
        self.K = K
        self.dual = lens
        self.soft = None
        if soft is not None:
            beta, eps_y, d_fn = soft
            # yield rotation per node: kappa_y * cell length, kappa_y = 2 eps_y / d
            dy = 2.0 * eps_y / d_fn(s[:N]) * lens
            self.soft = (float(beta), dy)

    # natural rotation jumps at nodes: node 0 relative to the ground (th0[0])
    def _dtheta(self, th):
        d = np.empty(self.N)
        d[0] = th[0] - self.th0[0]
        d[1:] = (th[1:] - th[:-1]) - (self.th0[1:] - self.th0[:-1])
        return d

    def _moment(self, dth):
        """moment and tangent stiffness at each node for rotation jumps dth"""
        if self.soft is None:
            return self.K * dth, self.K.copy()
        beta, dy = self.soft
        t = np.tanh(dth / dy)
        M = self.K * ((1 - beta) * dth + beta * dy * t)
        Kt = self.K * ((1 - beta) + beta * (1 - t * t))
        return M, Kt

    def positions(self, th):
        e = np.stack([np.cos(th), np.sin(th)], axis=1) * self.h[:, None]
        out = np.empty((self.N + 1, 2))
        out[0] = self.r0[0]
        out[1:] = self.r0[0] + np.cumsum(e, axis=0)
        return out


class Interaction:
    """point interaction at node q along unit vector d (in the x-z plane)."""

    def __init__(self, node, d, kind, **kw):
        self.node = int(node)
        self.d = np.asarray(d, float) / np.linalg.norm(d)
        self.kind = kind          # 'gap', 'anchor', 'force'
        self.k = kw.get('k', 0.0)
        self.gap = kw.get('gap', 0.0)
        self.a = kw.get('a', 0.0)
        self.f = kw.get('f', 0.0)
        self.active = True

    def V1V2(self, delta):
        if not self.active:
            return 0.0, 0.0
        if self.kind == 'gap':
            x = delta - self.gap
            return (self.k * x, self.k) if x > 0 else (0.0, 0.0)
        if self.kind == 'anchor':
            return self.k * (delta - self.a), self.k
        if self.kind == 'force':
            return self.f, 0.0
        raise ValueError(self.kind)


class Solver:
    """Displacement-controlled probe on a Chain.

    p : probe node; d : probe unit vector (force on the cane = F d);
    k_rig : series spring (N/m) or None.
    """

    def __init__(self, chain: Chain, p, d, k_rig=None, inter=()):
        self.c = chain
        self.p = int(p)
        self.d = np.asarray(d, float) / np.linalg.norm(d)
        self.comp = 0.0 if k_rig is None else 1.0 / k_rig
        self.inter = list(inter)
        self.th = chain.th0.copy()
        self.F = 0.0
        self.u = 0.0

    def delta(self, th, node, d):
        """(r_node - r0_node).d, gradient, hessian diagonal"""
        c = self.c
        cs, sn = np.cos(th[:node]), np.sin(th[:node])
        h = c.h[:node]
        pos = np.sum(h * (cs * d[0] + sn * d[1]))
        pos0 = np.dot(c.r0[node] - c.r0[0], d)
        g = np.zeros(c.N)
        g[:node] = h * (-sn * d[0] + cs * d[1])
        H = np.zeros(c.N)
        H[:node] = -h * (cs * d[0] + sn * d[1])
        return pos - pos0, g, H

    def residual_jac(self, th, F, u):
        c = self.c
        N = c.N
        dth = c._dtheta(th)
        M, Kt = c._moment(dth)
        # gradient of bending energy: node 0 acts on th[0]; node j (>=1) on th[j-1] (-) and th[j] (+)
        R = np.zeros(N + 1)
        R[:N] += M
        R[:N - 1] -= M[1:]
        J = np.zeros((N + 1, N + 1))
        idx = np.arange(N)
        J[idx, idx] += Kt
        J[idx[:-1], idx[:-1]] += Kt[1:]
        J[idx[:-1], idx[1:]] -= Kt[1:]
        J[idx[1:], idx[:-1]] -= Kt[1:]
        for it in self.inter:
            dl, g, Hd = self.delta(th, it.node, it.d)
            V1, V2 = it.V1V2(dl)
            if V1 == 0.0 and V2 == 0.0:
                continue
            R[:N] += V1 * g
            J[:N, :N] += V2 * np.outer(g, g)
            J[idx, idx] += V1 * Hd
        gp, gg, gH = self.delta(th, self.p, self.d)
        R[:N] -= F * gg
        J[idx, idx] -= F * gH
        J[:N, N] = -gg
        R[N] = gp + self.comp * F - u
        J[N, :N] = gg
        J[N, N] = self.comp
        return R, J

    def solve_at(self, u, th=None, F=None, maxit=40):
        th = self.th.copy() if th is None else th.copy()
        F = self.F if F is None else F
        for it in range(maxit):
            R, J = self.residual_jac(th, F, u)
            try:
                dx = np.linalg.solve(J, -R)
            except np.linalg.LinAlgError:
                return th, F, False
            if not np.all(np.isfinite(dx)):
                return th, F, False
            mx = np.max(np.abs(dx[:-1]))
            if mx > 0.2:
                dx *= 0.2 / mx
            th = th + dx[:-1]
            F = F + dx[-1]
            if mx < 1e-11 and abs(dx[-1]) < 1e-9 * (1.0 + abs(F)):
                return th, F, True
        return th, F, False

    def advance(self, u):
        """move the probe from its present position to u (continuation)."""
        todo = [u]
        while todo:
            target = todo[-1]
            th, F, ok = self.solve_at(target)
            if ok:
                self.th, self.F, self.u = th, F, target
                todo.pop()
            else:
                mid = 0.5 * (self.u + target)
                if abs(mid - target) < 1e-10:
                    raise RuntimeError('no convergence at u=%g' % target)
                todo.append(mid)
        return self.F

    def node_delta(self, node, d):
        return self.delta(self.th, node, np.asarray(d, float))[0]


# --------------------------------------------------------------------------
# helpers
# --------------------------------------------------------------------------
def chain_from_curve(curve, EI_fn, s_special, s_max, h_target=0.01, k_root=None,
                     soft=None, min_nodes=8):
    """Build a chain from curve(s) -> (x, z), with nodes at every s in s_special.

    Returns chain and a dict special s -> node index.
    """
    pts = sorted(set([0.0] + [float(v) for v in s_special] + [float(s_max)]))
    nodes = [0.0]
    for a, b in zip(pts[:-1], pts[1:]):
        n = max(1, int(np.ceil((b - a) / h_target)))
        nodes.extend(list(a + (b - a) * np.arange(1, n + 1) / n))
    nodes = np.array(nodes)
    if len(nodes) < min_nodes + 1:
        nodes = np.linspace(0, s_max, min_nodes + 1)
        nodes = np.unique(np.concatenate([nodes, pts]))
    xz = np.array([curve(v) for v in nodes])
    ch = Chain(nodes, xz, EI_fn, k_root=k_root, soft=soft)
    where = {v: int(np.argmin(np.abs(nodes - v))) for v in s_special}
    return ch, where


def push_curve(solver, us):
    """forces at a list of increasing probe positions (from the current state)"""
    out = []
    for u in us:
        out.append(solver.advance(u))
    return np.array(out)
