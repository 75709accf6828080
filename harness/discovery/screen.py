"""Fast screening model: each trial's small-deflection probe compliance as a
function of the candidate effects' parameters (microseconds per trial).

For a point force along u at the probe point p of a rod clamped at its base,
Castigliano's theorem gives the compliance along u as an integral over the
rod below the probe: the moment of a unit force at r(s) is m(s) = (p - r) x u,
bending about the axes across the tangent t and twisting about t:

    C(u) = u^T [ int A^T (I - t t^T) A / EI(s) + (1 + nu) A^T t t^T A / EI(s) ds ] u,   A = [p - r]x

(GJ = EI / (1 + nu)), evaluated by 3-point Gauss-Legendre on sub-segments of
at most 5 mm of the smoothed centreline. Effects enter as: ``modulus`` scales
E, ``diameter`` changes EI(s) at the quadrature points, ``root_compliance``
adds u^T A0^T (I - t0 t0^T) A0 u c_root at the base, ``probe_pitch_deg`` turns
u, ``measured`` (rig) adds a series compliance 1/k_rig. This is the beam
reference's own linear stiffness (tests check it against the beam backend);
the nonlinear answer (gravity, large deflection, the fit window) is carried
by the baseline simulation: the predicted stiffness of a trial is

    1 / k_pred = (1 / k_base) C_cane(theta) / C_cane(0) + C_series(theta)

with k_base the baseline engine's stiffness of that trial. Anchored on an engine
run with effects theta_a (:meth:`~canebench.discovery.screenset.ScreenSet.anchored`),
k_base is that run's stiffness and the formula becomes
1 / k_pred = (1 / k_a - C_series(theta_a)) C_cane(theta) / C_cane(theta_a) + C_series(theta).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..model.chain import build_chain, probe_direction
from ..model.config import ModelConfig
from ..model.diameter import DiameterFit
from ..model.effects import AppliedEffects

MAX_SUB_M = 0.005
_XG, _WG = np.polynomial.legendre.leggauss(3)


def _cross_matrix(v: np.ndarray) -> np.ndarray:
    out = np.zeros(v.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


@dataclass
class TrialGeometry:
    """Quadrature of one trial's compliance integral (see module docstring)."""

    trial: str
    cane: str
    s: np.ndarray  # quadrature arc lengths (m)
    w: np.ndarray  # quadrature weights (m)
    d0: np.ndarray  # caliper-fit diameter at s (m), before effects and floor
    Mb: np.ndarray  # (g, 3, 3) bending kernel A^T (I - tt^T) A
    Mt: np.ndarray  # (g, 3, 3) torsion kernel A^T tt^T A
    M_root: np.ndarray  # (3, 3) base kernel
    modulus: float
    nu: float
    min_diameter: float
    azimuth: np.ndarray
    t_push: np.ndarray
    base_pitch_deg: float
    s_push: float
    height: float
    #: the cane's calipers: arc lengths (m); each reading's residual about the least-squares line
    #: through them (m, before the diameter factor, which scales the line and not the readings);
    #: and the model's line d0 there (factor applied). A diameter effect must not contradict them.
    cal_s: np.ndarray = field(default_factory=lambda: np.zeros(0))
    cal_resid: np.ndarray = field(default_factory=lambda: np.zeros(0))
    cal_line: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def direction(self, pitch_deg: float) -> np.ndarray:
        return probe_direction(self.azimuth, self.t_push, self.base_pitch_deg + pitch_deg)

    def compliance(self, fx: AppliedEffects | None = None) -> tuple[float, float]:
        """(cane compliance, series compliance) in m/N under the effects ``fx``."""
        E = self.modulus if fx is None else fx.modulus(self.modulus)
        d = self.d0 if fx is None else fx.diameter(self.s, self.d0)
        d = np.maximum(d, self.min_diameter)
        inv_ei = self.w / (E * np.pi * d**4 / 64.0)
        S = np.einsum("g,gij->ij", inv_ei, self.Mb + (1.0 + self.nu) * self.Mt)
        u = self.direction(fx.probe_pitch_deg() if fx is not None else 0.0)
        c_cane = float(u @ S @ u)
        series = 0.0
        if fx is not None:
            c_root = fx.root_compliance()
            if c_root:
                c_cane += float(u @ self.M_root @ u) * c_root
            # a series spring in the measurement: what 1 N of force adds to the recorded travel
            x, _ = fx.measured(np.array([0.0, 0.0]), np.array([0.0, 1.0]))
            series = float(x[1] - x[0])
        return c_cane, series


def trial_geometry(trial, config: ModelConfig) -> TrialGeometry:
    """The quadrature of ``trial`` under the baseline ``config`` (its effects excluded)."""
    cfg = config.replace(effects=())
    chain = build_chain(trial.cane, trial.push_id, cfg)
    rod = chain.rod
    s_p = float(chain.meta["s_push"])
    P = rod.points
    S = rod.s
    p = chain.push_point
    ss, ww, tt, rr = [], [], [], []
    for a in range(len(S) - 1):
        s0, s1 = S[a], min(S[a + 1], s_p)
        if s1 <= s0:
            break
        t = (P[a + 1] - P[a]) / (S[a + 1] - S[a])
        n = max(1, int(np.ceil((s1 - s0) / MAX_SUB_M)))
        edges = np.linspace(s0, s1, n + 1)
        h = np.diff(edges)
        mids = 0.5 * (edges[:-1] + edges[1:])
        sg = (mids[:, None] + 0.5 * h[:, None] * _XG[None, :]).ravel()
        wg = (0.5 * h[:, None] * _WG[None, :]).ravel()
        ss.append(sg)
        ww.append(wg)
        tt.append(np.tile(t, (len(sg), 1)))
        rr.append(P[a][None, :] + (sg - S[a])[:, None] * t[None, :])
    s = np.concatenate(ss)
    w = np.concatenate(ww)
    T = np.concatenate(tt)
    R = np.concatenate(rr)
    A = _cross_matrix(p[None, :] - R)  # m = A u
    TT = T[:, :, None] * T[:, None, :]
    Pperp = np.eye(3)[None] - TT
    Mb = np.einsum("gki,gkl,glj->gij", A, Pperp, A)
    Mt = np.einsum("gki,gkl,glj->gij", A, TT, A)
    t0 = (P[1] - P[0]) / np.linalg.norm(P[1] - P[0])
    A0 = _cross_matrix(p - P[0])
    M_root = A0.T @ (np.eye(3) - np.outer(t0, t0)) @ A0
    line = DiameterFit(**chain.meta["diameter_fit"])  # the model's line (diameter factor applied)
    pp = trial.cane.push_point(trial.push_id)
    t_push = np.array(chain.meta["probe_tangent"], float)  # the chain's own: one probe in both
    cal = chain.meta["calipers"]
    cal_s = np.array(cal["s"], float)
    resid = np.array(cal["diameter"], float) - replace(line, factor=1.0)(cal_s)  # about the unscaled fit
    return TrialGeometry(trial.id, trial.cane.id, s, w, line(s), Mb, Mt, M_root, rod.modulus, rod.poisson_ratio,
                         rod.min_diameter, np.array(pp.direction, float), t_push, cfg.probe_angle_deg, s_p,
                         float(p[2] - P[0][2]), cal_s, resid, line(cal_s))
