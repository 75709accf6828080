"""Fitting candidate effects to per-trial residuals, with the cane as a random effect.

Residual of trial i on cane c: r_i = ln k_field_i - ln k_pred_i(theta). The
error model is e_i = b_c + eps_i, b_c ~ N(0, tau^2) (each cane's own
unexplained offset: modulus, geometry the data does not show), eps_i ~
N(0, sigma^2) (the trial's own). On the real data about 97 % of the error
variance lies between canes, so treating trials as independent would make
every effect look significant. The mean of b_c is fixed at 0: a non-zero
mean is what ``modulus_scale`` (or another effect) must explain.

sigma^2 and tau^2 are estimated in closed form from the residuals (within-cane
and between-cane mean squares, a balanced one-way design's estimators), so
the negative log-likelihood is a cheap function of theta alone.

Cross-validation leaves one cane out: parameters (and sigma, tau) fitted on
the other canes, the held-out cane scored by the predictive density of its
residual vector and by its absolute log ratios. A candidate's gain is the
per-cane difference of held-out losses; its significance a cluster-robust
score test (:func:`direction_test_p`) whose sign-flip permutation is over
canes (canes are the independent units).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable, Iterator

import numpy as np
from scipy import stats
from scipy.optimize import minimize

from ..model.effects import EFFECTS, AppliedEffects, EffectSpec, Parameter
from .screenset import Anchored

SIGMA_FLOOR = 0.01  # ln units: below the field slope's own standard error on any trial
#: Nelder-Mead's first simplex steps each free parameter by this share of its search range (in the
#: optimizer's coordinates: log for a log parameter). scipy's default steps 5 % of a coordinate's
#: value, and 0.00025 where it is 0; the start grid's middle is 0 for a scale (log 1) and a pitch,
#: and from there the fit barely moved that parameter: an independent-style pair, scale 0.52 with a
#: 45.7 N/m rig (``tests/scripts/pairs_outside_the_suite.py OUT 98``, set 00), was fitted scale
#: 1.000 with a 91 N/m rig (BIC -60.8) where scale 0.48 with a 44.5 N/m rig gives -99.1.
SIMPLEX_STEP = 0.1
#: at most this many restarts of Nelder-Mead from its own answer on the search box's boundary
BOX_RESTARTS = 3


def _bounds(par: Parameter) -> tuple[float, float]:
    """A parameter's search bounds in the optimizer's coordinates (log for a log parameter)."""
    return (math.log(par.low), math.log(par.high)) if par.log else (par.low, par.high)


def first_simplex(x0: np.ndarray, lo: np.ndarray, hi: np.ndarray, share: float = SIMPLEX_STEP) -> np.ndarray:
    """Nelder-Mead's first simplex about ``x0``: one vertex per coordinate, stepped by ``share`` of
    its range ``hi - lo``, toward the inside where a step would leave the box."""
    sim = [np.asarray(x0, float)]
    for i in range(len(sim[0])):
        step = share * (hi[i] - lo[i])
        v = sim[0].copy()
        v[i] += step if v[i] + step <= hi[i] else -step
        sim.append(v)
    return np.vstack(sim)


def nelder_mead_in_box(obj: Callable[[np.ndarray], float], x0: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                       maxiter: int) -> Any:
    """Nelder-Mead on ``obj``, which clips its argument to the box [lo, hi], from :func:`first_simplex`.

    Restarted from its own answer (clipped into the box), with a fresh first simplex, while that
    answer lies on the box's boundary and the restart lowers ``obj`` (at most :data:`BOX_RESTARTS`
    times). Outside the box the clipped objective is flat, and a simplex that strays there can
    shrink onto a corner short of the optimum along the face: seed 7's rig + flare set 36 (on
    30f3fd7) was fitted rig 45.6 N/m with the flare at the corner of its bounds (25 mm excess,
    20 mm length; BIC -67.0), where a restart finds 50.9 N/m, 25 mm and 84 mm (BIC -99.0), and
    a scale + rig pair that fits worse (-86.4) was named in its place.
    """
    fatol = 1e-6

    def run(x: np.ndarray) -> Any:
        return minimize(obj, x, method="Nelder-Mead", options={"xatol": 1e-4, "fatol": fatol, "maxiter": maxiter,
                                                               "initial_simplex": first_simplex(x, lo, hi)})

    res = run(x0)
    for _ in range(BOX_RESTARTS):
        x = np.clip(res.x, lo, hi)
        if not np.any((x <= lo) | (x >= hi)):
            break
        again = run(x)
        if not again.fun < res.fun - fatol:
            break
        res = again
    return res


@dataclass
class Candidate:
    """Effects with free global parameters (and fixed ones from earlier steps)."""

    names: tuple[str, ...]
    free: list[tuple[str, str]]  # (effect, parameter) fitted, in vector order

    @classmethod
    def of(cls, names: tuple[str, ...], refined: tuple[tuple[str, str], ...] = ()) -> "Candidate":
        """Every parameter of ``names`` free but those held until a refinement (``Parameter.refined``,
        left at their null) that ``refined`` does not list."""
        free = [(n, p) for n in names for p, par in EFFECTS[n].parameters.items()
                if not par.refined or (n, p) in refined]
        return cls(tuple(names), free)

    @property
    def refined(self) -> tuple[tuple[str, str], ...]:
        """The refinement parameters this candidate fits (:mod:`.refine`)."""
        return tuple((n, p) for n, p in self.free if EFFECTS[n].parameters[p].refined)

    @classmethod
    def like(cls, names: tuple[str, ...], model: Any) -> "Candidate":
        """``names`` with the refinements ``model`` (a :class:`CVResult`, :class:`Fit` or candidate) fits
        for those of its effects among them: a refit after a refinement keeps it."""
        cand = getattr(getattr(model, "fit", model), "candidate", model)
        return cls.of(tuple(names), tuple(r for r in cand.refined if r[0] in names))

    def to_internal(self, values: dict[tuple[str, str], float]) -> np.ndarray:
        out = []
        for n, p in self.free:
            par = EFFECTS[n].parameters[p]
            v = values[(n, p)]
            out.append(math.log(v) if par.log else v)
        return np.array(out)

    def specs(self, x: np.ndarray) -> tuple[EffectSpec, ...]:
        vals: dict[str, dict[str, float]] = {n: {} for n in self.names}
        for (n, p), xi in zip(self.free, x):
            par = EFFECTS[n].parameters[p]
            lo, hi = _bounds(par)
            xi = min(max(float(xi), lo), hi)
            vals[n][p] = math.exp(xi) if par.log else xi
        return tuple(EffectSpec(n, tuple(sorted(vals[n].items()))) for n in self.names)

    def box(self) -> tuple[np.ndarray, np.ndarray]:
        """The free parameters' search bounds in the optimizer's coordinates: (low, high)."""
        b = np.array([_bounds(EFFECTS[n].parameters[p]) for n, p in self.free], float).reshape(-1, 2)
        return b[:, 0], b[:, 1]

    def grid(self, n_per: int = 7) -> list[np.ndarray]:
        axes = []
        for n, p in self.free:
            lo, hi = _bounds(EFFECTS[n].parameters[p])
            axes.append(np.linspace(lo, hi, n_per))
        if not axes:
            return [np.zeros(0)]
        mesh = np.meshgrid(*axes, indexing="ij")
        return [np.array(v) for v in zip(*(m.ravel() for m in mesh))]


def group_index(groups: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each row's group (0.. in sorted order of the labels) and each group's row count: what
    :func:`variance_components` and :func:`group_nll` need of the labels, taken once by a fit that
    calls them at every evaluation."""
    _, inv, counts = np.unique(groups, return_inverse=True, return_counts=True)
    return inv, counts


def variance_components(r: np.ndarray, groups: np.ndarray,
                        index: tuple[np.ndarray, np.ndarray] | None = None) -> tuple[float, float]:
    """(sigma^2, tau^2) of the zero-mean random-intercept model, closed form (``index``:
    :func:`group_index` of ``groups``, if at hand)."""
    inv, counts = index if index is not None else group_index(groups)
    means = np.bincount(inv, r) / counts
    ssw = float(np.sum((r - means[inv]) ** 2))
    dfw = len(r) - len(counts)
    s2 = max(ssw / dfw if dfw > 0 else float(np.mean(r**2)), SIGMA_FLOOR**2)
    nbar = float(np.mean(counts))
    t2 = max(0.0, float(np.mean(counts * means**2)) / nbar - s2 / nbar)
    return s2, t2


def group_nll(r: np.ndarray, groups: np.ndarray, s2: float, t2: float,
              index: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """-log density of each group's residual vector under N(0, s2 I + t2 11^T)."""
    inv, counts = index if index is not None else group_index(groups)
    sums = np.bincount(inv, r)
    sq = np.bincount(inv, r**2)
    n = counts.astype(float)
    quad = sq / s2 - t2 * sums**2 / (s2 * (s2 + n * t2))
    logdet = (n - 1) * math.log(s2) + np.log(s2 + n * t2)
    return 0.5 * (quad + logdet + n * math.log(2 * math.pi))


def nll(r: np.ndarray, groups: np.ndarray, index: tuple[np.ndarray, np.ndarray] | None = None) -> float:
    index = index if index is not None else group_index(groups)
    s2, t2 = variance_components(r, groups, index)
    return float(np.sum(group_nll(r, groups, s2, t2, index)))


@dataclass
class Fit:
    candidate: Candidate
    x: np.ndarray
    specs: tuple[EffectSpec, ...]
    nll: float
    s2: float
    t2: float
    n: int

    @property
    def k_params(self) -> int:
        return len(self.x)

    @property
    def aic(self) -> float:
        return 2 * self.nll + 2 * (self.k_params + 2)

    @property
    def bic(self) -> float:
        return 2 * self.nll + (self.k_params + 2) * math.log(max(self.n, 1))


def fit_candidate(cand: Candidate, at: Anchored, log_k_field: np.ndarray,
                  fixed: tuple[EffectSpec, ...] = (), x0: np.ndarray | None = None) -> Fit:
    """Maximum likelihood of ``cand``'s free parameters (with ``fixed`` effects in place), predicting
    from the screen ``at``; ``at.log_k`` and ``log_k_field`` are in the same trial order."""
    groups = at.screen.canes
    index = group_index(groups)
    # the calipers are data too: a diameter effect may not contradict their readings (whether one
    # is in the fit depends on the effects' names only, not on the parameter values tried)
    x_any = np.zeros(len(cand.free))
    diameter = AppliedEffects([s.instance() for s in fixed + cand.specs(x_any)]).changes_diameter

    def obj(x: np.ndarray) -> float:
        specs = fixed + cand.specs(x)
        r = log_k_field - at.predict(specs)
        if not np.all(np.isfinite(r)):
            return 1e12
        penalty = at.screen.caliper_nll(AppliedEffects([s.instance() for s in specs])) if diameter else 0.0
        return nll(r, groups, index) + penalty

    if not cand.free:
        v = obj(np.zeros(0))
        r = log_k_field - at.predict(fixed)
        s2, t2 = variance_components(r, groups)
        return Fit(cand, np.zeros(0), fixed, v, s2, t2, len(r))
    starts = [x0] if x0 is not None else []
    grid = cand.grid(7 if len(cand.free) <= 2 else 5)
    vals = [obj(g) for g in grid]
    order = np.argsort(vals)
    starts += [grid[i] for i in order[:2]]
    best = None
    lo, hi = cand.box()
    for s in starts:
        res = nelder_mead_in_box(obj, s, lo, hi, maxiter=400 * len(s))
        if best is None or res.fun < best.fun:
            best = res
    x = best.x
    specs = fixed + cand.specs(x)
    r = log_k_field - at.predict(specs)
    s2, t2 = variance_components(r, groups)
    return Fit(cand, x, specs, float(best.fun), s2, t2, len(r))


@dataclass
class CVResult:
    fit: Fit
    loss: dict[str, float]  # held-out -log density per cane
    residual: np.ndarray  # held-out residual per trial (ln k_field - ln k_pred)
    fold_specs: dict[str, tuple[EffectSpec, ...]] = field(default_factory=dict)


def cross_validate(cand: Candidate, at: Anchored, log_k_field: np.ndarray,
                   fixed: tuple[EffectSpec, ...] = (), full: Fit | None = None) -> CVResult:
    """Leave-one-cane-out: fit on the other canes, score the held-out cane."""
    full = full or fit_candidate(cand, at, log_k_field, fixed)
    canes = at.screen.canes
    loss: dict[str, float] = {}
    resid = np.full(len(log_k_field), np.nan)
    folds: dict[str, tuple[EffectSpec, ...]] = {}
    for c in np.unique(canes):
        test = canes == c
        train = ~test
        sub = at.subset(train)
        f = fit_candidate(cand, sub, log_k_field[train], fixed,
                          x0=full.x if len(full.x) else None) if cand.free else None
        specs = f.specs if f is not None else fixed
        s2, t2 = (f.s2, f.t2) if f is not None else variance_components(
            log_k_field[train] - sub.predict(fixed), canes[train])
        r = log_k_field[test] - at.subset(test).predict(specs)
        resid[test] = r
        loss[str(c)] = float(np.sum(group_nll(r, canes[test], s2, t2)))
        folds[str(c)] = specs
    return CVResult(full, loss, resid, folds)


#: up to this many canes every sign assignment is enumerated; beyond, ``n_perm`` random ones
EXACT_FLIPS_UP_TO = 16


def sign_flips(n: int, n_perm: int, seed: int) -> tuple[np.ndarray, bool]:
    """Sign vectors over ``n`` canes: all 2^n (n <= :data:`EXACT_FLIPS_UP_TO`) or ``n_perm``
    random ones; and whether they are all (an exact null, which includes the observed signs)."""
    if n <= EXACT_FLIPS_UP_TO:
        return ((np.arange(2**n)[:, None] >> np.arange(n)[None, :]) & 1) * 2.0 - 1.0, True
    return np.random.default_rng(seed).choice([-1.0, 1.0], size=(n_perm, n)), False


def flip_p(null: np.ndarray, obs: float, exact: bool, tol: float = 1e-12) -> float:
    """One-sided p = P(null >= obs): the exact share, or the Monte Carlo estimate (+1 in both counts)."""
    hits = np.sum(null >= obs - tol)
    return float(hits / len(null)) if exact else float((hits + 1) / (len(null) + 1))


#: a per-cane gain (mean |ln k| ratio) this close to 0 is rounding, not a gain (:func:`sign_flip_p`)
GAIN_TIE = 1e-12


def sign_flip_p(diff: np.ndarray, n_perm: int = 20000, seed: int = 0) -> float:
    """One-sided p that the per-cane gains ``diff`` are centred above 0.

    Signed-rank statistic (sum of the ranks of |diff| with their signs) under
    random sign flips: exact enumeration up to 16 canes, Monte Carlo beyond.
    Ranks, not the gains themselves, so one cane with a huge gain cannot
    carry the test, and twelve canes that all improve are significant.
    A gain within :data:`GAIN_TIE` of 0 is a tie and left out: a candidate fitted at its null
    value differs from the current model by rounding only, and the signs of rounding are no
    evidence either way.
    """
    d = np.asarray(diff, float)
    d = d[np.abs(d) > GAIN_TIE]
    n = len(d)
    if n == 0:
        return 1.0
    ranks = np.argsort(np.argsort(np.abs(d))) + 1.0
    obs = float(np.sum(np.sign(d) * ranks))
    signs, exact = sign_flips(n, n_perm, seed)
    return flip_p(signs @ ranks, obs, exact, tol=1e-9)


def apply_vinv(x: np.ndarray, inv: np.ndarray, counts: np.ndarray, s2: float, t2: float) -> np.ndarray:
    """V^-1 x for V = blockdiag(s2 I + t2 11') over groups (``inv``: group index per row).

    Sherman-Morrison per block: (x - t2 sum_c(x) / (s2 + n_c t2)) / s2.
    """
    return (x - (t2 * np.bincount(inv, x, minlength=len(counts)) / (s2 + counts * t2))[inv]) / s2


def _fitted_directions(at: Anchored, fixed: tuple[EffectSpec, ...], base: np.ndarray) -> np.ndarray:
    """Central differences of ln k_pred in the fitted effects' internal coordinates (trials x params)."""
    names = tuple(sp.name for sp in fixed)
    if not names:
        return np.zeros((len(base), 0))
    # a refinement the fixed model carries (a flare's size exponent it fits) is one of its directions too
    held = tuple((sp.name, k) for sp in fixed for k, _ in sp.params if EFFECTS[sp.name].parameters[k].refined)
    cand = Candidate.of(names, held)
    x0 = cand.to_internal({(sp.name, k): v for sp in fixed for k, v in sp.params})
    cols = []
    for j in range(len(x0)):
        h = 1e-4 * max(1.0, abs(float(x0[j])))
        xp, xm = x0.copy(), x0.copy()
        xp[j] += h
        xm[j] -= h
        d = (at.predict(cand.specs(xp)) - at.predict(cand.specs(xm))) / (2 * h)
        if np.all(np.isfinite(d)) and np.max(np.abs(d)) > 1e-12:
            cols.append(d)  # a parameter at its bound or without effect gives no direction
    return np.column_stack(cols) if cols else np.zeros((len(base), 0))


def direction_test_p(name: str | tuple[str, ...] | list[tuple[str, ...]], at: Anchored, log_k_field: np.ndarray,
                     fixed: tuple[EffectSpec, ...], s2: float, t2: float, n_per: int = 9, n_perm: int = 20000,
                     seed: int = 0, project_fitted: bool = False) -> float:
    """p that the residuals of the current model lean the way effect ``name`` would move them.

    A cluster-robust score test with a max over the effect's parameters. For each
    point theta of a grid over ``name``'s parameters, the effect's predicted change
    p(theta) = ln k_pred(fixed + name(theta)) - ln k_pred(fixed) is the direction. Each cane
    contributes U_c = p_c' V_c^-1 r_c, with r the current residuals and V_c the current
    fit's random-intercept covariance (s2 I + t2 11'); the statistic is
    T(theta) = sum U_c / sqrt(sum U_c^2), maximised over theta. Under the null (the
    effect absent, each cane's residual vector symmetric about zero) the canes' signs
    are exchangeable, so the max is calibrated by flipping them (the same flips for
    every theta, which accounts for the search over theta). The test is one-sided in
    theta's direction; where the grid spans both signs of an effect (``modulus_scale``
    above and below 1, ``probe_misalignment`` up and down) the max covers both, i.e.
    it is two-sided. For a global offset such as ``modulus_scale`` T is the t statistic
    of the cane means; a test on held-out loss differences carries each cane's own
    offset (a term 2 delta u_c) and needs about four times the canes for the same
    power. A cane's own structure enters the denominator, so it cannot pass for the
    effect unless it leans the same way on many canes.

    ``project_fitted`` projects out of p the parts the effects already in ``fixed`` can
    produce (their finite-difference directions Q at the fitted values, in the V^-1
    metric: p <- p - Q (Q' V^-1 Q)^-1 Q' V^-1 p). At the fit's optimum the residuals are
    orthogonal to Q, so without it the flipped sums carry Q's part and the test is
    conservative after a first effect. It is off by default: on the self-test suite
    (seed 7) it added a spurious second effect to one single-effect set and a third
    effect to both out-of-library sets, with no gain elsewhere (docs/discovery.md);
    a false name costs more than a late one.
    """
    # one effect, effects tested jointly (a tuple), or a union of such sets (a list: the max
    # runs over all of their directions, so "some pair leans the residuals" is one test)
    if isinstance(name, str):
        sets = [(name,)]
    elif isinstance(name, list):
        sets = [(n,) if isinstance(n, str) else tuple(n) for n in name]
    else:
        sets = [tuple(name)]
    base = at.predict(fixed)
    r = log_k_field - base
    uniq, inv, counts = np.unique(at.screen.canes, return_inverse=True, return_counts=True)

    def vinv(x: np.ndarray) -> np.ndarray:
        return apply_vinv(x, inv, counts, s2, t2)

    vr = vinv(r)
    Q = _fitted_directions(at, fixed, base) if project_fitted else np.zeros((len(r), 0))
    if Q.shape[1]:
        VQ = np.column_stack([vinv(q) for q in Q.T])
        G = Q.T @ VQ
    cols = []
    points = []
    for names in sets:
        cand = Candidate.of(names)
        # a joint grid over 3+ parameters: 125 directions, not 729
        points += [(cand, x) for x in cand.grid(min(n_per, 5) if len(cand.free) > 2 else n_per)]
    for cand, x in points:
        pch = at.predict(fixed + cand.specs(x)) - base
        if not np.all(np.isfinite(pch)) or np.max(np.abs(pch)) < 1e-9:
            continue  # the effect's null point (or an undefined one) is no direction
        if Q.shape[1]:
            pch = pch - Q @ np.linalg.lstsq(G, VQ.T @ pch, rcond=None)[0]
        u = np.bincount(inv, pch * vr, minlength=len(uniq))
        nrm = math.sqrt(float(np.sum(u * u)))
        if nrm > 1e-12 * max(1.0, float(np.abs(vr).max())):
            cols.append(u / nrm)
    if not cols:
        return 1.0
    U = np.array(cols).T  # canes x directions
    obs = float(np.max(U.sum(axis=0)))
    flips, exact = sign_flips(len(uniq), n_perm, seed)
    return flip_p(np.max(flips @ U, axis=1), obs, exact)


def cane_resamples(at: Anchored, n: int, seed: int) -> Iterator[tuple[np.ndarray, Anchored]]:
    """``n`` cane-bootstrap resamples of ``at``: canes drawn with replacement, each with all its trials.

    Yields ``(rows, resample)``: the rows taken from ``at`` (to index the field stiffness the
    same way) and the trials there as their own :class:`.Anchored`. A cane drawn twice is
    relabelled as two canes (``"c#k"`` for its k-th place in the draw), so the random cane
    effect treats each copy as its own group. :func:`bootstrap_ci` draws its intervals from
    these; the same ``seed`` gives the same draws.
    """
    rng = np.random.default_rng(seed)
    canes = at.screen.canes
    uniq = np.unique(canes)
    rows_of = {c: np.flatnonzero(canes == c) for c in uniq}
    for _ in range(n):
        pick = rng.choice(uniq, size=len(uniq), replace=True)
        rows = np.concatenate([rows_of[c] for c in pick])
        labels = np.concatenate([[f"{c}#{k}"] * len(rows_of[c]) for k, c in enumerate(pick)])
        yield rows, at.take(rows, labels)


def small_sample_widening(n_canes: int) -> float:
    """How far a cane bootstrap's percentile interval is widened about the fit, for ``n_canes`` canes.

    t(0.975, G - 1) / z(0.975) * sqrt(G / (G - 1)): the bootstrap's spread of a between-cane
    effect carries (G - 1) / G of its variance, and its tails are the normal's where Student's
    with G - 1 degrees of freedom apply, the offsets' variance being estimated from G canes. 1.11
    at 18 canes, 1.05 at 40, 2.7 at 3; infinite below two canes (no spread between canes to
    resample: the interval is then the whole search range). Where the fitted model is the one
    that made the data (``python tests/scripts/interval_coverage.py OUT --reps 25 --seed {1,2}``,
    18 canes, 200 datasets), the plain percentile interval held the hidden value 177 times (88.5
    %), widened so 183 (91.5 %; docs/discovery.md, session 57).
    """
    if n_canes < 2:
        return math.inf
    return float(stats.t.ppf(0.975, n_canes - 1) / stats.norm.ppf(0.975) * math.sqrt(n_canes / (n_canes - 1)))


def bootstrap_draws(fit: Fit, at: Anchored, log_k_field: np.ndarray, fixed: tuple[EffectSpec, ...] = (),
                    n_boot: int = 100, seed: int = 0) -> np.ndarray:
    """The free parameters refitted on ``n_boot`` cane resamples (:func:`cane_resamples`), from the
    fit's own value: one row per resample, one column per free parameter, in their own units."""
    draws = []
    for rows, sub in cane_resamples(at, n_boot, seed):
        f = fit_candidate(fit.candidate, sub, log_k_field[rows], fixed, x0=fit.x)
        vals = {(sp.name, k): v for sp in f.specs[len(fixed):] for k, v in sp.params}
        draws.append([vals[key] for key in fit.candidate.free])
    return np.array(draws, float).reshape(-1, len(fit.candidate.free))


def intervals_from_draws(fit: Fit, draws: np.ndarray, n_canes: int, fixed: tuple[EffectSpec, ...] = (),
                         widening: float | None = None) -> dict[tuple[str, str], tuple[float, float]]:
    """95 % intervals from :func:`bootstrap_draws`.

    The draws' 2.5th and 97.5th percentiles, taken in the optimizer's coordinate (log for a log
    parameter, so a spring's end stays positive), each moved away from the fit by ``widening``
    times its distance (default :func:`small_sample_widening` of ``n_canes``; 1 keeps the
    percentiles), and cut at the search bounds. An end that lies on the fit's wrong side (a
    2.5th percentile above the fit, or a 97.5th below it) is the fit itself. With an infinite
    widening (fewer than two canes) the interval is the whole search range.
    """
    value = {(sp.name, k): v for sp in fit.specs[len(fixed):] for k, v in sp.params}
    w = small_sample_widening(n_canes) if widening is None else widening
    box_lo, box_hi = fit.candidate.box()
    logs = [EFFECTS[n].parameters[p].log for n, p in fit.candidate.free]

    def own_units(e: float, log: bool) -> float:
        return float(math.exp(e) if log else e)

    if not math.isfinite(w):  # fewer than two canes (no spread between them to resample): the search range
        return {key: (own_units(box_lo[j], log), own_units(box_hi[j], log))
                for j, (key, log) in enumerate(zip(fit.candidate.free, logs))}
    out = {}
    for j, (key, log) in enumerate(zip(fit.candidate.free, logs)):
        col = np.log(draws[:, j]) if log else draws[:, j]
        v = value[key]
        x = math.log(v) if log else v
        ends = []
        for q, side in ((2.5, -1.0), (97.5, 1.0)):
            dist = max(side * (np.percentile(col, q) - x), 0.0)
            if dist == 0.0:
                ends.append(float(v))  # exactly the fit (not exp(log v), which may miss it by a rounding)
            else:
                ends.append(own_units(min(max(x + side * w * dist, box_lo[j]), box_hi[j]), log))
        out[key] = (ends[0], ends[1])
    return out


def bootstrap_ci(fit: Fit, at: Anchored, log_k_field: np.ndarray, fixed: tuple[EffectSpec, ...] = (),
                 n_boot: int = 100, seed: int = 0) -> dict[tuple[str, str], tuple[float, float]]:
    """95 % intervals of the free parameters, resampling canes (the independent units): the
    percentile interval of :func:`bootstrap_draws`, widened about the fit for the number of canes
    (:func:`intervals_from_draws`, :func:`small_sample_widening`)."""
    draws = bootstrap_draws(fit, at, log_k_field, fixed, n_boot, seed)
    return intervals_from_draws(fit, draws, len(np.unique(at.screen.canes)), fixed)
