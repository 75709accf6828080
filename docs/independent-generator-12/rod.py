"""Planar geometrically exact (inextensible Euler elastica) rod, clamped base,
variable EI(s), natural curvature, point push under displacement control.

Discretisation: N straight segments of the loaded part [0, s_p] (the part above
the push point carries no load: no self-weight is modelled), angle theta_j per
segment, rotational springs at nodes with Voronoi stiffness (interior EI/h,
clamp 2EI/h).  Unknowns: theta_0..theta_{N-1}, optional base rotation phi
(base spring), and the probe force lam along the fixed probe axis d.  The probe
is a frictionless U: it constrains only the displacement of the push point
along d, so the force on the cane is lam*d (a fixed-direction load).
Coordinates are (x, z) in the cane plane; angles from +x, counter-clockwise.
"""
import numpy as np


class Base:
    """Base rotational spring M(phi). kind: 'clamp', 'linear', 'plastic'."""
    def __init__(self, kind='clamp', k=None, M_y=None, k_hard=0.0):
        self.kind, self.k, self.M_y, self.k_hard = kind, k, M_y, k_hard

    def M(self, phi):
        if self.kind == 'linear':
            return self.k * phi, self.k
        # smooth elastic-plastic hinge: M = My tanh(k phi / My) + k_hard phi
        t = np.tanh(self.k * phi / self.M_y)
        return self.M_y * t + self.k_hard * phi, self.k * (1 - t * t) + self.k_hard


def solve_push(s_p, EI_fn, theta0_fn, d, u_max, du=0.5e-3, N=80, base=None,
               F_stop=None, tol=1e-11, return_state=False):
    """Push the material point at arc length s_p along unit d=(dx,dz) from u=0
    to u_max in steps du.  Returns arrays u (m), lam (N, force along d)."""
    d = np.asarray(d, float); d = d / np.linalg.norm(d)
    h = s_p / N
    sm = (np.arange(N) + 0.5) * h
    th0 = np.array([theta0_fn(s) for s in sm])
    thc = theta0_fn(0.0)
    K = np.array([EI_fn(i * h) / h for i in range(N)])
    K[0] = 2.0 * EI_fn(0.25 * h) / h
    dth0 = np.diff(np.concatenate([[thc], th0]))
    has_phi = base is not None and base.kind != 'clamp'
    n = N + (1 if has_phi else 0) + 1
    P0 = h * np.array([np.cos(th0).sum(), np.sin(th0).sum()]) @ d
    x = np.concatenate([th0, [0.0] if has_phi else [], [0.0]])
    U = np.triu(np.ones((N, N)))

    def resid_jac(x, u):
        th = x[:N]; phi = x[N] if has_phi else 0.0; lam = x[-1]
        c, s = np.cos(th), np.sin(th)
        m = h * (c * d[1] - s * d[0])             # moment per unit force, per segment
        Msum = np.cumsum(m[::-1])[::-1]            # sum_{j>=i}
        prev = np.concatenate([[thc + phi], th[:-1]])
        R = np.empty(n); J = np.zeros((n, n))
        R[:N] = K * (th - prev - dth0) - lam * Msum
        dm = h * (-s * d[1] - c * d[0])
        J[:N, :N] = -lam * U * dm[None, :]
        J[np.arange(N), np.arange(N)] += K
        J[np.arange(1, N), np.arange(N - 1)] -= K[1:]
        J[:N, -1] = -Msum
        if has_phi:
            Mb, dMb = base.M(phi)
            R[N] = Mb - lam * Msum[0]
            J[0, N] = -K[0]
            J[N, N] = dMb
            J[N, :N] = -lam * dm
            J[N, -1] = -Msum[0]
        R[-1] = h * (c * d[0] + s * d[1]).sum() - P0 - u
        J[-1, :N] = h * (-s * d[0] + c * d[1])
        return R, J

    us, lams = [0.0], [0.0]
    xprev = x.copy(); u = 0.0
    nstep = int(round(u_max / du))
    for k in range(1, nstep + 1):
        u = k * du
        xg = x + (x - xprev) if k > 1 else x.copy()
        xprev = x.copy(); x = xg
        for it in range(40):
            R, J = resid_jac(x, u)
            dx = np.linalg.solve(J, -R)
            x += dx
            if np.max(np.abs(dx)) < tol:
                break
        else:
            raise RuntimeError('Newton did not converge at u=%g' % u)
        us.append(u); lams.append(x[-1])
        if F_stop is not None and x[-1] > F_stop:
            break
    out = (np.array(us), np.array(lams))
    if return_state:
        th = x[:N]
        tip = h * np.array([np.cos(th).sum(), np.sin(th).sum()])
        return out + (th, tip, (x[N] if has_phi else 0.0))
    return out
