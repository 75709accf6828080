"""Planar geometrically exact (inextensible, unshearable Kirchhoff/Euler-Bernoulli) cantilever rod.

Continuum formulation, solved by shooting from the clamped base with a fixed-step RK4 integrator
(not a chain of rigid links: the centreline, angle and bending moment are integrated as smooth
functions of arc length s).

State along s: x, z (centreline, z up), phi (tangent angle from +x), m (bending moment carried at s:
the moment about r(s) of every external load applied on (s, L], counter-clockwise positive).
    x' = cos phi,  z' = sin phi,  phi' = phi0'(s) + m / EI(s),  m' = -(t x n)
n(s) = resultant of the loads on (s, L]: dead self-weight, the probe force F d (for s < s_p) and an
optional obstruction reaction -G e (for s < s_o). All loads are dead in the global frame, so n(s) is
known once F and G are; the unknowns of a lane are (M0, F, G):
    R1: m(L) = 0                                     (free tip)
    R2: d . (r(s_p) - r_ref(s_p)) = u   (displacement control; or F = F_target, load control)
    R3: G = k_o softplus(e . (r(s_o) - r_ref(s_o)) - gap)   (or G = 0 when there is no obstruction)
Base: phi(0) = phi00 + theta_root(M0), theta_root from a linear spring, a clamp or any compliance law.
Many lanes (trials) are integrated together with numpy; the Jacobian is by finite differences on
extra lanes.
"""
import numpy as np

G_ACC = 9.81


def softplus(x, w):
    return w * np.logaddexp(0.0, x / w)


def theta_root(M, c_root, th_g, M_g):
    return c_root * M + th_g * np.tanh(M / M_g)


def natural_from_photo(phig, phigp, L, EI, q, c_root=0.0, play=(0.0, 1.0), nf=8001):
    """The photographed shape phig(s) is the equilibrium under self-weight. The cantilever is statically
    determinate under dead weight, so the base moment and the moment along s follow from the photo;
    the stress-free curvature is phig' - m_w/EI and the stress-free base angle phig(0) - theta_root(m_w(0))."""
    sf = np.linspace(0, L, nf)
    ph = phig(sf)
    # centreline of the photo (trapezoid on a fine grid)
    ds = np.diff(sf)
    x = np.concatenate([[0], np.cumsum(0.5 * (np.cos(ph[1:]) + np.cos(ph[:-1])) * ds)])
    if q is None:
        mw = np.zeros_like(sf)
    else:
        qf = q(sf)
        def tail(f):
            c = np.concatenate([[0], np.cumsum(0.5 * (f[1:] + f[:-1]) * ds)])
            return c[-1] - c
        mw = -(tail(qf * x) - x * tail(qf))
    phi0p = lambda s: phigp(s) - np.interp(s, sf, mw) / EI(s)
    phi00 = float(phig(0.0) - theta_root(mw[0], c_root, play[0], play[1]))
    return phi0p, phi00, (sf, x, mw)


class RodBatch:
    def __init__(self, lanes, nseg=(220, 80, 160)):
        """lanes: list of dicts with keys
        L, s_p, EI(s)->array, phi0p(s)->array (natural curvature), phi00 (natural base angle),
        q(s)->array weight per length (N/m) or None, d (2,) probe axis, theta_root(M)->array or None,
        obstruction: None or dict(s_o, e (2,), k_o, gap, w)
        """
        self.lanes = lanes
        n = len(lanes)
        self.n = n
        N1, N2, N3 = nseg
        N = N1 + N2 + N3
        self.N = N
        S = np.zeros((n, N + 1))
        self.kp = np.zeros(n, int)
        self.ko = np.zeros(n, int)
        self.has_obs = np.zeros(n, bool)
        for i, ln in enumerate(lanes):
            sp = ln['s_p']
            ob = ln.get('obstruction')
            so = ob['s_o'] if ob else sp
            a, b = min(sp, so), max(sp, so)
            seg = [np.linspace(0, a, N1 + 1), np.linspace(a, b, N2 + 1)[1:], np.linspace(b, ln['L'], N3 + 1)[1:]]
            S[i] = np.concatenate(seg)
            if ob:
                self.has_obs[i] = True
            self.kp[i] = N1 if sp <= so else N1 + N2
            self.ko[i] = N1 if so < sp else N1 + N2
            if not ob:
                self.ko[i] = self.kp[i]
        self.S = S
        H = np.diff(S, axis=1)
        self.H = H
        Smid = 0.5 * (S[:, :-1] + S[:, 1:])
        # per-step probe / obstruction indicator (step k lies wholly on one side of s_p, s_o)
        kk = np.arange(N)[None, :]
        self.hp = (kk < self.kp[:, None]).astype(float)
        self.ho = ((kk < self.ko[:, None]) & self.has_obs[:, None]).astype(float)
        self.EIn = np.zeros((n, N + 1)); self.EIm = np.zeros((n, N))
        self.K0n = np.zeros((n, N + 1)); self.K0m = np.zeros((n, N))
        self.Wn = np.zeros((n, N + 1)); self.Wm = np.zeros((n, N))
        self.phi00 = np.zeros(n)
        self.d = np.zeros((n, 2)); self.e = np.zeros((n, 2))
        self.k_o = np.zeros(n); self.gap = np.zeros(n); self.w_o = np.full(n, 1e-4)
        for i, ln in enumerate(lanes):
            self.EIn[i] = ln['EI'](S[i]); self.EIm[i] = ln['EI'](Smid[i])
            self.K0n[i] = ln['phi0p'](S[i]); self.K0m[i] = ln['phi0p'](Smid[i])
            if ln.get('q') is not None:
                # W(s) = int_s^L q, on a fine grid
                sf = np.linspace(0, ln['L'], 8001)
                qf = ln['q'](sf)
                cum = np.concatenate([[0], np.cumsum(0.5 * (qf[1:] + qf[:-1]) * np.diff(sf))])
                Wf = cum[-1] - cum
                self.Wn[i] = np.interp(S[i], sf, Wf); self.Wm[i] = np.interp(Smid[i], sf, Wf)
            self.phi00[i] = ln['phi00']
            self.d[i] = ln['d']
            ob = ln.get('obstruction')
            if ob:
                self.e[i] = ob['e']; self.k_o[i] = ob['k_o']; self.gap[i] = ob['gap']; self.w_o[i] = ob.get('w', 2e-4)
        # base compliance law: theta = c_root*M + th_g*tanh(M/M_g)  (c_root = 1/k_root; 0 = clamped)
        self.c_root = np.array([ln.get('c_root', 0.0) for ln in lanes], float)
        self.th_g = np.array([ln.get('play', (0.0, 1.0))[0] for ln in lanes], float)
        self.M_g = np.array([ln.get('play', (0.0, 1.0))[1] for ln in lanes], float)
        self.ref = None

    # ---------------------------------------------------------------
    def _theta(self, M0, idx):
        return theta_root(M0, self.c_root[idx], self.th_g[idx], self.M_g[idx])

    def integrate(self, M0, F, G, idx):
        """Integrate lanes idx (array of lane indices, repeats allowed). Returns m(L), r_p, r_o, full path opt."""
        idx = np.asarray(idx)
        H = self.H[idx]; hp = self.hp[idx]; ho = self.ho[idx]
        EIn = self.EIn[idx]; EIm = self.EIm[idx]; K0n = self.K0n[idx]; K0m = self.K0m[idx]
        Wn = self.Wn[idx]; Wm = self.Wm[idx]
        d = self.d[idx]; e = self.e[idx]
        x = np.zeros(len(idx)); z = np.zeros(len(idx))
        phi = self.phi00[idx] + self._theta(M0, idx)
        m = M0.copy()
        kp = self.kp[idx]; ko = self.ko[idx]
        rp = np.zeros((len(idx), 2)); ro = np.zeros((len(idx), 2))
        Fdx = F * d[:, 0]; Fdz = F * d[:, 1]; Gex = G * e[:, 0]; Gez = G * e[:, 1]
        ar = np.arange(len(idx))
        for k in range(self.N):
            sel = kp == k
            if sel.any():
                rp[sel, 0] = x[sel]; rp[sel, 1] = z[sel]
            sel = ko == k
            if sel.any():
                ro[sel, 0] = x[sel]; ro[sel, 1] = z[sel]
            h = H[:, k]
            nx = hp[:, k] * Fdx - ho[:, k] * Gex
            nzc = hp[:, k] * Fdz - ho[:, k] * Gez
            nz0 = nzc - Wn[:, k]; nzm = nzc - Wm[:, k]; nz1 = nzc - Wn[:, k + 1]
            # stage 1
            c = np.cos(phi); s_ = np.sin(phi)
            k1x, k1z = c, s_
            k1p = K0n[:, k] + m / EIn[:, k]
            k1m = -(c * nz0 - s_ * nx)
            p2 = phi + 0.5 * h * k1p; m2 = m + 0.5 * h * k1m
            c = np.cos(p2); s_ = np.sin(p2)
            k2x, k2z = c, s_
            k2p = K0m[:, k] + m2 / EIm[:, k]
            k2m = -(c * nzm - s_ * nx)
            p3 = phi + 0.5 * h * k2p; m3 = m + 0.5 * h * k2m
            c = np.cos(p3); s_ = np.sin(p3)
            k3x, k3z = c, s_
            k3p = K0m[:, k] + m3 / EIm[:, k]
            k3m = -(c * nzm - s_ * nx)
            p4 = phi + h * k3p; m4 = m + h * k3m
            c = np.cos(p4); s_ = np.sin(p4)
            k4x, k4z = c, s_
            k4p = K0n[:, k + 1] + m4 / EIn[:, k + 1]
            k4m = -(c * nz1 - s_ * nx)
            x = x + h / 6 * (k1x + 2 * k2x + 2 * k3x + k4x)
            z = z + h / 6 * (k1z + 2 * k2z + 2 * k3z + k4z)
            phi = phi + h / 6 * (k1p + 2 * k2p + 2 * k3p + k4p)
            m = m + h / 6 * (k1m + 2 * k2m + 2 * k3m + k4m)
        sel = kp == self.N
        rp[sel, 0] = x[sel]; rp[sel, 1] = z[sel]
        sel = ko == self.N
        ro[sel, 0] = x[sel]; ro[sel, 1] = z[sel]
        return m, rp, ro, np.stack([x, z, phi], 1)

    def residual(self, X, u, idx, force_ctrl=None):
        M0, F, G = X[:, 0], X[:, 1], X[:, 2]
        mL, rp, ro, tip = self.integrate(M0, F, G, idx)
        Ms = self.Mscale[idx]
        R1 = mL / Ms
        dp = np.einsum('ij,ij->i', self.d[idx], rp - self.ref_p[idx])
        if force_ctrl is not None:
            R2 = np.where(force_ctrl[idx], (F - u) / self.Fscale[idx], (dp - u) / 1e-3)
        else:
            R2 = (dp - u) / 1e-3
        eo = np.einsum('ij,ij->i', self.e[idx], ro - self.ref_o[idx])
        Gt = np.where(self.has_obs[idx], self.k_o[idx] * softplus(eo - self.gap[idx], self.w_o[idx]), 0.0)
        R3 = (G - Gt) / self.Fscale[idx]
        return np.stack([R1, R2, R3], 1), dict(dp=dp, eo=eo, tip=tip, rp=rp)

    def solve(self, X0, u, idx=None, force_ctrl=None, tol=1e-10, maxit=40):
        if idx is None:
            idx = np.arange(self.n)
        X = X0.copy()
        nl = len(idx)
        steps = np.stack([self.Mscale[idx] * 1e-6, self.Fscale[idx] * 1e-6, self.Fscale[idx] * 1e-6], 1)
        for it in range(maxit):
            # base + 3 perturbed copies
            XX = np.concatenate([X] + [X + np.eye(3)[j] * steps for j in range(3)])
            II = np.concatenate([idx] * 4)
            UU = np.concatenate([u] * 4)
            R, info = self.residual(XX, UU, II, force_ctrl)
            R0 = R[:nl]
            J = np.stack([(R[(j + 1) * nl:(j + 2) * nl] - R0) / steps[:, j:j + 1] for j in range(3)], 2)
            err = np.abs(R0).max()
            if err < tol:
                return X, dict((k, v[:nl]) for k, v in info.items()), err
            dX = np.linalg.solve(J, -R0[:, :, None])[:, :, 0]
            # damp big steps
            X = X + dX
        return X, dict((k, v[:nl]) for k, v in info.items()), err

    def reference(self):
        """Equilibrium under self-weight only (F = G = 0): defines r_ref at the probe and obstruction."""
        n = self.n
        self.Mscale = np.ones(n); self.Fscale = np.ones(n)
        self.ref_p = np.zeros((n, 2)); self.ref_o = np.zeros((n, 2))
        idx = np.arange(n)
        M = np.zeros(n)
        # 1-D Newton on M0 with F = G = 0
        for it in range(50):
            mL, rp, ro, tip = self.integrate(M, np.zeros(n), np.zeros(n), idx)
            mL2, *_ = self.integrate(M + 1e-6, np.zeros(n), np.zeros(n), idx)
            dm = -mL / ((mL2 - mL) / 1e-6)
            M = M + dm
            if np.abs(dm).max() < 1e-13:
                break
        mL, rp, ro, tip = self.integrate(M, np.zeros(n), np.zeros(n), idx)
        self.ref_p = rp; self.ref_o = ro; self.M_ref = M
        self.Mscale = np.maximum(np.abs(M), 0.05)
        return M

    def push(self, u_list, active=None):
        """Displacement-controlled continuation. Returns arrays F[n, len(u)], G, and the obstruction
        approach eo (e.(r_o - r_ref) - gap < 0 means open)."""
        n = self.n
        if self.ref is None:
            self.reference(); self.ref = True
        X = np.zeros((n, 3)); X[:, 0] = self.M_ref
        Xprev = X.copy()
        out_F = np.zeros((n, len(u_list))); out_G = np.zeros_like(out_F); out_eo = np.zeros_like(out_F)
        out_err = np.zeros(len(u_list))
        uprev = 0.0
        for j, u in enumerate(u_list):
            if j >= 2:
                X0 = X + (X - Xprev) * (u - u_list[j - 1]) / max(u_list[j - 1] - u_list[j - 2], 1e-12)
            else:
                X0 = X.copy()
            Xn, info, err = self.solve(X0, np.full(n, u))
            if not np.all(np.isfinite(Xn)) or err > 1e-6:
                # retry with substeps from the last converged state
                Xs = X.copy(); ua = u_list[j - 1] if j else 0.0
                for uu in np.linspace(ua, u, 9)[1:]:
                    Xs, info, err = self.solve(Xs, np.full(n, uu), maxit=80)
                Xn = Xs
            Xprev, X = X, Xn
            out_F[:, j] = X[:, 1]; out_G[:, j] = X[:, 2]
            out_eo[:, j] = info['eo'] - self.gap
            out_err[j] = err
        return out_F, out_G, out_eo, out_err
