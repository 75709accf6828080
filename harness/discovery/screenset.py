"""All trials' screening quadratures in flat arrays: one numpy pass evaluates
every trial's compliance under one set of effect parameters (about a
millisecond for 54 trials), which is what fitting and cross-validation call.

The probe direction enters through u = cos(th) a + sin(th) e_z (a the
horizontal azimuth, th the pitch that makes u perpendicular to the cane at
the probe plus any extra pitch), so each quadrature point stores the three
coefficients of u^T K u in (cos th, sin th).

The screen is linear; the engines are not (gravity acting on a cane that
leans on a soft root, large deflection, the fit window). It is therefore
used relative to an anchor: a model the baseline engine has actually been
run with (:meth:`ScreenSet.anchored`). At the anchor the prediction is the
engine's answer exactly; away from it only the change in compliance is
linearized. The workflow re-anchors on the engine after every effect it
names, so a second effect is never asked to absorb the first one's
linearization error.

One nonlinearity the anchor cannot carry is the probe's pitch. A probe pitched
up pulls the cane along its axis as it pushes it sideways, and tension
stiffens a bending rod (pitched down, compression softens it): beside the
1/cos^2 the linear screen gives, the beam adds up to 0.07 in ln k at 30
degrees on the bundled canes and up to 0.3 at 40 degrees on thinner ones,
with a sign the screen's quadratic form in the pitch does not have. So the
workflow runs the baseline engine at a few pitches (:data:`PITCH_GRID_DEG`)
and the screen adds, per trial, the engine's excess over its own prediction
there, interpolated in the pitch (:meth:`ScreenSet.with_pitch_table`). The
table is measured on the baseline model and reused as it is when other
effects are in the model (re-anchoring on the engine corrects the model
held, not the candidates tried beside it).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..model.effects import AppliedEffects, EffectSpec
from .screen import TrialGeometry

EZ = np.array([0.0, 0.0, 1.0])
#: the anchor tag of a screen moved off its anchor's geometry (:meth:`ScreenSet.with_diameters`)
_OFF_ANCHOR = "off the anchor's geometry"
#: scatter of caliper readings about each cane's fitted line when no cane has more calipers than
#: the line has parameters (nothing to estimate it from): a few tenths of a millimetre, what bud
#: bumps and ovality give on a woody cane read with a digital caliper
CALIPER_SIGMA_DEFAULT_M = 0.25e-3
#: floor of the estimated scatter: readings rounded to 0.1 mm scatter by 0.03 mm from rounding alone
CALIPER_SIGMA_FLOOR_M = 0.05e-3
#: extra probe pitches (deg) at which the baseline engine is run to tabulate each trial's nonlinear
#: response to the pitch (0 is the baseline run itself); the probe_misalignment parameter's bounds
#: are +-45, so the interpolant extrapolates by at most 5 degrees
PITCH_GRID_DEG = (-40.0, -20.0, 0.0, 20.0, 40.0)


def caliper_sigma(geoms: list[TrialGeometry]) -> float:
    """Pooled scatter (m) of the caliper readings about each cane's fitted line (one estimate per dataset).

    Each cane's line has two parameters, so a cane with n readings at two or more places gives
    n - 2 degrees of freedom; with none anywhere, :data:`CALIPER_SIGMA_DEFAULT_M`. Readings, not
    the diameter factor's scaled line: the factor is a modelling choice, the scatter the calipers'.
    """
    ss, dof = 0.0, 0
    seen: set[str] = set()
    for g in geoms:
        if g.cane in seen or len(g.cal_s) == 0:
            continue
        seen.add(g.cane)
        n = len(g.cal_s)
        if n > 2 and len(np.unique(np.round(g.cal_s, 6))) >= 2:
            ss += float(np.sum(g.cal_resid**2))
            dof += n - 2
    return max(float(np.sqrt(ss / dof)), CALIPER_SIGMA_FLOOR_M) if dof else CALIPER_SIGMA_DEFAULT_M


def _quad_coeffs(K: np.ndarray, a: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(a^T K a, a^T K e + e^T K a, e^T K e) for K (..., 3, 3)."""
    kaa = np.einsum("i,...ij,j->...", a, K, a)
    kae = np.einsum("i,...ij,j->...", a, K, EZ) + np.einsum("i,...ij,j->...", EZ, K, a)
    kee = K[..., 2, 2]
    return kaa, kae, kee


@dataclass
class ScreenSet:
    trials: list[str]
    canes: np.ndarray  # (n,) cane id per trial
    idx: np.ndarray  # (g,) trial index of every quadrature point
    s: np.ndarray
    w: np.ndarray
    d0: np.ndarray
    kaa: np.ndarray
    kae: np.ndarray
    kee: np.ndarray
    raa: np.ndarray  # (n,) base kernel coefficients
    rae: np.ndarray
    ree: np.ndarray
    E: np.ndarray  # (n,) stated modulus
    th0: np.ndarray  # (n,) pitch (rad) of the perpendicular probe
    min_d: float
    c0: np.ndarray  # (n,) cane compliance at the anchor (no effects unless anchored)
    s0: float = 0.0  # series compliance (m/N) at the anchor
    anchor: tuple = ()  # the EffectSpecs the anchor's engine stiffness was computed with
    #: the calipers (:meth:`caliper_nll`): every trial carries its cane's calipers with weight
    #: 1 / (the cane's trial count), so a cane counts once in any subset or resample of whole canes
    cal_idx: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    cal_s: np.ndarray = field(default_factory=lambda: np.zeros(0))
    cal_line: np.ndarray = field(default_factory=lambda: np.zeros(0))  # the caliper-fit line there
    cal_w: np.ndarray = field(default_factory=lambda: np.zeros(0))
    cal_sigma: float = CALIPER_SIGMA_DEFAULT_M
    #: (n, len(PITCH_GRID_DEG)) coefficients (highest power first, pitch in rad) of each trial's
    #: engine-minus-screen ln k as a function of the extra probe pitch, zero at zero pitch; an
    #: empty array: no table (the screen alone)
    pitch_coef: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    #: the extra probe pitch (deg) of the anchor's model
    anchor_pitch_deg: float = 0.0
    #: (3, g) each quadrature point's w k_aa, w k_ae, w k_ee times 64/pi, and where each trial's points
    #: start (:meth:`_per_trial`); not init fields, so every ``replace`` starts without them
    _weights: tuple | None = field(default=None, init=False, repr=False, compare=False)
    #: (3, n) :meth:`_per_trial` on the caliper line's diameters, once per screen
    _sums: np.ndarray | None = field(default=None, init=False, repr=False, compare=False)

    @classmethod
    def build(cls, geoms: list[TrialGeometry]) -> "ScreenSet":
        parts = {k: [] for k in ("idx", "s", "w", "d0", "kaa", "kae", "kee")}
        raa, rae, ree, E, th0 = [], [], [], [], []
        for i, g in enumerate(geoms):
            a = g.azimuth / np.linalg.norm(g.azimuth)
            t = g.t_push
            th = np.arctan2(-(a @ t), t[2]) + np.deg2rad(g.base_pitch_deg)
            K = g.Mb + (1.0 + g.nu) * g.Mt
            kaa, kae, kee = _quad_coeffs(K, a)
            parts["idx"].append(np.full(len(g.s), i))
            for k, v in (("s", g.s), ("w", g.w), ("d0", g.d0), ("kaa", kaa), ("kae", kae), ("kee", kee)):
                parts[k].append(v)
            r = _quad_coeffs(g.M_root, a)
            raa.append(r[0]), rae.append(r[1]), ree.append(r[2])
            E.append(g.modulus), th0.append(th)
        arr = {k: np.concatenate(v) for k, v in parts.items()}
        out = cls([g.trial for g in geoms], np.array([g.cane for g in geoms]), arr["idx"], arr["s"], arr["w"],
                  arr["d0"], arr["kaa"], arr["kae"], arr["kee"], np.array(raa), np.array(rae), np.array(ree),
                  np.array(E), np.array(th0), min(g.min_diameter for g in geoms), np.zeros(len(geoms)))
        per_cane = {c: int(np.sum(out.canes == c)) for c in np.unique(out.canes)}
        out.cal_idx = np.concatenate([np.full(len(g.cal_s), i) for i, g in enumerate(geoms)]).astype(int)
        out.cal_s = np.concatenate([g.cal_s for g in geoms])
        out.cal_line = np.concatenate([g.cal_line for g in geoms])
        out.cal_w = np.concatenate([np.full(len(g.cal_s), 1.0 / per_cane[g.cane]) for g in geoms])
        out.cal_sigma = caliper_sigma(geoms)
        out.c0 = out.compliance(AppliedEffects([]))[0]
        return out

    def take(self, rows: np.ndarray, labels: np.ndarray | None = None) -> "ScreenSet":
        """The trials ``rows`` (indices, in that order, repeats allowed) as a screen of their own.

        ``labels``: their cane labels (default their own); a cane bootstrap gives a resampled
        cane's repeats a label of their own, so each repeat counts as a cane.
        """
        rows = np.asarray(rows, int)
        pts, idx = _gather(self.idx, rows)  # quadrature points
        cpts, cidx = _gather(self.cal_idx, rows)  # calipers
        return ScreenSet([self.trials[i] for i in rows], self.canes[rows] if labels is None else np.asarray(labels),
                         idx, self.s[pts], self.w[pts], self.d0[pts], self.kaa[pts], self.kae[pts], self.kee[pts],
                         self.raa[rows], self.rae[rows], self.ree[rows], self.E[rows], self.th0[rows], self.min_d,
                         self.c0[rows], self.s0, self.anchor, cidx, self.cal_s[cpts], self.cal_line[cpts],
                         self.cal_w[cpts], self.cal_sigma, self.pitch_rows(rows), self.anchor_pitch_deg)

    def subset(self, keep: np.ndarray) -> "ScreenSet":
        """The trials where the mask ``keep`` is true, in their order."""
        return self.take(np.flatnonzero(np.asarray(keep, bool)))

    def pitch_rows(self, rows: np.ndarray) -> np.ndarray:
        """The pitch table's rows of the trials ``rows`` (a mask or indices; empty without a table)."""
        return self.pitch_coef[rows] if self.pitch_coef.size else self.pitch_coef

    def anchored(self, specs: tuple[EffectSpec, ...]) -> "ScreenSet":
        """The same trials, with predictions relative to an engine run of the model ``specs``."""
        from dataclasses import replace

        fx = AppliedEffects([s.instance() for s in specs])
        cc, series = self.compliance(fx)
        return replace(self, c0=cc, s0=series, anchor=tuple(specs), anchor_pitch_deg=fx.probe_pitch_deg())

    def with_pitch_table(self, table: np.ndarray) -> "ScreenSet":
        """The same screen with each trial's engine excess at the pitches :data:`PITCH_GRID_DEG`.

        ``table[i, j]``: the engine's ln k of trial i with the probe pitched by an extra
        ``PITCH_GRID_DEG[j]`` minus this screen's prediction of it from the baseline (0 at 0).
        It is interpolated by the polynomial through the grid's points (smooth, so the fit's
        optimizer sees no kinks). A trial the engine failed on at any pitch gets no correction.
        """
        from dataclasses import replace

        table = np.asarray(table, float)
        x = np.deg2rad(np.asarray(PITCH_GRID_DEG))
        coef = np.linalg.solve(np.vander(x, len(x)), np.nan_to_num(table, nan=0.0).T).T
        coef[~np.all(np.isfinite(table), axis=1)] = 0.0
        return replace(self, pitch_coef=coef)

    def pitch_excess(self, pitch_deg: float) -> np.ndarray | float:
        """Each trial's tabulated engine-minus-screen ln k at an extra probe pitch (0 without a table)."""
        if not self.pitch_coef.size:
            return 0.0
        x = np.deg2rad(pitch_deg)
        return self.pitch_coef @ (x ** np.arange(self.pitch_coef.shape[1] - 1, -1, -1))

    def with_diameters(self, d0: np.ndarray) -> "ScreenSet":
        """The same trials on other caliper-fit diameters ``d0`` (one per quadrature point).

        Still relative to this anchor's engine stiffness and compliance, but no longer *at* the
        anchor: :meth:`Anchored.predict` must recompute even for the anchor's own effects (which it
        otherwise returns unchanged), so the anchor tag is replaced by one no model matches.
        """
        from dataclasses import replace

        return replace(self, d0=np.asarray(d0, float), anchor=(_OFF_ANCHOR,))

    def caliper_nll(self, fx: AppliedEffects) -> float:
        """Penalty (in -log likelihood units) for what the diameter effects in ``fx`` change at the calipers.

        A diameter effect (a base flare) may change the cane where the calipers measured it only
        as far as their scatter about the fitted line allows. Its change f = d_fx - d_line at each
        caliper is scored as 0.5 (f / :attr:`cal_sigma`)^2: the Gaussian misfit it adds to the
        readings with the line held fixed, to first order (the cross term with each reading's own
        residual, -e f / sigma^2, is left out: with three calipers e is one curvature contrast, and
        on the real and bundled data it is under 2 % of the term for the flares fitted). Without a
        diameter effect the penalty is 0.
        """
        if not fx.changes_diameter or len(self.cal_s) == 0:
            return 0.0
        return float(0.5 * np.sum(self.cal_w * (self.caliper_change(fx) / self.cal_sigma) ** 2))

    def caliper_change(self, fx: AppliedEffects) -> np.ndarray:
        """What the effects ``fx`` change the diameter by (m) at every caliper of every trial."""
        return fx.diameter(self.cal_s, self.cal_line) - self.cal_line

    def _per_trial(self, d: np.ndarray) -> np.ndarray:
        """(3, n): each trial's sums over its quadrature points of w k_aa / I, w k_ae / I and w k_ee / I
        at the diameters ``d`` (one per point; I = pi d^4 / 64)."""
        n = len(self.trials)
        if n == 0:
            return np.zeros((3, 0))
        if self._weights is None:
            W = np.stack([self.w * self.kaa, self.w * self.kae, self.w * self.kee]) * (64.0 / np.pi)
            counts = np.bincount(self.idx, minlength=n)
            # every trial's points in one run, in trial order (as build and take lay them out): a
            # segmented sum; otherwise a bincount per row
            runs = bool(np.all(counts > 0)) and np.array_equal(self.idx, np.repeat(np.arange(n), counts))
            self._weights = (W, np.concatenate([[0], np.cumsum(counts)[:-1]]) if runs else None)
        W, starts = self._weights
        d2 = d * d
        X = W / (d2 * d2)
        if starts is None:
            return np.stack([np.bincount(self.idx, x, minlength=n) for x in X])
        return np.add.reduceat(X, starts, axis=1)

    def compliance(self, fx: AppliedEffects) -> tuple[np.ndarray, np.ndarray]:
        """(cane compliance (n,), series compliance (scalar)) under ``fx`` (global values).

        The probe's pitch enters each trial's kernel only through (cos th, sin th), so the cane's
        compliance is three sums per trial (:meth:`_per_trial`) in those. A model that leaves the
        diameter alone takes the caliper line's sums, computed once per screen: the fits call this
        tens of thousands of times, and a pass over every quadrature point (about 700 a trial) was
        most of a discovery run's time. An effect on the diameter takes that pass."""
        E = np.asarray(fx.modulus(self.E), float)
        th = self.th0 + np.deg2rad(fx.probe_pitch_deg())
        c, sn = np.cos(th), np.sin(th)
        if fx.changes_diameter:
            A = self._per_trial(np.maximum(fx.diameter(self.s, self.d0), self.min_d))
        else:
            if self._sums is None:
                self._sums = self._per_trial(np.maximum(self.d0, self.min_d))
            A = self._sums
        cc = (A[0] * c**2 + A[1] * (c * sn) + A[2] * sn**2) / E
        c_root = fx.root_compliance()
        if c_root:
            cc = cc + (self.raa * c**2 + self.rae * c * sn + self.ree * sn**2) * c_root
        x, _ = fx.measured(np.array([0.0, 0.0]), np.array([0.0, 1.0]))
        return cc, float(x[1] - x[0])


M_PER_N_TO_MM_PER_N = 1e3


@dataclass(frozen=True, eq=False)  # eq=False: == on ndarray fields would not give a bool
class Anchored:
    """A linear screen and the baseline engine's ln k it is anchored at, in the scored trials'
    order: what every fit predicts from, and what moves together when the screen is re-anchored
    (:func:`.engine_runs.reanchor`)."""

    screen: ScreenSet
    log_k: np.ndarray

    def predict(self, specs: tuple[EffectSpec, ...]) -> np.ndarray:
        """ln k_pred per trial (k in N/mm) under the effects ``specs``.

        ``log_k`` is the engine's stiffness at the screen's anchor (``screen.anchor``, no
        effects unless :meth:`ScreenSet.anchored`): the cane part of its compliance is scaled
        by the screened change and the series (rig) part replaced. At the anchor itself the
        anchor's ln k is returned as it is.
        """
        ss = self.screen
        if tuple(specs) == tuple(ss.anchor):
            return self.log_k
        fx = AppliedEffects([s.instance() for s in specs])
        cc, series = ss.compliance(fx)
        # stiffness is in N/mm throughout the harness; the series compliance comes in m/N
        cane = np.exp(-self.log_k) - ss.s0 * M_PER_N_TO_MM_PER_N
        # the pitch's nonlinearity (tension or compression along the cane) acts on the cane, not the rig
        excess = ss.pitch_excess(fx.probe_pitch_deg()) - ss.pitch_excess(ss.anchor_pitch_deg)
        inv = cane * (cc / ss.c0) * np.exp(-excess) + series * M_PER_N_TO_MM_PER_N
        with np.errstate(divide="ignore", invalid="ignore"):
            return -np.log(inv)

    def subset(self, keep: np.ndarray) -> "Anchored":
        """The trials where the mask ``keep`` is true (:meth:`ScreenSet.subset`), in their order."""
        keep = np.asarray(keep, bool)
        if keep.shape != self.log_k.shape:
            raise ValueError(f"a mask of {keep.shape} for {self.log_k.shape} trials")
        return self.take(np.flatnonzero(keep))

    def take(self, rows: np.ndarray, labels: np.ndarray | None = None) -> "Anchored":
        """The trials at ``rows`` (repeats allowed, as a bootstrap draws them), their canes
        relabelled ``labels`` if given, else keeping their own (:meth:`ScreenSet.take`)."""
        rows = np.asarray(rows, int)
        return Anchored(self.screen.take(rows, labels), self.log_k[rows])

    def with_diameters(self, d0: np.ndarray) -> "Anchored":
        """The same trials and anchor with the caliper line's diameters ``d0`` at the screen's
        points (:meth:`ScreenSet.with_diameters`)."""
        return Anchored(self.screen.with_diameters(d0), self.log_k)


def _gather(owner: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Positions of the points owned by each trial in ``rows`` (repeats allowed), and their new owners."""
    parts = [np.flatnonzero(owner == i) for i in rows]
    if not parts:
        return np.zeros(0, int), np.zeros(0, int)
    return (np.concatenate(parts).astype(int),
            np.concatenate([np.full(len(p), k, dtype=int) for k, p in enumerate(parts)]))
