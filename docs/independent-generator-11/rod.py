"""Independent large-deflection 3D elastic rod (discrete Kirchhoff rod, shooting).

The rod is a chain of N straight inextensible segments between N+1 nodes
(node 0 = clamped base).  Joint i (at node i, between segment i-1 and i) is an
elastic rotation  R_i = R_{i-1} exp(hat(Omega0_i + Omega_el_i)),  with
Omega_el = K^-1 (moment in the joint's mid frame),
K = diag(EI, EI, GJ) / dual_length  (Voronoi placement: the clamp joint uses
half the first segment, interior joints the mean of the two segments).
This converges to the Kirchhoff rod at O(1/N^2).

Equilibrium is found by shooting from the base: the unknowns are the base
force n0 and base moment m0 (world frame) and the probe force F; the
residuals are zero force and moment at the free tip plus the probe
constraint (displacement along a fixed axis, or a prescribed force).  The
walk base->tip is batched over columns so the Jacobian (central
differences) costs one walk.  Loads: self-weight of every segment at its
midpoint, a probe force F*e at a node, and optional node springs
(bilateral lateral springs, unilateral gap springs).  Optional rotational
spring at the base (root compliance) about the two axes perpendicular to
the base tangent, and optional soft joints (a crack) at chosen nodes.
"""
import numpy as np

G_ACC = 9.81


def hat(v):
    z = np.zeros(v.shape[:-1] + (3, 3))
    z[..., 0, 1] = -v[..., 2]; z[..., 0, 2] = v[..., 1]
    z[..., 1, 0] = v[..., 2]; z[..., 1, 2] = -v[..., 0]
    z[..., 2, 0] = -v[..., 1]; z[..., 2, 1] = v[..., 0]
    return z


def expm_so3(w):
    """Rodrigues, batched: w (...,3) -> (...,3,3)."""
    th2 = np.sum(w * w, axis=-1)
    th = np.sqrt(th2)
    small = th < 1e-4
    ths = np.where(small, 1.0, th)
    A = np.where(small, 1 - th2 / 6 + th2 * th2 / 120, np.sin(ths) / ths)
    B = np.where(small, 0.5 - th2 / 24 + th2 * th2 / 720, (1 - np.cos(ths)) / (ths * ths))
    K = hat(w)
    KK = K @ K
    return np.eye(3) + A[..., None, None] * K + B[..., None, None] * KK


def logm_so3(R):
    c = np.clip((np.trace(R, axis1=-2, axis2=-1) - 1) / 2, -1, 1)
    th = np.arccos(c)
    v = np.stack([R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]], -1)
    s = np.where(th < 1e-6, 1.0, th / np.where(th < 1e-6, 1.0, 2 * np.sin(th)))
    s = np.where(th < 1e-6, 0.5, s)
    return v * s[..., None]


def softplus(g, w):
    x = g / w
    return w * np.where(x > 30, x, np.log1p(np.exp(np.minimum(x, 30))))


def sigmoid(x):
    return 0.5 * (1 + np.tanh(0.5 * x))


class Rod:
    def __init__(self, r0, d_nodes, E, nu=0.3, rho=580.0, gravity=True,
                 k_root=None, soft_joints=None, d_mid=None, EI_nodes=None, GJ_nodes=None,
                 weight_per_len=None, frame0_d1=None):
        r0 = np.asarray(r0, float)
        self.N = len(r0) - 1
        self.r0 = r0
        seg = np.diff(r0, axis=0)
        self.h = np.linalg.norm(seg, axis=1)
        assert np.all(self.h > 0)
        t = seg / self.h[:, None]
        # parallel-transported frames per segment, columns d1,d2,d3
        R = np.zeros((self.N, 3, 3))
        if frame0_d1 is None:
            ref = np.array([1.0, 0, 0]) if abs(t[0, 0]) < 0.9 else np.array([0, 1.0, 0])
        else:
            ref = np.asarray(frame0_d1, float)
        d1 = ref - ref.dot(t[0]) * t[0]; d1 /= np.linalg.norm(d1)
        for i in range(self.N):
            if i > 0:
                a, b = t[i - 1], t[i]
                ax = np.cross(a, b); sn = np.linalg.norm(ax); cs = a.dot(b)
                if sn > 1e-14:
                    ang = np.arctan2(sn, cs)
                    d1 = expm_so3(ax / sn * ang) @ d1
                d1 = d1 - d1.dot(b) * b; d1 /= np.linalg.norm(d1)
            R[i, :, 0] = d1; R[i, :, 1] = np.cross(t[i], d1); R[i, :, 2] = t[i]
        self.R_nat = R
        # natural joint rotations (joint i between seg i-1 and seg i), i=1..N-1
        self.Om0 = np.zeros((self.N, 3))
        for i in range(1, self.N):
            self.Om0[i] = logm_so3(R[i - 1].T @ R[i])
        d_nodes = np.asarray(d_nodes, float)
        E = np.broadcast_to(np.asarray(E, float), d_nodes.shape)
        I = np.pi * d_nodes ** 4 / 64
        EI = E * I if EI_nodes is None else np.asarray(EI_nodes, float)
        GJ = EI / (1 + nu) if GJ_nodes is None else np.asarray(GJ_nodes, float)
        dual = np.empty(self.N)
        dual[0] = self.h[0] / 2
        dual[1:] = (self.h[:-1] + self.h[1:]) / 2
        self.Kinv = np.stack([dual / EI[:-1], dual / EI[:-1], dual / GJ[:-1]], 1)  # joints 0..N-1
        if soft_joints:
            for node, kb in soft_joints.items():   # kb: bending spring (N m/rad) in series
                self.Kinv[node, 0] += 1.0 / kb
                self.Kinv[node, 1] += 1.0 / kb
        if d_mid is None:
            d_mid = 0.5 * (d_nodes[:-1] + d_nodes[1:])
        wpl = rho * np.pi * np.asarray(d_mid) ** 2 / 4 * G_ACC if weight_per_len is None else weight_per_len
        self.w = np.zeros((self.N, 3))
        if gravity:
            self.w[:, 2] = -np.broadcast_to(wpl, (self.N,)) * self.h
        self.k_root = k_root
        self.L = self.h.sum()
        self.s = np.concatenate([[0], np.cumsum(self.h)])

    # ------------------------------------------------------------------
    def walk(self, X, probe=None, springs=(), record=False):
        """X (B,7) scaled unknowns [n0, m0/L, F]. Returns residual (B,7) (+ positions)."""
        B = X.shape[0]
        L = self.L
        n = X[:, 0:3].copy()
        m = X[:, 3:6] * L
        F = X[:, 6]
        r = np.broadcast_to(self.r0[0], (B, 3)).copy()
        spr = {}
        for sp in springs:
            spr.setdefault(sp['node'], []).append(sp)
        pnode = probe['node'] if probe is not None else -1
        pos = np.zeros((B, self.N + 1, 3)) if record else None
        if record:
            pos[:, 0] = r
        Rb = np.broadcast_to(self.R_nat[0], (B, 3, 3))
        if self.k_root is not None:
            t0 = self.R_nat[0][:, 2]
            mp = m - (m @ t0)[:, None] * t0[None, :]
            Rb = expm_so3(mp / self.k_root) @ Rb
        R = Rb
        rp = None
        for i in range(self.N):
            # joint i (at node i): rotation from previous frame (or clamp frame)
            mb = np.einsum('bji,bj->bi', R, m)
            Om = self.Kinv[i] * mb
            Rm = R @ expm_so3(0.5 * (Om + self.Om0[i]))
            mb = np.einsum('bji,bj->bi', Rm, m)
            Om = self.Kinv[i] * mb
            R = R @ expm_so3(Om + self.Om0[i])
            d3 = R[:, :, 2]
            h = self.h[i]
            w = self.w[i]
            rn = r + h * d3
            n = n - w
            m = m - np.cross(0.5 * h * d3, w[None, :]) - np.cross(h * d3, n)
            r = rn
            j = i + 1
            if record:
                pos[:, j] = r
            if j == pnode:
                n = n - F[:, None] * probe['e'][None, :]
                rp = r
            if j in spr:
                for sp in spr[j]:
                    f = self._spring_force(sp, r)
                    n = n - f
        res = np.zeros((B, 7))
        res[:, 0:3] = n
        res[:, 3:6] = m / L
        if probe is None:
            res[:, 6] = F
        elif probe['mode'] == 'force':
            res[:, 6] = F - probe['F']
        else:
            res[:, 6] = ((rp - probe['rc'][None, :]) @ probe['e'] - probe['delta']) / probe.get('ls', 1e-3)
        if record:
            return res, pos
        return res

    @staticmethod
    def _spring_force(sp, r):
        if sp['kind'] == 'lateral':        # bilateral spring in the plane perpendicular to axis
            dv = r - sp['anchor'][None, :]
            a = sp.get('axis', np.array([0, 0, 1.0]))
            dv = dv - (dv @ a)[:, None] * a[None, :]
            return -sp['k'] * dv
        if sp['kind'] == 'gap':            # unilateral body along e after a gap
            g = (r - sp['anchor'][None, :]) @ sp['e'] - sp['gap']
            return -sp['k'] * softplus(g, sp.get('w', 2e-4))[:, None] * sp['e'][None, :]
        raise ValueError(sp['kind'])

    def solve(self, x0, probe=None, springs=(), tol=1e-11, maxit=40, eps=1e-6):
        x = np.array(x0, float)
        for it in range(maxit):
            Xb = np.repeat(x[None, :], 15, 0)
            for j in range(7):
                Xb[1 + 2 * j, j] += eps
                Xb[2 + 2 * j, j] -= eps
            Rb = self.walk(Xb, probe, springs)
            r = Rb[0]
            nr = np.abs(r).max()
            if nr < tol:
                return x, True
            J = np.stack([(Rb[1 + 2 * j] - Rb[2 + 2 * j]) / (2 * eps) for j in range(7)], 1)
            try:
                dx = -np.linalg.solve(J, r)
            except np.linalg.LinAlgError:
                dx = -np.linalg.lstsq(J, r, rcond=None)[0]
            # damped step
            lam = 1.0
            for _ in range(12):
                xn = x + lam * dx
                rn = self.walk(xn[None, :], probe, springs)[0]
                if np.all(np.isfinite(rn)) and np.abs(rn).max() < nr * (1 - 0.1 * lam) + 1e-13:
                    break
                lam *= 0.5
            x = xn
        r = self.walk(x[None, :], probe, springs)[0]
        return x, np.abs(r).max() < 1e-7

    def rigid_guess(self):
        """Base reactions of the undeformed rod under its weight (exact if rigid)."""
        n0 = self.w.sum(0)
        mid = 0.5 * (self.r0[:-1] + self.r0[1:])
        m0 = np.cross(mid - self.r0[0], self.w).sum(0)
        return np.concatenate([n0, m0 / self.L, [0.0]])

    def positions(self, x, probe=None, springs=()):
        res, pos = self.walk(np.asarray(x)[None, :], probe, springs, record=True)
        return pos[0]

    def gravity_state(self, springs=()):
        x, ok = self.solve(self.rigid_guess(), None, springs)
        if not ok:   # load continuation on gravity
            w_full = self.w.copy(); x = self.rigid_guess() * 0
            for a in np.linspace(0.1, 1, 10):
                self.w = w_full * a
                x, ok = self.solve(x, None, springs)
            self.w = w_full
        return x, ok

    def push(self, node, e, deltas, x_grav=None, springs=(), record_nodes=()):
        """Displacement-controlled push at node along unit axis e.

        deltas: increasing displacements (m) of the node along e from its
        gravity-equilibrium position. Returns F (N) per delta, the solution
        vectors and the recorded node positions."""
        e = np.asarray(e, float); e = e / np.linalg.norm(e)
        if x_grav is None:
            x_grav, ok = self.gravity_state(springs)
        pos0 = self.positions(x_grav, None, springs)
        rc = pos0[node].copy()
        probe = {'node': node, 'e': e, 'rc': rc, 'mode': 'disp', 'delta': 0.0}
        Fs, xs, rec = [], [], []
        hist = [(0.0, x_grav.copy())]
        ok_all = True
        for d in deltas:
            probe['delta'] = d
            (d1, x1) = hist[-1]
            if len(hist) >= 2 and hist[-1][0] != hist[-2][0]:
                d0_, x0_ = hist[-2]
                guess = x1 + (x1 - x0_) * (d - d1) / (d1 - d0_)
            else:
                guess = x1.copy()
            x_new, ok = self.solve(guess, probe, springs)
            if not ok:
                xs_ = x1.copy()
                for dd in np.linspace(d1, d, 6)[1:]:
                    probe['delta'] = dd
                    xs_, ok = self.solve(xs_, probe, springs, maxit=60)
                x_new = xs_
            ok_all &= ok
            hist.append((d, x_new.copy()))
            x = x_new
            Fs.append(x[6]); xs.append(x.copy())
            if record_nodes:
                p = self.positions(x, probe, springs)
                rec.append(p[list(record_nodes)])
        return np.array(Fs), np.array(xs), (np.array(rec) if record_nodes else None), pos0, ok_all
