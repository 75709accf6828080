"""Planar large-deflection rod (inextensible, shear-free Euler elastica) for a
tapered, curved cane clamped at its base (optionally through a rotational
base spring), with self-weight, point probes (displacement- or load-
controlled), and optional lateral linear springs (a neighbouring cane).

Discretisation: N straight elements of length h = L/N, unknowns are the
element angles theta_j measured from +z (vertical) toward +x, so
x = sum h sin(theta), z = sum h cos(theta).  Rotational springs sit at nodes
0..N-1 (Voronoi placement): node k joins element k-1 and k (node 0 joins
the clamp and element 0).  Spring k has stiffness 1 / integral(ds / EI) over
its dual cell ([0, h/2] at the clamp, [s_k - h/2, s_k + h/2] inside), the
clamp one in series with the base spring k_root if given.

The cane is planar: its curvature and the probe lie in the (x, z) plane.

rest='given'       : the initial angles are the stress-free shape.
rest='equilibrium' : the initial angles are the equilibrium shape under
                     self-weight (what a photo shows); the stress-free
                     curvature is back-computed (the cantilever is statically
                     determinate, so this is exact for the discrete model).
"""
import numpy as np

G = 9.81


class Rod2D:
    def __init__(self, L, N, d_func, E, theta, rho=580.0, gravity=True,
                 k_root=None, base=(0.0, 0.0), rest="given", springs=(),
                 nsub=8):
        self.L, self.N = float(L), int(N)
        h = self.h = self.L / self.N
        self.E = E
        self.theta0 = np.asarray(theta, float).copy()
        assert self.theta0.shape == (self.N,)
        self.base = np.asarray(base, float)
        # --- bending springs at nodes 0..N-1 (dual-cell integrated compliance)
        EI = lambda s: E * np.pi * np.asarray(d_func(s)) ** 4 / 64.0
        K = np.empty(self.N)
        u = (np.arange(nsub) + 0.5) / nsub
        for k in range(self.N):
            a, b = (0.0, h / 2) if k == 0 else (k * h - h / 2, k * h + h / 2)
            ss = a + (b - a) * u
            K[k] = 1.0 / (np.mean(1.0 / EI(ss)) * (b - a))
        self.K_clamp_beam = K[0]
        if k_root is not None and np.isfinite(k_root):
            K[0] = 1.0 / (1.0 / K[0] + 1.0 / k_root)
        self.K = K
        # --- element weights
        if gravity:
            w = np.empty(self.N)
            for i in range(self.N):
                ss = i * h + h * u
                w[i] = rho * G * np.pi / 4 * np.mean(np.asarray(d_func(ss)) ** 2) * h
        else:
            w = np.zeros(self.N)
        self.w = w
        # W_j = w_j/2 + sum_{i>j} w_i  (weight "carried" by element j's rotation)
        tail = np.concatenate([np.cumsum(w[::-1])[::-1][1:], [0.0]])
        self.W = w / 2 + tail
        # --- springs to ground (lateral supports), reference at initial shape
        self.springs = []
        for sp in springs:
            e = np.asarray(sp["dir"], float)
            e = e / np.linalg.norm(e)
            r0 = self.point(sp["s"], self.theta0)
            self.springs.append(dict(s=float(sp["s"]), e=e, k=float(sp["k"]), r0=r0))
        # --- rest state
        self.theta_c = self.theta0[0]
        dth = np.diff(np.concatenate([[self.theta_c], self.theta0]))
        if rest == "given":
            self.D0 = dth
        elif rest == "equilibrium":
            m = np.cumsum((h * np.sin(self.theta0) * self.W)[::-1])[::-1]
            self.D0 = dth - m / self.K
        else:
            raise ValueError(rest)

    # ---------------------------------------------------------------- geometry
    def coef(self, s):
        """a_j such that r(s) = base + h * sum_j a_j (sin th_j, cos th_j)."""
        x = np.clip(s / self.h, 0.0, self.N)
        k = min(int(np.floor(x)), self.N - 1)
        a = np.zeros(self.N)
        a[:k] = 1.0
        a[k] = x - k
        return a

    def point(self, s, th):
        a = self.coef(s)
        return self.base + self.h * np.array([a @ np.sin(th), a @ np.cos(th)])

    def nodes(self, th):
        xs = np.concatenate([[0], np.cumsum(self.h * np.sin(th))])
        zs = np.concatenate([[0], np.cumsum(self.h * np.cos(th))])
        return self.base + np.stack([xs, zs], 1)

    def _jac_dir(self, a, th, d):
        """gradient of d.r(s) w.r.t. theta, and its (diagonal) Hessian."""
        g = a * self.h * (d[0] * np.cos(th) - d[1] * np.sin(th))
        H = a * self.h * (-d[0] * np.sin(th) - d[1] * np.cos(th))
        return g, H

    # ---------------------------------------------------------------- energy
    def grad_hess(self, th, gamma=1.0):
        N = self.N
        e = np.diff(np.concatenate([[self.theta_c], th])) - self.D0
        m = self.K * e
        g = m.copy()
        g[:-1] -= m[1:]
        g -= gamma * self.h * np.sin(th) * self.W
        H = np.zeros((N, N))
        idx = np.arange(N)
        Kn = np.concatenate([self.K[1:], [0.0]])
        H[idx, idx] = self.K + Kn - gamma * self.h * np.cos(th) * self.W
        H[idx[:-1], idx[:-1] + 1] = -self.K[1:]
        H[idx[:-1] + 1, idx[:-1]] = -self.K[1:]
        for sp in self.springs:
            a = self.coef(sp["s"])
            r = self.point(sp["s"], th)
            dl = sp["e"] @ (r - sp["r0"])
            gj, hj = self._jac_dir(a, th, sp["e"])
            g += sp["k"] * dl * gj
            H += sp["k"] * np.outer(gj, gj)
            H[idx, idx] += sp["k"] * dl * hj
        return g, H

    # ---------------------------------------------------------------- solves
    def compliance(self, s, d, th=None, gamma=1.0):
        """Small-deflection compliance (m/N) of point s along unit d at an
        equilibrium th (no probe load)."""
        th = self.theta0 if th is None else th
        d = np.asarray(d, float) / np.linalg.norm(d)
        _, H = self.grad_hess(th, gamma)
        gj, _ = self._jac_dir(self.coef(s), th, d)
        return gj @ np.linalg.solve(H, gj)

    def cross_compliance(self, s_load, d_load, s_obs, d_obs, th=None):
        th = self.theta0 if th is None else th
        _, H = self.grad_hess(th)
        gl, _ = self._jac_dir(self.coef(s_load), th, np.asarray(d_load, float))
        go, _ = self._jac_dir(self.coef(s_obs), th, np.asarray(d_obs, float))
        x = np.linalg.solve(H, gl)
        return go @ x, x

    def residual_norm(self, th=None, gamma=1.0):
        th = self.theta0 if th is None else th
        g, _ = self.grad_hess(th, gamma)
        return np.max(np.abs(g))

    def solve_load(self, s, d, F, gamma=1.0, nsteps=20, th=None, tol=1e-11):
        """Dead load F (N) along fixed unit d at point s (load control),
        with gravity factor gamma.  Returns angles."""
        d = np.asarray(d, float) / np.linalg.norm(d)
        th = (self.theta0 if th is None else th).copy()
        a = self.coef(s)
        for i in range(1, nsteps + 1):
            f = F * i / nsteps
            for it in range(60):
                g, H = self.grad_hess(th, gamma)
                gj, hj = self._jac_dir(a, th, d)
                R = g - f * gj
                H[np.diag_indices(self.N)] -= f * hj
                dx = np.linalg.solve(H, -R)
                th += dx
                if np.max(np.abs(dx)) < tol:
                    break
            else:
                raise RuntimeError("load step did not converge")
        return th

    def push(self, s, d, u_values, th=None, Fmax=np.inf, tol=1e-10):
        """Displacement control: d.(r(s) - r0(s)) = u for each u in u_values
        (increasing from 0), force along fixed unit d (a frictionless U-probe:
        the cane slides freely across the probe axis).  Returns the probe
        force (N) for each u (stops after the first F > Fmax) and the last
        angles."""
        d = np.asarray(d, float) / np.linalg.norm(d)
        th = (self.theta0 if th is None else th).copy()
        a = self.coef(s)
        r0 = self.point(s, th)
        lam = 0.0
        N = self.N
        out = []
        prev = None
        for u in u_values:
            if prev is not None:     # secant predictor
                th_p, lam_p, u_p, dth, dlam, du = prev
                if du > 0:
                    f = (u - u_p) / du
                    th = th + f * dth
                    lam = lam + f * dlam
            th_start, lam_start = th.copy(), lam
            for it in range(50):
                g, H = self.grad_hess(th)
                gj, hj = self._jac_dir(a, th, d)
                c = d @ (self.point(s, th) - r0) - u
                R = g - lam * gj
                H[np.diag_indices(N)] -= lam * hj
                A = np.zeros((N + 1, N + 1))
                A[:N, :N] = H
                A[:N, N] = -gj
                A[N, :N] = -gj
                sol = np.linalg.solve(A, -np.concatenate([R, [-c]]))
                th += sol[:N]
                lam += sol[N]
                if np.max(np.abs(sol[:N])) < tol:
                    break
            else:
                raise RuntimeError("push step did not converge at u=%g" % u)
            if prev is None:
                prev = (th.copy(), lam, u, th - th_start, lam - lam_start, 0.0)
            else:
                prev = (th.copy(), lam, u, th - prev[0], lam - prev[1], u - prev[2])
            out.append(lam)
            if lam > Fmax:
                break
        return np.array(out), th
