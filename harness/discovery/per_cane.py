"""Per-cane scope: does a named effect's parameter differ from cane to cane?

Some effects are each cane's own: a root's stiffness is its plant's and its soil's, a collar
its cane's. The selection fits every effect globally (one value for all canes, each cane's
own level beside it as a random effect). Here each named effect whose class allows the
``per_cane`` scope (:attr:`~canebench.model.effects.Effect.scopes`) is asked whether its
parameter varies between canes beyond what the data's noise makes it seem to.

Free values per cane would cost a parameter each (18 on 54 trials, three pushes a cane); the
count is penalized instead by a hierarchical model with one extra parameter: the cane's value
v_c = exp(mu + omega z_c), z_c ~ N(0, 1), integrated out of each cane's likelihood by
adaptive Gauss-Hermite quadrature. On cane c (trials i):

    ln k_field_i - P_i(v_c) ~ N(0, sigma^2 I + tau^2 11^T + G_c)

P is the screen's prediction (:meth:`.screenset.Anchored.predict`) with the other named effects
at their fitted values, tau^2 the cane's own level (its modulus), and G_c the covariance, over the
cane's pushes, of the model's ln k when the cane's caliper line is off by its own error
(:func:`.adequacy.geometry_draws`): a line whose slope is off moves a cane's low and high pushes
apart, as a root or a collar of its own would, and that must not pass for one. For an effect on
the diameter, the calipers' penalty (:meth:`.screenset.ScreenSet.caliper_nll`) of the cane's
value is part of the cane's likelihood. P and that penalty are tabulated once over a grid of
ln v, with cubic splines between its points and straight lines beyond its ends.

omega = 0 (the global fit) is tested against omega > 0 by the likelihood ratio; omega = 0 lies
on the boundary, so p = P(chi^2_1 > LR) / 2. The scope is ``per_cane`` when p < alpha (split over
the effects tested) and the canes' own values move the model by at least ``min_change`` in mean
|ln k| (the selection's materiality) from the population's median. Each cane's value is its
posterior mean of ln v under the fitted hierarchy (shrunk toward the median where its pushes say
little). A cane outside the data takes the global fit's value, the one the engines confirm and the
interval and the out-of-sample gap are of.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from scipy import stats
from scipy.interpolate import CubicSpline
from scipy.optimize import minimize
from scipy.special import logsumexp

from ..errors import InputError
from ..model.effects import COV_LN_MAX, EFFECTS, AppliedEffects, EffectSpec, Parameter, Spread, check_cov_ln
from .adequacy import geometry_draws
from .fit import SIGMA_FLOOR
from .screenset import Anchored

#: adaptive Gauss-Hermite nodes over each cane's value (about the mode of its integrand, scaled by
#: its curvature; exact where the prediction is linear in ln v)
N_NODES = 16
#: points of the ln v grid the predictions are tabulated on (cubic splines between them)
N_GRID = 321
#: the grid spans the fitted value times exp(+-GRID_HALF_WIDTH): a spread of omega = 2 (a factor 7
#: per sd) reaches 2.5 sd at the ends; beyond them the tables go on straight at the ends' slopes
GRID_HALF_WIDTH = 5.0
#: draws of the caliper lines' error for G_c
N_GEOMETRY_DRAWS = 400
LOG_FLOOR = -30.0
#: family-wise level of the per-cane tests (split over the effects tested). Stricter than a selection
#: step's 0.05: a per-cane scope adds a value for every cane, and the hierarchy's null is checked only
#: on data drawn from the screen itself (``tests/scripts/per_cane_calibration.py``), where the caliper
#: line is the taper; on the self-test's rod two sets whose effect is global gave 0.023 and 0.036
#: (docs/discovery.md, session 60)
PER_CANE_ALPHA = 0.01

#: a 2 x 2 covariance of (ln median, ln omega)
Cov2 = tuple[tuple[float, float], tuple[float, float]]


@dataclass
class PerCaneTest:
    """The per-cane test of one named effect (:func:`per_cane_test`).

    Attributes
    ----------
    effect, parameter, unit
        The effect, the parameter that varies per cane, its unit.
    median
        exp(mu): the population's median under the hierarchy.
    ln_sd
        omega: the sd of ln v between canes (0 when the fit puts it there).
    lr, p, alpha
        Likelihood ratio (omega > 0 against 0), its boundary p, and the level it was judged at.
    spread
        Mean over the trials of |ln k| moved by the canes' own values from the median's.
    per_cane
        Whether the scope is per cane (``p < alpha`` and ``spread >= min_change``).
    values, ln_sd_each
        Each cane's value (exp of its posterior mean of ln v) and the posterior sd of its ln v.
    reason
        Why it is (or is not) per cane, in words.
    cov_ln
        Sampling covariance of (ln median, ln omega): the hierarchy's observed information's
        (``cov_ln_model``, :func:`sampling_cov`) with each standard error widened to the one clustered
        by plant (``cov_ln_plants``, :func:`clustered_cov`) where that is larger (:func:`wider_of`).
        None where omega is 0 or the information is not positive definite.
    cov_ln_model, cov_ln_plants, n_plants
        The two covariances it is made of (the clustered one None without plants, with fewer than
        :data:`MIN_PLANTS`, or where it cannot be had) and the number of plants.
    spread_lost_without
        The plants without whose canes the jackknife's refit finds no spread
        (:attr:`PlantJackknife.lost_without`): ln omega's error is then unbounded.
    """

    effect: str
    parameter: str
    unit: str
    median: float
    ln_sd: float
    lr: float
    p: float
    alpha: float
    spread: float
    per_cane: bool
    values: dict[str, float] = field(default_factory=dict)
    ln_sd_each: dict[str, float] = field(default_factory=dict)
    reason: str = ""
    cov_ln: Cov2 | None = None
    cov_ln_model: Cov2 | None = None
    cov_ln_plants: Cov2 | None = None
    n_plants: int | None = None
    spread_lost_without: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        return {"parameter": self.parameter, "unit": self.unit, "per_cane": self.per_cane,
                "median": self.median, "ln_sd_between_canes": self.ln_sd, "lr": self.lr, "p": self.p,
                "alpha": self.alpha, "spread_mean_abs_ln_k": self.spread, "reason": self.reason,
                "cov_ln_median_ln_sd": _listed(self.cov_ln), "cov_ln_information": _listed(self.cov_ln_model),
                "cov_ln_clustered_by_plant": _listed(self.cov_ln_plants), "n_plants": self.n_plants,
                "spread_lost_without_plants": list(self.spread_lost_without),
                "values": dict(self.values), "ln_sd_each": dict(self.ln_sd_each)}

    def to_df(self) -> "Any":
        import pandas as pd

        return pd.DataFrame({"cane": list(self.values), "effect": self.effect, "parameter": self.parameter,
                             "value": list(self.values.values()),
                             "ln_sd": [self.ln_sd_each[c] for c in self.values]})

    def spec(self, named: EffectSpec) -> EffectSpec:
        """``named`` with the scope this test found: per cane, each cane's own value as ``local``
        beside the global fit's value, which a cane the data do not have takes (the value the
        engines confirm, whose interval is drawn and whose gap is measured out of sample), and the
        hierarchy's median and spread, with their sampling covariance, as ``between`` (what a
        population export draws a new cane's value from); else ``named`` unchanged."""
        if not self.per_cane:
            return named
        local = tuple(sorted((c, ((self.parameter, v),)) for c, v in self.values.items()))
        return EffectSpec(named.name, named.params, local, "per_cane",
                          ((self.parameter, Spread(self.median, self.ln_sd, self.drawable_cov())),))

    def drawable_cov(self) -> Cov2 | None:
        """``cov_ln`` as a population draws within it: each variance beyond
        :data:`~canebench.model.effects.COV_LN_MAX` cut to it, the correlation kept (beyond it a draw's
        spread can reach hundreds and overflow; discovery's note says where it was cut). A spread known
        worse is drawn within the most a population allows, never as if exact. None without ``cov_ln``
        or where it is not a covariance the model file's loader takes."""
        if self.cov_ln is None:
            return None
        V = np.array(self.cov_ln, float)
        cap = np.array(COV_LN_MAX, float)
        with np.errstate(divide="ignore", invalid="ignore"):
            cut = np.where(np.diag(V) > cap, np.sqrt(cap / np.diag(V)), 1.0)
        V = V * np.outer(cut, cut)
        for i in range(2):
            if cut[i] < 1.0:
                V[i, i] = cap[i]  # exactly the bound (the product can round past it)
        try:  # the model file's own rule, so that discovery never writes a file its loader refuses
            return check_cov_ln(_block(V), "per-cane test", "cov_ln")
        except InputError:
            return None


def _listed(cov: Cov2 | None) -> list[list[float]] | None:
    return None if cov is None else [list(r) for r in cov]


def varying_parameter(name: str) -> str | None:
    """The parameter of effect ``name`` that discovery tests per cane: its
    :meth:`~canebench.model.effects.Effect.per_cane_parameter`, unless the effect is the cane's level
    itself (a modulus scale per cane is the random level every fit already has); None otherwise."""
    return None if name == "modulus_scale" else EFFECTS[name].per_cane_parameter()


class _Hierarchy:
    """The hierarchical likelihood of one effect's per-cane parameter (see the module docstring).

    Each cane's value is integrated out by adaptive Gauss-Hermite quadrature: the nodes sit about
    the mode of the cane's integrand (prior times likelihood, found by Gauss-Newton) and scale with
    its curvature, so a cane whose pushes pin its value to 0.01 in ln v is integrated as well as one
    they say little about (fixed nodes spaced by a share of omega missed the first by tens of nats).
    Where the prediction is linear in ln v the integrand is Gaussian and the quadrature exact.

    Parameters
    ----------
    grid : (g,) array
        Increasing grid of ln v the tables are given on (cubic splines between its points; the
        ends' values beyond it).
    P : (g, n) array
        Each trial's predicted ln k at each grid value.
    pen : (g, canes) array
        Each cane's calipers' penalty at each grid value (zeros for an effect off the diameter).
    y : (n,) array
        The field's ln k.
    canes : (n,) array
        Each trial's cane (``pen``'s columns follow their sorted unique values).
    G : (n, n) array
        The caliper lines' error covariance (only each cane's own block is used).
    """

    def __init__(self, grid: np.ndarray, P: np.ndarray, pen: np.ndarray, y: np.ndarray, canes: np.ndarray,
                 G: np.ndarray):
        # the tables as given, for :meth:`without` (the grid and y are kept below)
        self._tables = (np.asarray(P, float), np.asarray(pen, float), np.asarray(canes), np.asarray(G, float))
        self.grid = np.asarray(grid, float)
        self.Ps = CubicSpline(self.grid, np.asarray(P, float), axis=0)
        self.dPs = self.Ps.derivative()
        self.pens = CubicSpline(self.grid, np.asarray(pen, float), axis=0)
        self.dpens, self.d2pens = self.pens.derivative(), self.pens.derivative(2)
        self.y = np.asarray(y, float)
        self.uniq, self.inv = np.unique(canes, return_inverse=True)
        # canes batched by their number of trials: one stacked Cholesky per size, not one per cane
        self.batches = []
        for size in np.unique(np.bincount(self.inv)):
            ks = np.array([k for k in range(len(self.uniq)) if np.sum(self.inv == k) == size])
            rows = np.array([np.flatnonzero(self.inv == k) for k in ks])  # (m, size)
            self.batches.append((ks, rows, G[rows[:, :, None], rows[:, None, :]]))
        self.x, self.w = np.polynomial.hermite.hermgauss(N_NODES)
        self._mode: np.ndarray | None = None  # the last modes: the next evaluation's start

    def without(self, drop: np.ndarray) -> "_Hierarchy":
        """The hierarchy of the canes not in ``drop`` ((canes,) bool, in the order of ``uniq``)."""
        P, pen, canes, G = self._tables
        drop = np.asarray(drop, bool)
        keep = ~drop[self.inv]
        return _Hierarchy(self.grid, P[:, keep], pen[:, ~drop], self.y[keep], canes[keep], G[np.ix_(keep, keep)])

    def _at(self, spline: CubicSpline, slope: CubicSpline, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """A table's values and slopes at ``u``; beyond the grid's ends it goes on straight, with the
        end's slope (smooth at the ends, so a cane whose value lies past them is integrated as well)."""
        uc = np.clip(u, self.grid[0], self.grid[-1])
        d = slope(uc)
        return spline(uc) + d * (u - uc)[:, None], d

    def predict_at(self, u: np.ndarray) -> np.ndarray:
        """Each trial's prediction at its cane's value ``u`` ((canes,) ln v)."""
        return self._at(self.Ps, self.dPs, np.asarray(u, float))[0][self.inv, np.arange(len(self.inv))]

    def _cov(self, s2: float, t2: float) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] | None:
        """Per batch: canes, rows, inverse covariance and log determinant (None: not positive definite)."""
        out = []
        for ks, rows, G in self.batches:
            n = rows.shape[1]
            S = s2 * np.eye(n) + t2 + G
            try:
                L = np.linalg.cholesky(S)
            except np.linalg.LinAlgError:
                return None
            Linv = np.linalg.inv(L)
            out.append((ks, rows, np.einsum("mki,mkj->mij", Linv, Linv),
                        2.0 * np.sum(np.log(np.diagonal(L, axis1=1, axis2=2)), axis=1)))
        return out

    def _loglik(self, U: np.ndarray, cov: list) -> np.ndarray:
        """(k, canes) log density of each cane's data and calipers at the values ``U`` (k, canes)."""
        k, C = U.shape
        u = U.ravel()
        Pall = self._at(self.Ps, self.dPs, u)[0].reshape(k, C, -1)  # (k, canes, trials)
        pen = self._at(self.pens, self.dpens, u)[0].reshape(k, C, C)[:, np.arange(C), np.arange(C)]
        out = -pen
        for ks, rows, Sinv, logdet in cov:
            n = rows.shape[1]
            r = self.y[rows][None] - Pall[:, ks[:, None], rows]  # (k, m, n)
            quad = np.einsum("kmi,mij,kmj->km", r, Sinv, r)
            out[:, ks] -= 0.5 * (quad + logdet[None] + n * math.log(2 * math.pi))
        return out

    def _grad_hess(self, u: np.ndarray, mu: float, omega: float, cov: list) -> tuple[np.ndarray, np.ndarray]:
        """Gradient and Gauss-Newton curvature of each cane's -log(prior x likelihood) at ``u``."""
        ar = np.arange(len(u))
        Pall, dP = self._at(self.Ps, self.dPs, u)
        _, dpen = self._at(self.pens, self.dpens, u)
        inside = (u >= self.grid[0]) & (u <= self.grid[-1])  # straight beyond the ends: no curvature
        grad = (u - mu) / omega**2 + dpen[ar, ar]
        hess = 1.0 / omega**2 + np.where(inside, np.maximum(self.d2pens(np.clip(u, self.grid[0],
                                                                               self.grid[-1]))[ar, ar], 0.0), 0.0)
        for ks, rows, Sinv, _ in cov:
            r = self.y[rows] - Pall[ks[:, None], rows]  # (m, n)
            J = dP[ks[:, None], rows]
            grad[ks] -= np.einsum("mi,mij,mj->m", J, Sinv, r)
            hess[ks] += np.einsum("mi,mij,mj->m", J, Sinv, J)
        return grad, hess

    def _modes(self, mu: float, omega: float, cov: list) -> tuple[np.ndarray, np.ndarray]:
        """Each cane's mode of prior times likelihood in ln v (Gauss-Newton) and its curvature there.

        The modes start from the last evaluation's when it converged (the optimizer moves the
        parameters little between evaluations), else from mu; an unconverged answer is not kept."""
        C = len(self.uniq)
        u = np.full(C, mu) if self._mode is None or len(self._mode) != C else self._mode.copy()
        converged = False
        for _ in range(60):
            grad, hess = self._grad_hess(u, mu, omega, cov)
            step = np.clip(grad / hess, -1.0, 1.0)
            u = u - step
            if np.max(np.abs(step)) < 1e-10:
                converged = True
                break
        _, hess = self._grad_hess(u, mu, omega, cov)
        self._mode = u if converged else None
        return u, hess

    def cane_loglik(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Each cane's log marginal likelihood, and its posterior mean and sd of ln v."""
        mu, log_omega, log_s2, log_t2 = (float(t) for t in theta)
        C = len(self.uniq)
        if not math.isfinite(mu):
            return np.full(C, -np.inf), np.full(C, np.nan), np.full(C, np.nan)
        omega = math.exp(min(log_omega, 5.0)) if log_omega > LOG_FLOOR else 0.0
        s2 = max(math.exp(min(log_s2, 50.0)), SIGMA_FLOOR**2)
        t2 = math.exp(min(log_t2, 50.0)) if log_t2 > LOG_FLOOR else 0.0
        cov = self._cov(s2, t2)
        if cov is None:
            return np.full(C, -np.inf), np.full(C, np.nan), np.full(C, np.nan)
        if omega == 0.0:  # one value for all canes: nothing to integrate
            return self._loglik(np.full((1, C), mu), cov)[0], np.full(C, mu), np.zeros(C)
        mode, hess = self._modes(mu, omega, cov)
        sig = 1.0 / np.sqrt(hess)
        U = mode[None, :] + math.sqrt(2.0) * sig[None, :] * self.x[:, None]  # (k, canes)
        logprior = -0.5 * ((U - mu) / omega) ** 2 - math.log(omega * math.sqrt(2 * math.pi))
        a = (np.log(self.w) + self.x**2)[:, None] + logprior + self._loglik(U, cov)
        ll = logsumexp(a, axis=0) + np.log(math.sqrt(2.0) * sig)
        wts = np.exp(a - logsumexp(a, axis=0))
        m = np.sum(wts * U, axis=0)
        sd = np.sqrt(np.maximum(np.sum(wts * U**2, axis=0) - m**2, 0.0))
        return ll, m, sd

    def nll(self, theta: np.ndarray) -> float:
        v = -float(np.sum(self.cane_loglik(theta)[0]))
        return v if math.isfinite(v) else 1e12

    def posterior(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Each cane's posterior mean and sd of ln v."""
        _, m, sd = self.cane_loglik(theta)
        return m, sd


#: relative step (in each of mu, ln omega, ln s2, ln t2) of the observed information's central differences
HESSIAN_STEP = 1e-2
#: fewest plants a clustered error is taken from: the jackknife's spread is over the plants, and with
#: fewer it is too noisy to widen anything by
MIN_PLANTS = 4


def _information(h: _Hierarchy, theta: np.ndarray, step: float) -> np.ndarray | None:
    """The observed information over the free parameters at ``theta``: central differences of
    :meth:`_Hierarchy.nll` over mu, ln omega and those of ln s2, ln t2 that are free. None where omega
    is 0 or a density on the stencil is not finite. A variance within a step of its floor (s2 at
    :data:`SIGMA_FLOOR`, t2 at 0), where the likelihood is flat on one side, is held there."""
    theta = np.asarray(theta, float)
    if not (np.all(np.isfinite(theta[:2])) and theta[1] > LOG_FLOOR):
        return None
    floors = {2: 2.0 * math.log(SIGMA_FLOOR), 3: LOG_FLOOR}
    free = [0, 1] + [i for i in (2, 3) if math.isfinite(theta[i]) and theta[i] - step > floors[i]]
    memo: dict[tuple[tuple[int, int], ...], float] = {}

    def f(*moves: tuple[int, int]) -> float:
        """-ln L with the parameters moved by a step each."""
        key = tuple(sorted(moves))
        if key not in memo:
            t = theta.copy()
            for i, sgn in moves:
                t[i] += sgn * step
            memo[key] = -float(np.sum(h.cane_loglik(t)[0]))
        return memo[key]

    f0 = f()
    H = np.empty((len(free), len(free)))
    for a, i in enumerate(free):
        H[a, a] = (f((i, 1)) - 2.0 * f0 + f((i, -1))) / step**2
        for b in range(a):
            j = free[b]
            H[a, b] = H[b, a] = (f((i, 1), (j, 1)) - f((i, 1), (j, -1)) - f((i, -1), (j, 1))
                                 + f((i, -1), (j, -1))) / (4.0 * step**2)
    if not all(math.isfinite(v) for v in memo.values()):
        return None
    return H


def sampling_cov(h: _Hierarchy, theta: np.ndarray, step: float = HESSIAN_STEP) -> Cov2 | None:
    """The sampling covariance of (mu, ln omega) at the maximum-likelihood ``theta``: the
    (mu, ln omega) block of the inverse observed information (:func:`_information`: over mu, ln omega
    and the variances ln s2, ln t2, which it is correlated with: a cane's own level and its own value
    move its pushes alike).

    None where omega is 0 or the information is not positive definite: a spread the data do not pin
    apart from the canes' own levels has no standard error to give, and holding a variance to get one
    would give the error as if that variance were known."""
    H = _information(h, theta, step)
    if H is None or not _positive_definite(H):
        return None
    return _block(np.linalg.inv(H))


#: Nelder-Mead's settings for a fit with omega free
FREE_FIT_OPTIONS = {"xatol": 1e-3, "fatol": 1e-4, "maxiter": 4000, "maxfev": 4000}
#: a leave-one-plant-out refit whose spread lowers -ln L by less than this from omega = 0 (its other
#: parameters held) has found none: the likelihood is flat in ln omega below about -8, and where
#: Nelder-Mead stops there (ln omega -11 to -13, moving with the start) says nothing
NO_SPREAD_NLL = 1e-3


@dataclass(frozen=True)
class PlantJackknife:
    """:func:`jackknife_over_plants`'s answer.

    Attributes
    ----------
    cov
        The covariance of (mu, ln omega) (:func:`clustered_cov`), None where it cannot be had.
    lost_without
        The plants without whose canes the refit finds no spread (omega at 0): ln omega's error is then
        unbounded, and ``cov`` holds the most a population draws within
        (:data:`~canebench.model.effects.COV_LN_MAX`) in its place, uncorrelated with mu.
    """

    cov: Cov2 | None
    lost_without: tuple[str, ...] = ()


def jackknife_over_plants(h: _Hierarchy, theta: np.ndarray, plants: np.ndarray) -> PlantJackknife:
    """The sampling covariance of (mu, ln omega) with the canes of a plant not taken as independent:
    the jackknife over plants. Each plant's canes are left out in turn and the hierarchy refitted
    (from ``theta``); over the G estimates e_g of (mu, ln omega) the covariance is
    (G - 1) / G sum_g (e_g - mean e)(e_g - mean e)^T, scaled by (t_{G-1, 0.975} / z_0.975)^2.

    The hierarchy draws each cane's value on its own; where the canes of a plant share theirs (a root
    is its crown's and its soil's as much as its cane's) it has fewer independent values than canes,
    and the information's error is too small by about the square root of the canes a plant. The
    jackknife holds either way. It replaced session 64's sandwich (the plants' summed scores about the
    information), whose error of ln omega, a variance's, ran low: on 200 datasets of 6 and 12 plants of
    3 canes sharing their values the sandwich covered ln omega 83-85.5 %, the jackknife 90-93 %
    (docs/discovery.md, session 65). A Wald interval from G plants has G - 1 degrees of freedom, hence
    the t scaling (1.72 in variance at six plants).

    Where leaving out a plant's canes leaves no spread (the refit's omega does not beat omega = 0 by
    :data:`NO_SPREAD_NLL`), the spread rests on that plant and ln omega's error has no bound: the
    plant is named in ``lost_without``, and ln omega's variance is the most a population draws within
    (:data:`~canebench.model.effects.COV_LN_MAX`), uncorrelated with mu, whose jackknife stands.

    ``cov`` is None with fewer than :data:`MIN_PLANTS` plants, at omega = 0 or a ``theta`` that is not
    finite, or where a refit fails (Nelder-Mead out of evaluations, or no finite likelihood).

    Parameters
    ----------
    plants : (canes,) array
        Each cane's plant, in the order of the hierarchy's canes (``h.uniq``).
    """
    plants = np.asarray(plants)
    if len(plants) != len(h.uniq):
        raise ValueError(f"{len(plants)} plants given for {len(h.uniq)} canes")
    groups, g_inv = np.unique(plants, return_inverse=True)
    theta = np.asarray(theta, float)
    if len(groups) < MIN_PLANTS or not (np.all(np.isfinite(theta)) and theta[1] > LOG_FLOOR):
        return PlantJackknife(None)
    est, lost = [], []
    for k, g in enumerate(groups):
        sub = h.without(g_inv == k)
        res = minimize(sub.nll, theta, method="Nelder-Mead", options=FREE_FIT_OPTIONS)
        if not (res.success and res.fun < 1e12):  # nll is 1e12 where the likelihood is not finite
            return PlantJackknife(None)
        x = res.x
        if sub.nll(np.array([x[0], -np.inf, x[2], x[3]])) - res.fun < NO_SPREAD_NLL:
            lost.append(str(g))
        est.append(x[:2])
    G = len(groups)
    e = np.array(est) - np.mean(est, axis=0)
    # a Wald interval from G plants has G - 1 degrees of freedom: scaled by (t_{G-1} / z)^2, the
    # normal interval this covariance gives (and the spread a population draws) is the t interval's
    small_g = (stats.t.ppf(0.975, G - 1) / stats.norm.ppf(0.975)) ** 2
    V = small_g * (G - 1) / G * e.T @ e
    if lost:
        V[0, 1] = V[1, 0] = 0.0
        V[1, 1] = COV_LN_MAX[1]
    return PlantJackknife(_block(V), tuple(lost))


def clustered_cov(h: _Hierarchy, theta: np.ndarray, plants: np.ndarray) -> Cov2 | None:
    """:func:`jackknife_over_plants`'s covariance alone."""
    return jackknife_over_plants(h, theta, plants).cov


def wider_of(model: Cov2 | None, clustered: Cov2 | None) -> Cov2 | None:
    """``model`` with each standard error widened to the clustered one's where that is larger (its
    correlation kept, so it stays positive semi-definite). The information's error holds where the canes
    are independent and the jackknife is noisy at a few plants; where they share their values the
    jackknife is the one that is right, and the larger of the two errors is the one a reader can trust
    either way (docs/discovery.md, sessions 64 and 65)."""
    if model is None or clustered is None:
        return model
    V = np.array(model)
    ratio = np.sqrt(np.maximum(np.diag(np.array(clustered)) / np.diag(V), 1.0))
    return _block(V * np.outer(ratio, ratio))


def _positive_definite(H: np.ndarray) -> bool:
    try:
        np.linalg.cholesky(H)
    except np.linalg.LinAlgError:
        return False
    return True


def _block(V: np.ndarray) -> Cov2:
    return ((float(V[0, 0]), float(V[0, 1])), (float(V[0, 1]), float(V[1, 1])))


def _tables(at: Anchored, others: tuple[EffectSpec, ...], spec: EffectSpec,
            parameter: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The ln v grid about ``spec``'s value, each trial's prediction and each cane's calipers'
    penalty on it, with ``others`` in place."""
    par: Parameter = EFFECTS[spec.name].parameters[parameter]
    params = dict(spec.params)
    v0 = params[parameter]
    lo, hi = math.log(v0) - GRID_HALF_WIDTH, math.log(v0) + GRID_HALF_WIDTH
    if not par.log:  # a linear parameter (a flare's excess) stays within a few times its search range
        hi = min(hi, math.log(3.0 * par.high))
    grid = np.linspace(lo, hi, N_GRID)
    ss = at.screen
    uniq, inv = np.unique(ss.canes, return_inverse=True)
    preds, pens = [], []
    for g in grid:
        specs = others + (replace(spec, params=tuple(sorted({**params, parameter: math.exp(g)}.items()))),)
        preds.append(at.predict(specs))
        fx = AppliedEffects([s.instance() for s in specs])
        if fx.changes_diameter and len(ss.cal_s):
            # each cane's calipers once (every trial carries them, weighted 1 / the cane's trial count)
            terms = 0.5 * ss.cal_w * (ss.caliper_change(fx) / ss.cal_sigma) ** 2
            pens.append(np.bincount(inv[ss.cal_idx], terms, minlength=len(uniq)))
        else:
            pens.append(np.zeros(len(uniq)))
    return grid, np.asarray(preds), np.asarray(pens)


def _fit(h: _Hierarchy, starts: list[np.ndarray], free_omega: bool) -> tuple[np.ndarray, float]:
    """Nelder-Mead from each start; omega held at 0 unless ``free_omega``."""
    best = None
    for s in starts:
        if free_omega:
            res = minimize(h.nll, s, method="Nelder-Mead", options=FREE_FIT_OPTIONS)
            x = res.x
        else:
            def obj(t: np.ndarray) -> float:
                return h.nll(np.array([t[0], -np.inf, t[1], t[2]]))

            res = minimize(obj, s[[0, 2, 3]], method="Nelder-Mead",
                           options={"xatol": 1e-3, "fatol": 1e-4, "maxiter": 3000, "maxfev": 3000})
            x = np.array([res.x[0], -np.inf, res.x[1], res.x[2]])
        if best is None or res.fun < best[1]:
            best = (x, float(res.fun))
    return best


def per_cane_test(at: Anchored, log_k_field: np.ndarray, specs: tuple[EffectSpec, ...], name: str,
                  alpha: float, min_change: float, diameter_factor: float = 1.0, s2: float = 0.01,
                  t2: float = 0.02, seed: int = 0,
                  plants: Mapping[str, Any] | None = None) -> PerCaneTest | None:
    """Whether effect ``name`` (one of the fitted ``specs``) varies per cane; None when its class does
    not allow it (:func:`varying_parameter`).

    Parameters
    ----------
    at, log_k_field
        The screen the fit predicts from and the field's ln k, in the same trial order.
    specs
        The fitted global model; the others stay at their values.
    alpha, min_change
        The test's level and the materiality of the canes' spread (mean |change in ln k|).
    diameter_factor
        The model's diameter factor (the caliper line's error scales with it).
    s2, t2
        The global fit's within- and between-cane variances (starting values).
    plants
        Each cane's plant (bush), for the spread's error clustered by plant (:func:`clustered_cov`);
        None: each cane its own.
    """
    parameter = varying_parameter(name)
    if parameter is None:
        return None
    spec = next(s for s in specs if s.name == name)
    others = tuple(s for s in specs if s.name != name)
    unit = EFFECTS[name].parameters[parameter].unit
    v0 = dict(spec.params)[parameter]
    if not (math.isfinite(v0) and v0 > 0):
        return None
    gd = geometry_draws(at, specs, factor=diameter_factor, n_draws=N_GEOMETRY_DRAWS, seed=seed)
    ok = np.all(np.isfinite(gd), axis=0)
    G = np.cov(np.where(ok[None, :], gd, 0.0), rowvar=False)
    grid, P, pen = _tables(at, others, spec, parameter)
    # a trial the screen cannot predict somewhere on the grid (an engine that failed at the anchor)
    # is left out of the test; a cane left with no trial gets no value of its own
    keep = np.all(np.isfinite(P), axis=0) & np.isfinite(log_k_field)
    canes = at.screen.canes[keep]
    if len(np.unique(canes)) < 3:
        return None
    kept_canes = np.isin(np.unique(at.screen.canes), np.unique(canes))
    h = _Hierarchy(grid, P[:, keep], pen[:, kept_canes], log_k_field[keep], canes, G[np.ix_(keep, keep)])
    base = np.array([math.log(v0), -np.inf, math.log(max(s2, SIGMA_FLOOR**2)), math.log(max(t2, 1e-6))])
    x0, f0 = _fit(h, [base, base + np.array([0.0, 0.0, -1.0, 0.0])], free_omega=False)
    starts = [np.array([x0[0], math.log(om), x0[2], x0[3]]) for om in (0.15, 0.5, 1.2)]
    x1, f1 = _fit(h, starts, free_omega=True)
    if f1 > f0:  # nested: the alternative can do no worse than omega = 0
        x1, f1 = x0, f0
    lr = max(0.0, 2.0 * (f0 - f1))
    p = 0.5 * float(stats.chi2.sf(lr, 1)) if lr > 0 else 1.0
    omega = math.exp(x1[1]) if x1[1] > LOG_FLOOR else 0.0
    m, sd = h.posterior(x1)
    # how far the canes' own values move the model from the median's
    moved = np.abs(h.predict_at(m) - h.predict_at(np.full(len(m), x1[0])))
    spread = float(np.mean(moved[np.isfinite(moved)])) if np.any(np.isfinite(moved)) else 0.0
    per = bool(p < alpha and spread >= min_change)
    if per:
        reason = (f"{parameter} varies between canes (ln sd {omega:.2f}; LR {lr:.1f}, p = {p:.2g} < {alpha:.3g}) and "
                  f"the canes' own values move the model by {spread:.3f} in mean |ln k|")
    elif p >= alpha:
        reason = (f"no evidence that {parameter} varies between canes beyond the noise and the caliper lines' "
                  f"error (LR {lr:.2f}, p = {p:.2g}, against {alpha:.3g})")
    else:
        reason = (f"{parameter} varies between canes (p = {p:.2g}) but the canes' own values move the model by "
                  f"{spread:.3f} in mean |ln k|, under {min_change:.3g}: kept global")
    cov_model = cov_plants = n_plants = None
    lost: tuple[str, ...] = ()
    if omega > 0:
        cov_model = sampling_cov(h, x1)
        if plants is not None and all(c in plants for c in h.uniq):
            of = np.array([str(plants[c]) for c in h.uniq])
            n_plants = len(np.unique(of))
            jk = jackknife_over_plants(h, x1, of)
            cov_plants, lost = jk.cov, jk.lost_without
    return PerCaneTest(name, parameter, unit, math.exp(x1[0]), omega, lr, p, alpha, spread, per,
                       {str(c): float(math.exp(v)) for c, v in zip(h.uniq, m)},
                       {str(c): float(s) for c, s in zip(h.uniq, sd)}, reason,
                       wider_of(cov_model, cov_plants), cov_model, cov_plants, n_plants, lost)
