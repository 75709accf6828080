"""The per-cane scope of a named effect (``canebench.discovery.per_cane``)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from canebench.model.effects import EffectSpec


@pytest.fixture(scope="module")
def bundled_screen(bundled_trials):
    from canebench.discovery.screen import trial_geometry
    from canebench.discovery.screenset import Anchored, ScreenSet
    from canebench.model.presets import PRESETS

    ss = ScreenSet.build([trial_geometry(t, PRESETS["beam-consistent"]) for t in bundled_trials])
    return Anchored(ss, np.log(np.full(len(ss.trials), 0.1)))


def _linear_hierarchy(a, b, y, canes, G):
    """A :class:`_Hierarchy` whose prediction is exactly linear in ln v, P_i = a_i + b_i ln v."""
    from canebench.discovery import per_cane as pc

    grid = np.linspace(-6.0, 6.0, pc.N_GRID)
    pen = np.zeros((pc.N_GRID, len(np.unique(canes))))
    return pc._Hierarchy(grid, a[None, :] + b[None, :] * grid[:, None], pen, y, canes, G)


@pytest.mark.parametrize("case", ["broad", "narrow"])
def test_the_hierarchy_integrates_each_canes_value_exactly_where_the_prediction_is_linear(case):
    """Where the prediction is linear in ln v, a cane's value integrates out in closed form: its
    residual vector is Gaussian with covariance s2 I + t2 11^T + G_c + omega^2 b_c b_c^T about
    a_c + b_c mu, and its posterior mean of ln v is mu + omega^2 b^T V^-1 (y - a - b mu). The
    adaptive quadrature is exact there (a Gaussian integrand), so both must hold to rounding (1e-9),
    on canes whose pushes say little about their value (``broad``) and on canes whose root
    dominates their compliance with little noise (``narrow``: each cane's likelihood 0.01-0.03 wide
    in ln v, where 32 fixed nodes were 84 nats off). At omega = 0 and G = 0 it is the global fit's
    random-intercept density (:func:`canebench.discovery.fit.group_nll`, written separately)."""
    from scipy.stats import multivariate_normal

    from canebench.discovery.fit import group_nll

    rng = np.random.default_rng(3)
    if case == "broad":
        canes = np.repeat([f"c{i}" for i in range(6)], [3, 3, 2, 4, 3, 1])
        n = len(canes)
        a, b = rng.normal(0.0, 0.3, n), -rng.uniform(0.1, 0.9, n)
        mu, omega, s2, t2, g_sd = 0.3, 0.6, 0.02, 0.05, 0.05
    else:
        canes = np.repeat([f"c{i:02d}" for i in range(18)], 3)
        n = len(canes)
        a, b = rng.normal(0.0, 0.3, n), -rng.uniform(0.85, 0.95, n)
        mu, omega, s2, t2, g_sd = 0.3, 0.8, 0.002, 0.0005, 0.01
    A = rng.normal(0.0, g_sd, (n, n))
    G = np.zeros((n, n))
    for c in np.unique(canes):  # each cane's own block: the line error does not cross canes
        m = canes == c
        G[np.ix_(m, m)] = (A @ A.T)[np.ix_(m, m)]
    y = a + b * (mu + omega * rng.normal(size=n)) + rng.normal(0.0, 0.05, n)
    h = _linear_hierarchy(a, b, y, canes, G)
    theta = np.array([mu, math.log(omega), math.log(s2), math.log(t2)])
    want, post = 0.0, []
    for c in np.unique(canes):
        m = canes == c
        V = s2 * np.eye(m.sum()) + t2 + G[np.ix_(m, m)] + omega**2 * np.outer(b[m], b[m])
        want -= multivariate_normal(a[m] + b[m] * mu, V).logpdf(y[m])
        post.append(mu + omega**2 * b[m] @ np.linalg.solve(V, y[m] - a[m] - b[m] * mu))
    assert h.nll(theta) == pytest.approx(want, rel=1e-9, abs=1e-9)
    m_post, _ = h.posterior(theta)
    assert m_post == pytest.approx(np.array(post), abs=1e-9)
    # omega = 0 and no line error: the global fit's random-intercept density of the same residual
    h0 = _linear_hierarchy(a, b, y, canes, np.zeros((n, n)))
    theta0 = np.array([mu, -np.inf, math.log(s2), math.log(t2)])
    r = y - a - b * mu
    assert h0.nll(theta0) == pytest.approx(float(np.sum(group_nll(r, canes, s2, t2))), rel=1e-12)


def test_the_quadrature_holds_with_a_calipers_penalty_and_past_the_grids_ends():
    """Two cases the linear closed form above leaves out. (1) A calipers' penalty q_c (u - u0_c)^2 on
    each cane (a quadratic: its spline is exact), checked against a trapezoid integral of prior x
    likelihood x exp(-penalty) written here from the formulas (2e5 points over +-12 sd), to 1e-9.
    (2) Canes whose values lie far past the grid's ends (grid +-0.5 about mu, values 2-4 sd out):
    the tables go on straight beyond them, exact for a linear prediction, so the closed form must
    hold there too, to 1e-9 (held flat past the ends, as in 685ac7e, this case was 263 nats off)."""
    from scipy.integrate import trapezoid
    from scipy.stats import multivariate_normal

    from canebench.discovery import per_cane as pc

    rng = np.random.default_rng(8)
    canes = np.repeat([f"c{i}" for i in range(5)], [3, 3, 2, 1, 3])
    n, C = len(canes), 5
    uniq, inv = np.unique(canes, return_inverse=True)
    a, b = rng.normal(0.0, 0.3, n), -rng.uniform(0.3, 0.9, n)
    mu, omega, s2, t2 = 0.2, 0.7, 0.004, 0.01
    theta = np.array([mu, math.log(omega), math.log(s2), math.log(t2)])
    G = np.zeros((n, n))
    # (1) a penalty, the grid wide
    q, u0 = rng.uniform(0.5, 20.0, C), rng.normal(mu, 0.5, C)
    grid = np.linspace(-6.0, 6.0, pc.N_GRID)
    y = a + b * (mu + omega * rng.normal(size=C))[inv] + rng.normal(0.0, 0.06, n)
    pen = q[None, :] * (grid[:, None] - u0[None, :]) ** 2
    h = pc._Hierarchy(grid, a[None, :] + b[None, :] * grid[:, None], pen, y, canes, G)
    want = 0.0
    for k in range(C):
        m = inv == k
        u = mu + omega * np.linspace(-12.0, 12.0, 200001)
        S = s2 * np.eye(m.sum()) + t2
        r = y[m][None, :] - (a[m][None, :] + b[m][None, :] * u[:, None])
        ll = multivariate_normal(np.zeros(m.sum()), S).logpdf(r) - q[k] * (u - u0[k]) ** 2
        lp = -0.5 * ((u - mu) / omega) ** 2 - math.log(omega * math.sqrt(2 * math.pi))
        top = np.max(ll + lp)
        want -= top + math.log(trapezoid(np.exp(ll + lp - top), u))
    assert h.nll(theta) == pytest.approx(want, rel=1e-9, abs=1e-9)
    # (2) values far past the ends of a narrow grid, no penalty: the closed form
    grid = np.linspace(mu - 0.5, mu + 0.5, 41)
    z = np.array([-4.0, -2.5, 2.0, 3.0, 4.0])
    y = a + b * (mu + omega * z)[inv] + rng.normal(0.0, 0.03, n)
    h = pc._Hierarchy(grid, a[None, :] + b[None, :] * grid[:, None], np.zeros((41, C)), y, canes, G)
    want, post = 0.0, []
    for k in range(C):
        m = inv == k
        V = s2 * np.eye(m.sum()) + t2 + omega**2 * np.outer(b[m], b[m])
        want -= multivariate_normal(a[m] + b[m] * mu, V).logpdf(y[m])
        post.append(mu + omega**2 * b[m] @ np.linalg.solve(V, y[m] - a[m] - b[m] * mu))
    assert h.nll(theta) == pytest.approx(want, rel=1e-9, abs=1e-9)
    assert h.posterior(theta)[0] == pytest.approx(np.array(post), abs=1e-9)
    # evaluated again after other parameters (the modes start from the last ones), the same answer
    h.nll(theta + np.array([1.0, 0.5, 0.0, 0.0]))
    assert h.nll(theta) == pytest.approx(want, rel=1e-9, abs=1e-9)


def _eighteen_canes(slopes):
    """18 canes of three pushes with ``slopes`` (the prediction's d ln k / d ln v at each push) and
    random offsets: canes, each trial's cane index, a, b (for :func:`_linear_hierarchy`)."""
    canes = np.repeat([f"c{i:02d}" for i in range(18)], 3)
    return canes, np.unique(canes, return_inverse=True)[1], np.tile(slopes, 18)


def _draw_and_fit(rng, canes, inv, a, b, mu, omega, s2, t2):
    """One dataset from the hierarchy (each cane's ln v, level and the trial noise), its linear
    hierarchy, and the maximum-likelihood parameters (per_cane_test's own two-stage fit)."""
    from canebench.discovery import per_cane as pc

    C, n = len(np.unique(canes)), len(canes)
    y = (a + b * (mu + omega * rng.normal(size=C))[inv] + rng.normal(0.0, math.sqrt(t2), C)[inv]
         + rng.normal(0.0, math.sqrt(s2), n))
    h = _linear_hierarchy(a, b, y, canes, np.zeros((n, n)))
    base = np.array([mu, -np.inf, math.log(s2), math.log(t2)])
    x0, _ = pc._fit(h, [base, base + np.array([0.0, 0.0, -1.0, 0.0])], free_omega=False)
    x1, _ = pc._fit(h, [np.array([x0[0], math.log(o), x0[2], x0[3]]) for o in (0.15, 0.5, 1.2)], free_omega=True)
    return y, h, x1


def test_the_spreads_sampling_covariance_matches_its_scatter_over_repeated_datasets():
    """:func:`sampling_cov` (the inverse observed information, the (mu, ln omega) block) against the
    scatter of the fitted mu and ln omega over 40 datasets drawn from one hierarchy (18 canes, three
    pushes, prediction linear in ln v with a root's share larger at the lower push, each cane's level
    and noise beside it). The sd of 40 estimates is itself uncertain by about 1 / sqrt(2 x 39) = 11 %,
    and the information's inverse is an asymptotic answer at 18 canes (in development, 60 datasets:
    scatter 0.151 against a median error of 0.137 for mu, 0.182 against 0.175 for ln omega), so each ratio of scatter to the
    median standard error must lie in [0.7, 1.4] (about 3 of the sd's errors); a covariance off by
    a factor 2 in variance (41 % in sd) fails. The (mu, ln omega) correlation is near 0 both ways.
    Each 95 % Wald interval covers the truth in at least 33 of 40 (an independent review's 400
    datasets: 94 % and 92.5 %; at 92.5 % fewer than 33 of 40 has a chance of about 1 %; ML's ln omega
    is low by about 0.07 at 18 canes)."""
    from canebench.discovery import per_cane as pc

    rng = np.random.default_rng(7)
    canes, inv, b = _eighteen_canes([-0.8, -0.55, -0.3])
    a = rng.normal(0.0, 0.3, len(canes))
    mu, omega, s2, t2 = math.log(50.0), 0.6, 0.05**2, 0.15**2
    est, se, cover = [], [], 0
    for _ in range(40):
        _, h, x1 = _draw_and_fit(rng, canes, inv, a, b, mu, omega, s2, t2)
        V = np.array(pc.sampling_cov(h, x1))
        assert V.shape == (2, 2) and np.all(np.linalg.eigvalsh(V) > 0)
        est.append(x1[:2])
        se.append(np.sqrt(np.diag(V)))
        cover += np.abs(x1[:2] - [mu, math.log(omega)]) < 1.96 * np.sqrt(np.diag(V))
    est, se = np.array(est), np.array(se)
    ratio = est.std(axis=0, ddof=1) / np.median(se, axis=0)
    assert np.all((ratio > 0.7) & (ratio < 1.4)), ratio
    assert abs(np.corrcoef(est.T)[0, 1]) < 0.4
    assert np.all(cover >= 33), cover
    # omega at 0 has no ln omega to give an error of
    assert pc.sampling_cov(h, np.array([mu, -np.inf, math.log(s2), math.log(t2)])) is None


def test_the_spreads_sampling_covariance_is_the_inverse_information_where_a_canes_level_and_value_trade_off():
    """Pushes whose share of the root hardly changes along a cane (slopes -0.35, -0.3, -0.25) make a
    cane's own level (t2) and its own value (omega) nearly interchangeable: there the variances'
    correlation with (mu, ln omega) matters, and dropping them from the information, or a wrong mixed
    partial, changes the answer by tens of percent. Against the inverse Hessian of the Gaussian
    marginal likelihood written out here (multivariate_normal per cane, exact where the prediction is
    linear in ln v: the first test), differentiated by a different scheme (central differences of
    central-difference gradients, steps 2e-3), each element within 1e-3 of the largest."""
    from scipy.stats import multivariate_normal

    from canebench.discovery import per_cane as pc

    rng = np.random.default_rng(11)
    canes, inv, b = _eighteen_canes([-0.35, -0.3, -0.25])
    a = rng.normal(0.0, 0.3, len(canes))
    y, h, x1 = _draw_and_fit(rng, canes, inv, a, b, math.log(50.0), 0.9, 0.05**2, 0.1**2)
    C = 18

    def nll(th):
        m, w, v, u = th[0], math.exp(th[1]), math.exp(th[2]), math.exp(th[3])
        out = 0.0
        for c in range(C):
            k = inv == c
            V = v * np.eye(3) + u + w**2 * np.outer(b[k], b[k])
            out -= multivariate_normal(a[k] + b[k] * m, V).logpdf(y[k])
        return out

    e, d = np.eye(4), 2e-3

    def grad(th):
        return np.array([(nll(th + d * e[i]) - nll(th - d * e[i])) / (2 * d) for i in range(4)])

    H = np.array([(grad(x1 + d * e[j]) - grad(x1 - d * e[j])) / (2 * d) for j in range(4)])
    want = np.linalg.inv(0.5 * (H + H.T))[:2, :2]
    got = np.array(pc.sampling_cov(h, x1))
    assert np.all(np.abs(got - want) <= 1e-3 * np.abs(want).max()), (got, want)
    # the variances matter here: the (mu, ln omega) block of the information alone is far off
    assert abs(np.linalg.inv(0.5 * (H + H.T)[:2, :2])[1, 1] / want[1, 1] - 1) > 0.1


def _draw_by_plant(rng, plant_of_cane, a, b, inv, mu, omega, s2, t2):
    """ln k of canes whose value is their plant's (one draw a plant), each cane's level and the noise."""
    P, C = plant_of_cane.max() + 1, len(plant_of_cane)
    return (a + b * (mu + omega * rng.normal(size=P))[plant_of_cane][inv] + rng.normal(0.0, math.sqrt(t2), C)[inv]
            + rng.normal(0.0, math.sqrt(s2), len(inv)))


def _fit_linear(h, mu, s2, t2):
    from canebench.discovery import per_cane as pc

    base = np.array([mu, -np.inf, math.log(s2), math.log(t2)])
    x0, _ = pc._fit(h, [base, base + np.array([0.0, 0.0, -1.0, 0.0])], free_omega=False)
    x1, _ = pc._fit(h, [np.array([x0[0], math.log(o), x0[2], x0[3]]) for o in (0.15, 0.5, 1.2)], free_omega=True)
    return x1


def _six_plants_sharing(seed, omega):
    """Six plants of three canes whose values are their plant's, on the linear hierarchy, fitted; and
    the Gaussian marginal -ln L of a set of canes written with scipy (``w`` holds omega, for omega = 0)."""
    from scipy.stats import multivariate_normal

    rng = np.random.default_rng(seed)
    canes, inv, b = _eighteen_canes([-0.8, -0.55, -0.3])
    a = rng.normal(0.0, 0.3, len(canes))
    plant = np.arange(18) // 3
    mu, s2, t2 = math.log(50.0), 0.05**2, 0.15**2
    y = _draw_by_plant(rng, plant, a, b, inv, mu, omega, s2, t2)
    h = _linear_hierarchy(a, b, y, canes, np.zeros((len(y), len(y))))

    def nll(th, cs, w=None):
        m, v, u = th[0], math.exp(th[-2]), math.exp(th[-1])
        w = math.exp(th[1]) if w is None else w
        return -sum(multivariate_normal(a[inv == c] + b[inv == c] * m,
                                        v * np.eye(3) + u + w**2 * np.outer(b[inv == c], b[inv == c])
                                        ).logpdf(y[inv == c]) for c in cs)

    return h, _fit_linear(h, mu, s2, t2), plant, nll


def test_the_spreads_error_clustered_by_plant_is_the_jackknife_over_the_plants():
    """:func:`clustered_cov` against the jackknife written out here: each plant's canes left out in turn,
    (mu, ln omega) refitted by another optimizer (BFGS from the full fit, gradient tolerance 1e-7) on the
    Gaussian marginal likelihood (exact where the prediction is linear in ln v, and written here with
    scipy's multivariate normal), the covariance (G - 1) / G sum of the centred estimates' outer
    products times (t_5 / z)^2 for six plants' five degrees of freedom. Each element within 0.5 % of the
    largest: the module's Nelder-Mead stops within about 1e-3 of each optimum, and each of the six
    deviations (0.05-0.28) enters squared (in development they agreed to 0.05 %; refits holding the
    variances at the full fit's were 1.85 % off). Six plants of three canes whose values are their plant's. Then
    :func:`wider_of`: each standard error the larger of the two, the information's correlation kept;
    and the cases without a clustered error (fewer than four plants; a plant list that does not fit
    the canes is an error)."""
    from scipy import stats
    from scipy.optimize import minimize

    from canebench.discovery import per_cane as pc

    h, x1, plant, nll = _six_plants_sharing(21, 0.6)
    est = []
    for k in range(6):
        res = minimize(nll, x1, args=(np.flatnonzero(plant != k),), method="BFGS", options={"gtol": 1e-7})
        est.append(res.x[:2])
    e = np.array(est) - np.mean(est, axis=0)
    t5 = (stats.t.ppf(0.975, 5) / stats.norm.ppf(0.975)) ** 2  # 2.5706 / 1.9600, squared
    want = t5 * 5 / 6 * e.T @ e
    got = np.array(pc.clustered_cov(h, x1, plant))
    assert np.all(np.abs(got - want) <= 0.005 * np.abs(want).max()), (got, want)
    # the canes share their plant's value: the information, which takes them as independent, is too small
    model = np.array(pc.sampling_cov(h, x1))
    wide = np.array(pc.wider_of(pc.sampling_cov(h, x1), pc._block(got)))
    assert np.diag(wide) == pytest.approx(np.maximum(np.diag(model), np.diag(got)), rel=1e-12)
    corr = lambda V: V[0, 1] / math.sqrt(V[0, 0] * V[1, 1])  # noqa: E731
    assert corr(wide) == pytest.approx(corr(model), rel=1e-12)
    assert pc.wider_of(pc.sampling_cov(h, x1), None) == pc.sampling_cov(h, x1)
    assert pc.clustered_cov(h, x1, np.arange(18) // 6) is None  # three plants
    with pytest.raises(ValueError, match="17 plants given for 18 canes"):
        pc.clustered_cov(h, x1, np.arange(17))


def test_a_hierarchy_without_some_canes_is_the_one_built_from_the_rest():
    """:meth:`_Hierarchy.without` (the jackknife's leave-one-plant-out) against a hierarchy built from the
    remaining canes' rows, penalty columns and caliper covariance directly: each cane's log likelihood
    and posterior the same to rounding, on canes of unequal counts with a penalty and a caliper
    covariance that differ per cane (where a column or block taken from the wrong cane would show)."""
    from canebench.discovery import per_cane as pc

    rng = np.random.default_rng(4)
    # the trials interleaved, not grouped by cane: a subset taken by cane counts would show
    canes = rng.permutation(np.repeat([f"c{i}" for i in range(6)], [3, 2, 3, 4, 3, 1]))
    n = len(canes)
    grid = np.linspace(-6.0, 6.0, pc.N_GRID)
    P = rng.normal(0.0, 0.3, n)[None, :] + rng.uniform(-0.9, -0.2, n)[None, :] * grid[:, None]
    pen = 0.05 * (grid[:, None] - rng.normal(0.0, 1.0, 6)[None, :]) ** 2
    L = rng.normal(0.0, 0.05, (n, n))
    G = L @ L.T
    y = rng.normal(-2.0, 0.5, n)
    drop = np.array([False, True, False, False, True, False])
    h = pc._Hierarchy(grid, P, pen, y, canes, G)
    keep = ~np.isin(canes, ["c1", "c4"])
    direct = pc._Hierarchy(grid, P[:, keep], pen[:, ~drop], y[keep], canes[keep], G[np.ix_(keep, keep)])
    theta = np.array([0.3, math.log(0.5), math.log(0.01), math.log(0.02)])
    got, want = h.without(drop).cane_loglik(theta), direct.cane_loglik(theta)
    assert list(h.without(drop).uniq) == ["c0", "c2", "c3", "c5"]
    for g, w in zip(got, want):
        np.testing.assert_allclose(g, w, rtol=1e-12, atol=1e-12)
    assert abs(h.cane_loglik(theta)[0][~drop] - got[0]).max() < 1e-9  # the rest's own densities unchanged


def test_a_spread_that_rests_on_one_plant_has_an_unbounded_error_taken_as_the_most_a_population_draws():
    """Six plants of three canes sharing their values, with a small spread (omega 0.25; seed 19): without
    plant 2's canes the data hold no spread. Written here with BFGS on the Gaussian marginal likelihood:
    the refit with omega free does not beat omega = 0 (its best -ln L within 1e-3 of the free one's),
    and the other five leave-outs do by more than 0.01. :func:`jackknife_over_plants` must name plant 2
    alone, give ln omega the variance :data:`COV_LN_MAX` allows, uncorrelated with mu, and give mu its
    jackknife from the refits (within 0.5 % of the one written here). Where Nelder-Mead stops in the
    flat ln omega below -8 moves with its start: the answer must not (a start 0.05 away in ln omega)."""
    from scipy import stats
    from scipy.optimize import minimize

    from canebench.discovery import per_cane as pc
    from canebench.model.effects import COV_LN_MAX

    h, x1, plant, nll = _six_plants_sharing(19, 0.25)
    mus, gains = [], []
    for k in range(6):
        cs = np.flatnonzero(plant != k)
        free = minimize(nll, x1, args=(cs,), method="BFGS", options={"gtol": 1e-7})
        null = minimize(lambda t: nll(np.r_[t[0], 0.0, t[1:]], cs, w=0.0), x1[[0, 2, 3]], method="BFGS",
                        options={"gtol": 1e-7})
        gains.append(null.fun - free.fun)
        mus.append(null.x[0] if gains[-1] < 1e-3 else free.x[0])
    assert gains[2] < 1e-3 and min(g for k, g in enumerate(gains) if k != 2) > 1e-2, gains
    t5 = (stats.t.ppf(0.975, 5) / stats.norm.ppf(0.975)) ** 2
    want_mu = t5 * 5 / 6 * np.sum((np.array(mus) - np.mean(mus)) ** 2)
    for start in (x1, x1 + np.array([0.0, 0.05, 0.0, 0.0])):
        jk = pc.jackknife_over_plants(h, start, plant)
        assert jk.lost_without == ("2",)
        V = np.array(jk.cov)
        assert V[1, 1] == COV_LN_MAX[1] and V[0, 1] == 0.0
        assert V[0, 0] == pytest.approx(want_mu, rel=5e-3)


@pytest.mark.heavy
def test_the_spreads_error_holds_where_a_plants_canes_share_their_value(seed=9):
    """Over 60 datasets of 12 plants of four canes whose values are their plant's, the fitted mu and
    ln omega scatter about twice as much as the information's error says (it takes the 48 canes as 48
    independent values; they are 12). The error the test reports (:func:`wider_of`: the information's,
    widened to the jackknife over plants, with its small-sample scaling) must match the scatter:
    each ratio of scatter to median error in [0.6, 1.5], and each information ratio above 1.6. On
    independent canes (each its own draw) the widened error must still match. The sd of 60 estimates
    is itself uncertain by 1 / sqrt(118) = 9 %; in development (seeds 9 and 3) the widened ratios were
    0.99/0.95 and 0.98/0.94 for (mu, ln omega) (session 64's sandwich: 0.99/1.15 and 0.98/1.15, its
    error of a variance running low), the information's 2.27/2.09 and 2.23/2.10, and on independent
    canes 0.92/1.05 and 0.82/1.14. The bounds do not tell the jackknife from the sandwich (that is
    :func:`test_the_spreads_error_clustered_by_plant_is_the_jackknife_over_the_plants`'s job); they
    catch an error that does not follow the plants at all. 380 s each with the two seeds run at once."""
    from canebench.discovery import per_cane as pc

    rng = np.random.default_rng(seed)
    P, per = 12, 4
    C = P * per
    canes = np.repeat([f"c{i:02d}" for i in range(C)], 3)
    inv = np.unique(canes, return_inverse=True)[1]
    b = np.tile([-0.8, -0.55, -0.3], C)
    a = rng.normal(0.0, 0.3, len(canes))
    plant = np.arange(C) // per
    mu, omega, s2, t2 = math.log(50.0), 0.6, 0.05**2, 0.15**2
    ratios = {}
    for case, of in (("shared", plant), ("independent", np.arange(C))):
        est, se_model, se_wide = [], [], []
        for _ in range(60):
            y = _draw_by_plant(rng, of, a, b, inv, mu, omega, s2, t2)
            h = _linear_hierarchy(a, b, y, canes, np.zeros((len(y), len(y))))
            x1 = _fit_linear(h, mu, s2, t2)
            model = pc.sampling_cov(h, x1)
            est.append(x1[:2])
            se_model.append(np.sqrt(np.diag(model)))
            se_wide.append(np.sqrt(np.diag(pc.wider_of(model, pc.clustered_cov(h, x1, plant)))))
        sd = np.array(est).std(axis=0, ddof=1)
        ratios[case] = (sd / np.median(se_model, axis=0), sd / np.median(se_wide, axis=0))
    assert np.all((ratios["shared"][1] > 0.6) & (ratios["shared"][1] < 1.5)), ratios
    assert np.all(ratios["shared"][0] > 1.6), ratios
    assert np.all((ratios["independent"][1] > 0.6) & (ratios["independent"][1] < 1.5)), ratios


def _simulate(at, rng, k_med, ln_sd):
    """ln k_field on the bundled canes' screen: a root per cane (ln-normal about ``k_med``), each
    cane's own level (modulus, sd 0.15 in ln), trial noise 0.05 and one draw of the caliper lines'
    error (the same law the test's G is built from), as real data carry it."""
    from canebench.discovery.adequacy import geometry_draws

    uniq, inv = np.unique(at.screen.canes, return_inverse=True)
    kc = k_med * np.exp(ln_sd * rng.normal(size=len(uniq)))
    y = np.empty(len(inv))
    for c in range(len(uniq)):
        y[inv == c] = at.predict((EffectSpec.parse(f"root_compliance(k_root={kc[c]})"),))[inv == c]
    g = geometry_draws(at, (EffectSpec.parse(f"root_compliance(k_root={k_med})"),), n_draws=1,
                       seed=int(rng.integers(2**31)))[0]
    y += rng.normal(0.0, 0.15, len(uniq))[inv] + rng.normal(0.0, 0.05, len(y)) - g
    return y, dict(zip(uniq, kc))


def _test(at, y):
    from canebench.discovery.fit import Candidate, fit_candidate
    from canebench.discovery.per_cane import PER_CANE_ALPHA, per_cane_test

    fit = fit_candidate(Candidate.of(("root_compliance",)), at, y)
    return per_cane_test(at, y, fit.specs, "root_compliance", PER_CANE_ALPHA, 0.05, s2=fit.s2, t2=fit.t2)


def test_the_per_cane_test_clusters_the_spreads_error_over_the_plants_it_is_given(bundled_screen, monkeypatch):
    """``per_cane_test`` with each cane's plant (the bundled canes' bushes: six of three canes): it records
    the number of plants, the information's and the clustered covariances, and reports the wider of
    them (:func:`wider_of`), in its dict too; without plants, or with a plant map that misses a cane, the
    information's alone. The fit itself does not depend on the plants."""
    from canebench.discovery import per_cane as pc
    from canebench.discovery.fit import Candidate, fit_candidate

    y, _ = _simulate(bundled_screen, np.random.default_rng(5), 20.0, 0.7)
    fit = fit_candidate(Candidate.of(("root_compliance",)), bundled_screen, y)
    canes = sorted(set(bundled_screen.screen.canes))
    plants = {c: c.split("c")[0] for c in canes}
    assert len(set(plants.values())) == 6

    def run(pl):
        return pc.per_cane_test(bundled_screen, y, fit.specs, "root_compliance", pc.PER_CANE_ALPHA, 0.05,
                                s2=fit.s2, t2=fit.t2, plants=pl)

    seen = []
    real = pc.jackknife_over_plants

    def spy(h, theta, of):  # what the test hands the jackknife: each cane's own bush, in h's order
        seen.append((list(h.uniq), list(of)))
        return real(h, theta, of)

    monkeypatch.setattr(pc, "jackknife_over_plants", spy)
    t, t0 = run(plants), run(None)
    assert len(seen) == 1 and seen[0][1] == [plants[c] for c in seen[0][0]] and len(seen[0][0]) == len(t.values)
    assert t.ln_sd > 0 and t.n_plants == 6 and t.cov_ln_plants is not None
    assert t.cov_ln_plants != t.cov_ln_model and t.spread_lost_without == ()
    assert t.cov_ln == pc.wider_of(t.cov_ln_model, t.cov_ln_plants) and t.cov_ln_model == t0.cov_ln_model
    assert (t.median, t.ln_sd, t.lr, t.values) == (t0.median, t0.ln_sd, t0.lr, t0.values)
    assert t0.n_plants is None and t0.cov_ln_plants is None and t0.cov_ln == t0.cov_ln_model
    d = json.loads(json.dumps(t.to_dict()))
    assert d["n_plants"] == 6 and d["cov_ln_information"] == [list(r) for r in t.cov_ln_model]
    assert d["cov_ln_clustered_by_plant"] == [list(r) for r in t.cov_ln_plants]
    assert d["spread_lost_without_plants"] == []
    assert d["cov_ln_median_ln_sd"] == [list(r) for r in t.cov_ln]
    missing = run({c: p for c, p in plants.items() if c != canes[0]})
    assert missing.n_plants is None and missing.cov_ln == t0.cov_ln


def test_a_global_root_stays_global_and_a_root_per_cane_is_found_with_each_canes_value(bundled_screen):
    """On the 18 bundled canes' screen (three pushes a cane), with each cane's own level and the
    caliper lines' error in the data: a root of one stiffness for every cane (20 N m/rad) is called
    per cane in at most 1 of 20 datasets at the workflow's level of 0.01 (more than 1 would be P <
    0.02 at a true rate of 1 %); roots scattered by 0.7 in ln between canes are found in at least 7 of
    10 (17 of 20 in development, P(<= 6 of 10) = 0.05 at that rate) and each found cane's value
    follows its true one (r >= 0.75 in ln: the shrinkage and three pushes a cane leave about 0.3 in
    ln of error on a spread of 0.7)."""
    rng = np.random.default_rng(2026)
    null = [_test(bundled_screen, _simulate(bundled_screen, rng, 20.0, 0.0)[0]) for _ in range(20)]
    assert sum(t.per_cane for t in null) <= 1, [t.p for t in null]
    found = 0
    for _ in range(10):
        y, truth = _simulate(bundled_screen, rng, 20.0, 0.7)
        t = _test(bundled_screen, y)
        if t.per_cane:
            found += 1
            c = sorted(truth)
            r = np.corrcoef(np.log([t.values[k] for k in c]), np.log([truth[k] for k in c]))[0, 1]
            assert r >= 0.75, (r, t.reason)
            assert t.spec(EffectSpec.parse("root_compliance(k_root=20)")).scope == "per_cane"
    assert found >= 7


def test_a_per_cane_value_reaches_each_canes_trials_through_the_model_file(tmp_path):
    """A per-cane effect's spec gives each cane its own value and keeps the global fit's for a cane
    not in the data (the value the engines confirm, with its interval); the model file carries both,
    and each trial's configuration (what every backend compiles) holds its cane's value."""
    from canebench.discovery.per_cane import PerCaneTest
    from canebench.model.modelfile import load_model_file, write_model_file
    from canebench.model.presets import PRESETS

    t = PerCaneTest("root_compliance", "k_root", "N m/rad", 21.0, 0.6, 12.0, 1e-4, 0.01, 0.2, True,
                    {"b1c1": 8.0, "b1c2": 55.0}, {"b1c1": 0.3, "b1c2": 0.4})
    spec = t.spec(EffectSpec.parse("root_compliance(k_root=20)"))
    assert spec.scope == "per_cane" and dict(spec.params) == {"k_root": 20.0}
    cfg = PRESETS["beam-consistent"].replace(effects=(spec,))
    f = write_model_file(tmp_path / "model.yaml", cfg, "beam-consistent")
    back = load_model_file(f)
    assert back.effects[0].scope == "per_cane"
    # and the hierarchy's median and spread, what a population export draws a new cane's value from
    assert back.effects[0].between == (("k_root", (21.0, 0.6, None)),)
    for cane, k in (("b1c1", 8.0), ("b1c2", 55.0), ("b9c9", 20.0)):
        (e,) = back.localized(cane, f"{cane}t1").effects
        assert e.instance().root_compliance() == pytest.approx(1.0 / k)
    # not per cane: the spec is the global one, unchanged
    t.per_cane = False
    assert t.spec(EffectSpec.parse("root_compliance(k_root=20)")) == EffectSpec.parse("root_compliance(k_root=20)")


def test_a_collar_per_cane_is_scored_against_each_canes_calipers(bundled_screen):
    """A flare's per-cane test carries each cane's calipers: each cane's tabulated penalty is the
    screen's own caliper penalty (:meth:`ScreenSet.caliper_nll`, written separately) of that cane's
    trials, at every value; one flare of 6 mm over 200 mm for all canes stays global, and a collar scattered by 0.7
    in ln between canes is found, its canes' values following the truth."""
    from canebench.discovery.adequacy import geometry_draws
    from canebench.discovery.fit import Candidate, fit_candidate
    from canebench.discovery.per_cane import PER_CANE_ALPHA, _tables, per_cane_test
    from canebench.model.effects import AppliedEffects

    at = bundled_screen
    spec = EffectSpec.parse("base_flare(excess_mm=6, length_mm=200)")
    grid, _, pen = _tables(at, (), spec, "excess_mm")
    uniq, inv = np.unique(at.screen.canes, return_inverse=True)
    for j in (0, 160, 300):
        fx = AppliedEffects([EffectSpec.parse(f"base_flare(excess_mm={np.exp(grid[j])}, length_mm=200)").instance()])
        for k, c in enumerate(uniq):  # each cane's column: its own calipers, counted once
            assert pen[j, k] == pytest.approx(at.screen.subset(at.screen.canes == c).caliper_nll(fx), rel=1e-12)
    rng = np.random.default_rng(11)
    found = {}
    for ln_sd in (0.0, 0.7):
        ex = 6.0 * np.exp(ln_sd * rng.normal(size=len(uniq)))
        y = np.empty(len(inv))
        for c in range(len(uniq)):
            y[inv == c] = at.predict((EffectSpec.parse(f"base_flare(excess_mm={ex[c]}, length_mm=200)"),))[inv == c]
        g = geometry_draws(at, (spec,), n_draws=1, seed=5)[0]
        y += rng.normal(0.0, 0.15, len(uniq))[inv] + rng.normal(0.0, 0.05, len(y)) - g
        fit = fit_candidate(Candidate.of(("base_flare",)), at, y)
        t = per_cane_test(at, y, fit.specs, "base_flare", PER_CANE_ALPHA, 0.05, s2=fit.s2, t2=fit.t2)
        found[ln_sd] = t
        if t.per_cane:
            r = np.corrcoef(np.log([t.values[k] for k in uniq]), np.log(ex))[0, 1]
            assert r >= 0.6, r
    assert not found[0.0].per_cane, found[0.0].reason
    assert found[0.7].per_cane, found[0.7].reason


def test_only_effects_that_can_be_a_canes_own_are_tested():
    """A root and a collar may differ per cane; a rig, a probe mount and the trial's obstruction may
    not, and a modulus scale per cane is the fit's own random level."""
    from canebench.discovery.per_cane import varying_parameter

    assert varying_parameter("root_compliance") == "k_root"
    assert varying_parameter("base_flare") == "excess_mm"
    for name in ("modulus_scale", "rig_compliance", "probe_misalignment", "obstruction"):
        assert varying_parameter(name) is None


def test_the_scope_is_worded_for_the_cli_and_the_report():
    from canebench.discovery.checks_text import scope_text

    assert scope_text({"params": {}}) == ""
    per = {"per_cane_test": {"per_cane": True, "parameter": "k_root", "unit": "N m/rad", "p": 2e-5, "alpha": 0.01,
                             "ln_sd_between_canes": 0.74, "values": {"a": 8.1, "b": 95.0},
                             "spread_mean_abs_ln_k": 0.2}}
    assert scope_text(per) == "per cane: k_root 8.1 to 95 N m/rad over 2 canes (ln sd 0.74; p = 2e-05)"
    # with the spread's sampling covariance, ln omega's standard error as a relative error of omega
    per["per_cane_test"]["cov_ln_median_ln_sd"] = [[0.01, 0.0], [0.0, 0.0289]]
    assert scope_text(per) == "per cane: k_root 8.1 to 95 N m/rad over 2 canes (ln sd 0.74 +- 17 %; p = 2e-05)"
    one = {"per_cane_test": {"per_cane": False, "p": 0.41, "alpha": 0.01, "spread_mean_abs_ln_k": 0.0}}
    assert scope_text(one) == "one value for all canes (per-cane test: p = 0.41)"
    # and discovery's note names what a population draws from, with the errors where known
    from canebench.discovery.per_cane import PerCaneTest
    from canebench.discovery.workflow import per_cane_note

    t = PerCaneTest("root_compliance", "k_root", "N m/rad", 21.0, 0.6, 12.0, 1e-4, 0.01, 0.2, True,
                    {"b1c1": 8.0, "b1c2": 55.0}, {"b1c1": 0.3, "b1c2": 0.4}, "varies")
    assert per_cane_note({"root_compliance": t}).endswith(
        "from median 21 and ln sd 0.60 (between_canes); their sampling error is not known (the hierarchy's "
        "information is not positive definite: the spread is not pinned apart from the canes' own levels), so a "
        "population draws from them as if exact")
    t.cov_ln = ((0.0049, 0.0), (0.0, 0.0625))
    assert per_cane_note({"root_compliance": t}).endswith(
        "(between_canes), each first drawn within its sampling error (standard errors 0.07 in ln median, "
        "0.25 in ln ln sd)")
    assert t.spec(EffectSpec.parse("root_compliance(k_root=20)")).between[0][1].cov_ln == t.cov_ln
    # a spread known worse than the model file allows (ln ln sd's standard error 0.6 > 0.5) is drawn within
    # the most it allows (its variance cut to 0.25, the correlation kept), never as if exact
    t.cov_ln = ((0.0049, 0.021), (0.021, 0.36))
    assert per_cane_note({"root_compliance": t}).endswith(
        "(standard errors 0.07 in ln median, 0.60 in ln ln sd; a population draws within 0.07 and 0.50, the most it "
        "allows, as its spread can overflow beyond)")
    cut = t.spec(EffectSpec.parse("root_compliance(k_root=20)")).between[0][1].cov_ln
    assert cut[1][1] == 0.25 and cut[0][0] == 0.0049
    assert cut[0][1] / math.sqrt(cut[0][0] * cut[1][1]) == pytest.approx(0.021 / math.sqrt(0.0049 * 0.36), rel=1e-12)
    t.cov_ln = ((4.0, 0.0), (0.0, 1.0))  # both cut
    assert t.drawable_cov() == ((1.0, 0.0), (0.0, 0.25))
    t.cov_ln = ((float("nan"), 0.0), (0.0, 0.01))  # not a covariance: none, and the note says so
    assert t.drawable_cov() is None and "not a covariance a population can draw within" in per_cane_note(
        {"root_compliance": t})
    # the clustering by plant: the note names only the error it widened, and from what
    t.cov_ln_model, t.n_plants = ((0.0225, 0.001), (0.001, 0.0289)), 6
    t.cov_ln = ((0.0484, 0.0015), (0.0015, 0.0289))
    assert per_cane_note({"root_compliance": t}).endswith(
        "(standard errors 0.22 in ln median, 0.17 in ln ln sd; clustered by plant (a jackknife over 6 plants), which widened "
        "ln median from 0.15)")
    t.cov_ln = ((0.0484, 0.002), (0.002, 0.04))
    assert "which widened ln median from 0.15 and ln ln sd from 0.17)" in per_cane_note({"root_compliance": t})
    # a spread that rests on one plant: its error unbounded, taken as the bound, and the plant named
    t.cov_ln, t.spread_lost_without = ((0.0484, 0.0), (0.0, 0.25)), ("3",)
    assert per_cane_note({"root_compliance": t}).endswith(
        "which widened ln median from 0.15 and ln ln sd from 0.17; without the canes of plant 3 no spread is found, "
        "so ln ln sd's error has no bound and is taken as 0.50, the most a population draws within)")


@pytest.mark.heavy
def test_discover_gives_each_cane_its_own_root_where_the_generator_hides_one_per_cane(tmp_path):
    """The generator's exact rod with each cane's root drawn about 20 N m/rad (ln sd 0.7): the
    root is named, per cane, with each cane's value following the truth (r >= 0.6 in ln; 0.79 in
    development), the model file carrying them; the same dataset with one root for all canes keeps
    it global. The scope changes no name, interval or gap (the global fit's), and the engines and the
    provenance hold the global model."""
    from canebench.canes.generate_hidden import generate_hidden
    from canebench.data.dataset import load_dataset
    from canebench.discovery.workflow import discover
    from canebench.execute.executors import make_executor
    from canebench.model.effects import COV_LN_MAX
    from canebench.model.modelfile import load_model_file

    out = {}
    for tag, eff in (("per_cane", {"k_root": 20.0, "ln_sd": 0.7}), ("one", {"k_root": 20.0})):
        d = generate_hidden(tmp_path / tag, 101, {"root_compliance": eff})
        res = discover(load_dataset(d), confirm=False, executor=make_executor("serial", 1, None), n_boot=40,
                       seed=101, out=tmp_path / f"out_{tag}")
        out[tag] = (res, json.loads((d / "truth" / "truth.json").read_text()))
    res, truth = out["per_cane"]
    (root,) = [n for n in res.named if n["effect"] == "root_compliance"]
    assert root["scope"] == "per_cane", root["per_cane_test"]
    c = sorted(root["local"])
    r = np.corrcoef(np.log([root["local"][k]["k_root"] for k in c]),
                    np.log([truth["canes"][k]["k_root"] for k in c]))[0, 1]
    assert r >= 0.6
    cfg = load_model_file(tmp_path / "out_per_cane" / "model.yaml")
    (e,) = [s for s in cfg.effects if s.name == "root_compliance"]
    assert e.scope == "per_cane" and set(dict(e.local)) == set(c)
    pct = root["per_cane_test"]
    ((name, spread),) = e.between
    assert name == "k_root" and spread.median == pytest.approx(pct["median"])
    assert spread.ln_sd == pytest.approx(pct["ln_sd_between_canes"])
    # the model file's covariance is the reported one, each variance cut to what a population draws within
    cov = np.array(pct["cov_ln_median_ln_sd"])
    assert np.diag(np.array(spread.cov_ln)) == pytest.approx(np.minimum(np.diag(cov), COV_LN_MAX), rel=1e-12)
    # the workflow passed each cane's bush: the error clustered over the dataset's plants, the reported one
    # the wider of it and the information's
    assert pct["n_plants"] == len({k.split("c")[0] for k in c}) >= 4
    info, clus = np.array(pct["cov_ln_information"]), np.array(pct["cov_ln_clustered_by_plant"])
    assert np.diag(cov) == pytest.approx(np.maximum(np.diag(info), np.diag(clus)), rel=1e-9)
    # with the spread's sampling covariance: a standard error of ln omega near 1 / sqrt(2 (C - 1)), its
    # value for C canes' exact values (0.17 at 18); noisier pushes make it larger, not under half of it
    se_ln_sd = math.sqrt(pct["cov_ln_median_ln_sd"][1][1])
    assert 0.5 / math.sqrt(2 * (len(c) - 1)) < se_ln_sd < 1.0, se_ln_sd
    # beside them the global fit's value, which a cane not in the data takes; the engines ran that
    # global model, and the provenance records it (no canes' values)
    assert dict(e.params)["k_root"] == pytest.approx(root["params"]["k_root"])
    assert cfg.localized("b9c9", "b9c9t1").effects[0].instance().root_compliance() == pytest.approx(
        1.0 / root["params"]["k_root"])
    doc = json.loads((tmp_path / "out_per_cane" / "discovery.json").read_text())
    prov = [x for x in doc["provenance"]["model_config"]["effects"] if x["effect"] == "root_compliance"]
    assert prov and "local" not in prov[0] and prov[0]["scope"] == "global"
    res1, _ = out["one"]
    (root1,) = [n for n in res1.named if n["effect"] == "root_compliance"]
    assert root1["scope"] == "global" and not root1["per_cane_test"]["per_cane"]
