"""The adequacy check with the caliper-fit geometry's own error in its null.

The check asks whether the held-out residual trends with the model's own
stiffness level between canes (:func:`.structure.level_trend` is its plain
permutation form). Level and residual are not independent under a correct
model: both carry the error of the cane's caliper-fit line. A line that reads
a cane too thick raises the model's ln k by g and lowers the residual by the
same g, so r is biased negative by var(g); with three calipers near the push
points the line is extrapolated a metre down to the base, where the bending
moment is largest, and g is a few tenths in ln k (as large as the canes' own
modulus scatter). A permutation null ignores this and flags correct models.

The null here is a parametric bootstrap of that error, from the data:

* each cane's line error (centroid diameter, slope) is drawn from the
  calipers' pooled scatter about the lines (:attr:`ScreenSet.cal_sigma`) and
  the cane's own caliper positions (least-squares covariance), and the
  model's ln k recomputed on the screen with the perturbed line: g per trial;
* cane-mean residual* = b + e - g and level* = L + g, with the trial noise e
  from the within-cane residual variance, the canes' own offsets b from what
  remains of the between-cane variance, and L the observed cane-mean level
  shrunk about its mean by the error's share of its variance (the observed
  level already carries one line error);
* the observed r is placed in the distribution of r*.

The geometry share is bounded by the data: residual = b + e - g with
independent parts, so var(g) cannot exceed the cane means' variance less the
trial noise's share. Where the calipers' scatter says more (real calipers
read bud bumps and ovality, not only line error) g is scaled down to that
bound and the canes' own offsets get nothing: the null that gives the line
error the largest share the data allow, the one most lenient to the model
(``geometry_bounded``). The bound is taken from the residual's own spread,
trend included, so in that regime the check has little power. On the real
field data it binds (the calipers scatter 1.06 mm about the lines).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..model.effects import EffectSpec
from .screenset import Anchored

N_DRAWS = 2000
#: the share of canes (rounded down) whose residual scatters most, left out of the pooled
#: within-cane spreads :func:`within_dispersion` compares (see :func:`_trimmed_spreads`)
TRIM_SHARE = 0.1


def _corr(a: np.ndarray, b: np.ndarray) -> float:
    """Pearson r of two (n,) arrays; 0 where either is constant."""
    a = a - a.mean()
    b = b - b.mean()
    den = np.sqrt((a @ a) * (b @ b))
    return float(a @ b / den) if den > 0 else 0.0


def _row_corr(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Pearson r of each row of ``a`` (draws, n) with ``b``: the same rows of a (draws, n) array, or one (n,)."""
    ac = a - a.mean(axis=1, keepdims=True)
    bc = b - b.mean(axis=-1, keepdims=True)
    return np.sum(ac * bc, axis=1) / np.sqrt(np.sum(ac**2, axis=1) * np.sum(bc**2, axis=-1))


def _two_sided_p(null: np.ndarray, obs: float) -> float:
    """Two-sided Monte Carlo p of ``obs`` in the null's draws (+1 in both counts), at most 1."""
    B = len(null)
    return float(min(1.0, 2.0 * min((np.sum(null <= obs) + 1) / (B + 1), (np.sum(null >= obs) + 1) / (B + 1))))


def geometry_draws(at: Anchored, specs: tuple[EffectSpec, ...], factor: float = 1.0,
                   n_draws: int = N_DRAWS, seed: int = 0) -> np.ndarray:
    """(n_draws, n_trials): the model's change in ln k when each cane's caliper line is off by its own error.

    The line d(s) = d_c + factor b (s - s_c) (:class:`~canebench.model.diameter.DiameterFit`)
    through n readings with scatter sigma has independent errors sigma / sqrt(n) at the
    centroid s_c and sigma / sqrt(sum (s - s_c)^2) in the slope. A cane with calipers at one
    place only gets the centroid error.
    """
    rng = np.random.default_rng(seed)
    ss = at.screen
    n = len(ss.trials)
    uniq, cane_of_trial = np.unique(ss.canes, return_inverse=True)
    sc = np.zeros(len(uniq))
    sd_c = np.zeros(len(uniq))
    sd_b = np.zeros(len(uniq))
    for k in range(len(uniq)):
        first = int(np.flatnonzero(cane_of_trial == k)[0])
        s = ss.cal_s[ss.cal_idx == first]  # every trial carries its cane's calipers
        if len(s) == 0:
            continue
        sc[k] = float(s.mean())
        sxx = float(np.sum((s - sc[k]) ** 2))
        sd_c[k] = ss.cal_sigma / math.sqrt(len(s))
        sd_b[k] = ss.cal_sigma / math.sqrt(sxx) if sxx > 1e-12 else 0.0
    k_q = cane_of_trial[ss.idx]
    lk0 = at.predict(specs)
    out = np.empty((n_draws, n))
    for b in range(n_draws):
        dc = rng.normal(0.0, 1.0, len(uniq)) * sd_c
        db = rng.normal(0.0, 1.0, len(uniq)) * sd_b
        d0 = ss.d0 + dc[k_q] + factor * db[k_q] * (ss.s - sc[k_q])
        out[b] = at.with_diameters(d0).predict(specs) - lk0
    return out


def level_trend_geometry(canes: np.ndarray, resid: np.ndarray, level: np.ndarray, g: np.ndarray,
                         seed: int = 0) -> dict[str, float]:
    """Between-cane r of the cane-mean residual with the cane-mean level, against the geometry null.

    Parameters
    ----------
    canes, resid, level : arrays (n,)
        Cane of each trial, held-out ln k_field / k_model, the model's held-out ln k.
    g : array (draws, n)
        :func:`geometry_draws` for the same trials.

    Returns
    -------
    dict
        ``r``; two-sided ``p`` of r in the null's distribution; ``null_median`` (the bias a
        permutation null ignores); ``geometry_sd`` (the cane means' share, after the bound);
        ``geometry_bounded`` (the calipers' scatter said more than the data allow, and the
        null gives all of the between-cane spread to the line error: its most lenient form, in
        which the check has little power); ``n_trials_left_out`` (no finite residual, level or
        geometry draw); ``n_canes``.
    """
    # a draw the screen could not evaluate (a perturbed line past a series compliance) would
    # poison every null r: such a trial is left out, and counted
    ok = np.isfinite(resid) & np.isfinite(level) & np.all(np.isfinite(g), axis=0)
    left_out = int(np.sum(~ok))
    canes, resid, level, g = canes[ok], resid[ok], level[ok], g[:, ok]
    uniq, inv = np.unique(canes, return_inverse=True)
    cnt = np.bincount(inv).astype(float)
    C = len(uniq)
    if C < 4:
        return {"r": math.nan, "p": 1.0, "null_median": math.nan, "geometry_sd": math.nan, "geometry_bounded": False,
                "n_trials_left_out": left_out, "n_canes": int(C)}
    rm = np.bincount(inv, resid) / cnt
    lm = np.bincount(inv, level) / cnt
    obs = _corr(rm, lm)
    dfw = len(resid) - C
    s2 = float(np.sum((resid - rm[inv]) ** 2) / dfw) if dfw > 0 else 0.0
    gm = np.stack([np.bincount(inv, gb, minlength=C) for gb in g]) / cnt  # (draws, C)
    vg = float(np.mean(gm.var(axis=0)))
    room = max(0.0, float(np.var(rm)) - s2 * float(np.mean(1.0 / cnt)))
    bounded = vg > room
    if bounded:  # the data bound the geometry's share (module docstring)
        gm = gm * math.sqrt(room / vg) if vg > 0 else gm
        vg = room
    tau2 = max(0.0, room - vg)
    rng = np.random.default_rng(seed)
    res = (rng.normal(0.0, math.sqrt(tau2), gm.shape) + rng.normal(0.0, 1.0, gm.shape) * np.sqrt(s2 / cnt)
           - gm)
    # the observed level already carries one line error: its true part has var(lm) - var(g), so
    # level* = that part + g* has the observed spread (lm + g* would double the error's share)
    vl = float(np.var(lm))
    shrink = math.sqrt(max(0.0, vl - vg) / vl) if vl > 0 else 0.0
    lev = (lm.mean() + shrink * (lm - lm.mean()))[None, :] + gm
    null = _row_corr(res, lev)
    return {"r": obs, "p": _two_sided_p(null, obs), "null_median": float(np.median(null)),
            "geometry_sd": math.sqrt(vg), "geometry_bounded": bool(bounded), "n_trials_left_out": left_out,
            "n_canes": int(C)}


def within_trend_geometry(canes: np.ndarray, resid: np.ndarray, position: np.ndarray, g: np.ndarray,
                          seed: int = 0, reuse: int = 10) -> dict[str, float]:
    """Within-cane r of the held-out residual with the push's position, against the geometry null.

    Every library effect leaves a cane's pushes in the proportions its physics gives them, and
    a model that fits must leave no trend with height along a cane: each cane's own modulus
    and offset drop out of within-cane contrasts, so this check sees what the level trend
    (between canes) cannot, an effect that acts on part of a cane (a weak zone between the
    push points softens the pushes above it and spares those below). The within-cane
    deviations of the residual are correlated with those of ``position`` (pooled over
    canes). Under a correct model they are trial noise plus the caliper line's own error,
    which moves a cane's low and high pushes differently (the line's slope error is
    extrapolated to the base): the null draws that error from ``g`` (:func:`geometry_draws`,
    within-cane deviations), and trial noise from what the residual's within-cane variance
    leaves (the geometry's share bounded by it, as in :func:`level_trend_geometry`). Each
    geometry draw is used ``reuse`` times with fresh noise (noise is cheap, the draws are
    not), so the null has ``reuse`` x draws values. Where the geometry's share is bounded
    (it takes all the within-cane variance, as on the real data) there is no noise left and
    the copies are the same: the null then has the draws' 2000 distinct values, which still
    resolve p = 0.001 (beyond every draw).

    Returns
    -------
    dict
        ``r``, two-sided ``p``, ``null_sd`` (spread of the null's r), ``geometry_bounded``,
        ``n_trials``, ``n_canes``; and the two spreads :func:`within_dispersion` compares:
        ``sd``, the residual's pooled within-cane standard deviation (n - canes degrees of
        freedom), and ``geometry_sd``, the same of the caliper line's error alone (the draws',
        before any bound), both over the canes :func:`_trimmed_spreads` keeps (those it leaves
        out in ``sd_trimmed_canes``); ``sd_all`` and ``geometry_sd_all`` over every cane.
    """
    ok = np.isfinite(resid) & np.isfinite(position) & np.all(np.isfinite(g), axis=0)
    canes, resid, position, g = np.asarray(canes)[ok], resid[ok], position[ok], g[:, ok]
    uniq, inv = np.unique(canes, return_inverse=True)
    cnt = np.bincount(inv).astype(float)
    C, n = len(uniq), len(resid)
    out = {"r": math.nan, "p": 1.0, "null_sd": math.nan, "geometry_bounded": False, "n_trials": int(n),
           "n_canes": int(C), "sd": math.nan, "geometry_sd": math.nan}
    dfw = n - C
    if C < 4 or dfw < 4:  # as the level trend: too few canes to say anything
        return out

    onehot = np.zeros((n, C))
    onehot[np.arange(n), inv] = 1.0

    def within(a: np.ndarray) -> np.ndarray:  # deviations from each cane's mean (last axis: trials)
        a2 = np.atleast_2d(a)
        # one product for every row (the null's copies are tens of thousands of rows, and the
        # structure table calls this once per feature)
        means = (a2 @ onehot) / cnt
        return (a2 - means[:, inv]).reshape(a.shape)

    rw, xw = within(resid), within(position)
    s2 = float(rw @ rw) / dfw
    gw = np.tile(within(g), (max(1, int(reuse)), 1))
    vg = float(np.mean(np.sum(gw**2, axis=1))) / dfw
    out.update(_trimmed_spreads(uniq, inv, cnt, rw, gw), sd_all=math.sqrt(s2), geometry_sd_all=math.sqrt(vg))
    if not (np.any(xw != 0) and np.any(rw != 0)):
        return out
    obs = _corr(rw, xw)
    bounded = vg > s2
    if bounded:
        gw = gw * math.sqrt(s2 / vg)
        vg = s2
    rng = np.random.default_rng(seed)
    noise = within(rng.normal(0.0, math.sqrt(max(0.0, s2 - vg)), gw.shape))
    null = _row_corr(noise - gw, xw)
    out.update(r=obs, p=_two_sided_p(null, obs), null_sd=float(np.std(null)), geometry_bounded=bool(bounded))
    return out


def _trimmed_spreads(uniq: np.ndarray, inv: np.ndarray, cnt: np.ndarray, rw: np.ndarray, gw: np.ndarray) -> dict[str, Any]:
    """Pooled within-cane spreads of the residual and of the geometry draws, the worst canes left out.

    The library holds a per-trial effect that can be invisible: an obstruction engaged from
    contact leaves no elbow to find, only one push reading several times stiffer than its
    cane's others. One such trial lifted our self-test's pooled spread 16-23 times the
    calipers' (seed 7, obstruction sets 25-27, one trial each), which no model of the cane
    can be blamed for. So the :data:`TRIM_SHARE` of canes (at least one once there are ten)
    whose residual scatters most are left out of both pools (residual and geometry alike, so
    the ratio compares the same canes); an effect that acts along every cane (a neighbour's
    lateral support, 20.6 times on an independent generator's data) is untouched by it.
    Below ten canes of two pushes or more nothing is left out, and one such push still fails
    the model. The canes are picked by the residual alone, so under a correct model the
    trimmed ratio runs lower than the whole one (about 9 % on 15 canes of 3 pushes, an
    independent review's simulation); the allowance was measured on the trimmed ratio.
    """
    C = len(cnt)
    ss = np.bincount(inv, rw**2, minlength=C)
    # canes ranked by their own variance (a cane of more pushes is not worse for having more), a
    # tenth of those that have one (a single push has no spread to trim)
    spread = ss / np.maximum(cnt - 1.0, 1.0)
    n_trim = int(np.sum(cnt > 1) * TRIM_SHARE)
    drop = np.argsort(spread)[::-1][:n_trim] if n_trim else np.array([], int)
    keep = np.ones(C, bool)
    keep[drop] = False
    dfk = float(np.sum(cnt[keep]) - np.sum(keep))
    if dfk < 4:  # too few pushes left: use every cane
        keep[:], drop = True, np.array([], int)
        dfk = float(np.sum(cnt) - C)
    kt = keep[inv]
    return {"sd": math.sqrt(float(np.sum(ss[keep])) / dfk),
            "geometry_sd": math.sqrt(float(np.mean(np.sum(gw[:, kt] ** 2, axis=1))) / dfk),
            "sd_trimmed_canes": [str(uniq[i]) for i in drop]}


def within_dispersion(within: dict[str, Any], factor: float, material: float) -> dict[str, Any]:
    """Does the residual scatter between a cane's own pushes more than the model's errors can make it?

    The trend check (:func:`within_trend_geometry`) sees an effect that moves a cane's low and
    high pushes apart the same way on every cane; an effect whose pattern along the cane
    changes sign from cane to cane cancels there (a neighbouring cane touching above the
    pushes on one cane and below them on the next: it stiffens the nearest push most). It
    shows as size: the residual's within-cane spread ``sd`` far beyond what the geometry's
    error puts there. The caliper line's error alone (``geometry_sd``) is a lower bound of
    that: a taper that curves below the lowest caliper adds to it and the calipers do not
    see it. Both spreads are pooled over the canes :func:`_trimmed_spreads` keeps (one
    obstructed push must not condemn the model). Across the nulls and library effects of three
    generators (power-law tapers of exponent 0.4-2.2 among them) and the real field trials the
    ratio sd / geometry_sd over every cane was at most 4.1 with a perpendicular or held probe
    (real: 3.0) and 5.6 with a pitched probe sliding in its U (a contact the library's pitch
    does not model); an independent generator's lateral support gave 20.6. Trimmed, the
    independent generator's sets reach 3.6 and 5.0, the real trials 2.8, its lateral support
    18.7. ``factor`` is that allowance, and ``material`` keeps a
    scatter of a few per cent, which trial noise no geometry carries makes (a probe's pitch
    jitter), from failing the model where the line's share all but vanishes (a soft root
    taking most of the compliance).

    Returns
    -------
    dict
        ``sd``, ``geometry_sd``, ``ratio``, ``factor``, ``material`` and ``fails``.
    """
    sd, gsd = float(within.get("sd", math.nan)), float(within.get("geometry_sd", math.nan))
    ratio = sd / gsd if np.isfinite(sd) and np.isfinite(gsd) and gsd > 0 else math.nan
    fails = bool(np.isfinite(ratio) and ratio > factor and sd >= material)
    return {"sd": sd, "geometry_sd": gsd, "ratio": ratio, "factor": float(factor), "material": float(material),
            "fails": fails}
