"""Which trial features carry the residual, and how strongly (tests grouped by cane).

A residual r (ln k_field/k_model, before or after an effect) is split into its cane
means (between canes) and the deviations from them (within canes). Each
feature is split the same way and correlated with the matching part:

* between: Pearson r of cane-mean residual on cane-mean feature; null by
  permuting the canes' means (canes are the independent units);
* within: Pearson r of the deviations; null by permuting trials within each
  cane (a cane's offset is never mistaken for a height effect); given the
  model's geometry draws, a row must also beat the caliper line's own error,
  which moves a cane's pushes apart along it (:func:`structure_tests`).

p-values are Bonferroni-adjusted over all tests in the table. The share of
the residual variance between canes is reported beside it. Every row but the
trace curvature's can flag the model (:data:`NOT_JUDGED`, :func:`structure_flags`).

:func:`level_trend` is the model's adequacy check, the residual-versus-fitted
plot of regression diagnostics made into one pre-declared test: do the canes
the model calls soft keep measuring stiffer (or softer) than it predicts?
Every library effect has its own scaling across canes (a modulus scale
none, a flare's extra millimetres ~1/d, a root or rig spring the more the
stiffer the cane); a missing effect whose stiffening goes as the cane's own
compliance (a neighbour's lateral support, ~1/EI) is absorbed only in part
by the nearest of them (a flare takes its mean and its height pattern) and
leaves a trend. Not every such trend: a modulus scale above 1 with a root or
rig spring also stiffens soft canes relatively more, so the pair step can
absorb part of it; the check is then weaker, not wrong. The model's level
and the residual share the error of the caliper-fit geometry, which biases r
negative (see ``ADEQUACY_ALPHA`` in :mod:`.verdict` for its measured size).
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from .adequacy import _corr, level_trend_geometry, within_trend_geometry

N_PERM = 2000

FEATURES = {
    "height_m": "push height above the base",
    "s_push_m": "arc length to the push point",
    "rel_push": "push arc length / cane length",
    "diameter_mm": "diameter at the push point (caliper fit)",
    "above_lowest_caliper_m": "arc length from the lowest caliper up to the push point",
    "log_k_model": "stiffness level (the model's own ln k; the field's would contain the residual)",
    "curvature": "trace curvature: slope of the second half / first half of contact",
    "trial_no": "position of the push point on the cane (1 = highest)",
}


#: features tested within canes only: their cane means differ only through missing trials (the
#: push point's place) or carry nothing between canes (the trace's curvature)
WITHIN_ONLY = ("trial_no", "above_lowest_caliper_m", "curvature")
#: features tested between canes only: within a cane the model's level is a function of push
#: height (tested), and it moves with the caliper line's slope error exactly as the residual moves
#: against it, a negative r under any null that the within-cane nulls (feature held fixed) miss
BETWEEN_ONLY = ("log_k_model",)
#: features whose row is reported (and counted in the Bonferroni family) but never flags the model.
#: The trace's curvature is read off the same trace as the field stiffness, so a rough rig's
#: noise moves both: a rough patch late in the push raises the fitted slope and the second half's
#: slope together. Under a correct model the row then correlates within canes: a load-cell
#: roughness of 3 % on the force gave one trace's noise in ln k and in curvature r = +0.64, and
#: the row p < 0.01/12 on 14 % of correct models (AR(1) 0.85; 4 % with white roughness;
#: ``tests/scripts/curvature_shared_noise.py``); an independent generator's correct modulus scale
#: was flagged on it alone. A per-trace bootstrap (tried, not kept) cannot supply the null: one
#: trace does not show its slow noise apart from its bend, so the bootstrap's pair of noises
#: correlated far less than the true pair. How the traces bend is judged by the shape check instead
#: (:mod:`.shape`), which compares them with the model's own traces, not with the stiffness.
NOT_JUDGED = ("curvature",)


def _perm_corr(a: np.ndarray, b: np.ndarray, B: np.ndarray) -> tuple[float, float]:
    """Pearson r of ``a`` with ``b`` and its two-sided p against the permuted copies ``B`` of ``b``."""
    obs = _corr(a, b)
    Bc = B - B.mean(axis=1, keepdims=True)
    ac = a - a.mean()
    null = (Bc @ ac) / np.sqrt((Bc**2).sum(axis=1) * (ac @ ac))
    return obs, float((np.sum(np.abs(null) >= abs(obs) - 1e-12) + 1) / (len(B) + 1))


def structure_tests(df: pd.DataFrame, resid_col: str, features: list[str] | None = None, seed: int = 0,
                    n_perm: int = N_PERM, geometry: np.ndarray | None = None,
                    level_col: str | None = None) -> pd.DataFrame:
    """One row per (feature, level): correlation, p, Bonferroni-adjusted p.

    Parameters
    ----------
    df : DataFrame
        One row per trial: ``cane``, ``resid_col`` and the features.
    geometry : array (draws, len(df)), optional
        The model's change in ln k under the caliper line's own error
        (:func:`.adequacy.geometry_draws`), row-aligned with ``df``. The line's slope error
        moves a cane's low and high pushes apart, so under a correct model the residual trends
        along each cane, and with every feature that varies along it (push height, and a
        trace's curvature where it changes with height); a within-cane permutation null cannot
        know that and flags it (an independent generator's null: r = -0.54 with push height,
        permutation p = 0.0005, against this null 0.004). Given the draws, every within-cane
        row's ``p`` is the larger of the permutation's (``p_permutation``) and that null's
        (:func:`.adequacy.within_trend_geometry`, which holds the feature fixed): valid under
        either null. The geometry null alone takes trial noise as the same on every cane and,
        where a cane or two scatter most, put a trace feature ten times below the permutation's
        p (r = 0.55, 0.0003 against 0.007); the permutation keeps that honest. ``null`` says
        which ``p`` is.
    level_col : str, optional
        Column of ``df`` with the model's own ln k for the residual in ``resid_col`` (the
        baseline's for the residual before, the held-out prediction after): the stiffness-level
        row ``log_k_model``, between canes only (:data:`BETWEEN_ONLY`), left out without it.
        Not the field's ln k: it contains the residual, so under any null the two correlate
        (a cane measuring stiff has both a high level and a high residual). The model's level
        shares the caliper line's error with the residual instead, so given ``geometry`` its
        row also takes the larger of the permutation's p and
        :func:`.adequacy.level_trend_geometry`'s.
    """
    rng = np.random.default_rng(seed)
    keep = np.isfinite(df[resid_col].to_numpy(float))
    d = df[keep].copy()
    model_level = d[level_col].to_numpy(float) if level_col is not None else None
    d = d.drop(columns=["log_k_model"], errors="ignore")  # only ever the level the caller names
    if model_level is not None:
        if not np.all(np.isfinite(model_level)):
            raise ValueError(f"level column {level_col!r} is not finite on every trial with a residual "
                             f"({resid_col!r}): the level row would be dropped")
        d["log_k_model"] = model_level
    g = None
    if geometry is not None:
        g = np.asarray(geometry, float)
        if g.ndim != 2 or g.shape[1] != len(df):
            raise ValueError(f"geometry draws have shape {g.shape}; expected (draws, {len(df)}), one column per trial")
        g = g[:, keep]
    feats = [f for f in (features or list(FEATURES)) if f in d.columns and d[f].notna().all() and d[f].std() > 0]
    canes = d["cane"].to_numpy()
    uniq, inv = np.unique(canes, return_inverse=True)
    cnt = np.bincount(inv)
    order = np.argsort(inv, kind="stable")  # trials grouped by cane, for the within-cane shuffles
    r = d[resid_col].to_numpy(float)
    rm = np.bincount(inv, r) / cnt
    rw = r - rm[inv]
    rows = []
    for f in feats:
        x = d[f].to_numpy(float)
        xm = np.bincount(inv, x) / cnt
        xw = x - xm[inv]
        for level, (a, b) in (("between canes", (rm, xm)), ("within canes", (rw, xw))):
            if (level == "between canes" and f in WITHIN_ONLY) or (level == "within canes" and f in BETWEEN_ONLY):
                continue
            if np.std(b) == 0 or np.std(a) == 0:
                continue
            if level == "between canes":
                B = np.stack([rng.permutation(b) for _ in range(n_perm)])
            else:  # shuffle within each cane: sort by (cane, random key)
                idx = np.argsort(inv[None, :] * 10.0 + rng.random((n_perm, len(b))), axis=1)
                B = np.empty((n_perm, len(b)))
                B[:, order] = b[idx]
            obs, p = _perm_corr(a, b, B)
            row = {"feature": f, "level": level, "r": obs, "p": p, "what": FEATURES.get(f, f),
                   "null": "cane permutation" if level == "between canes" else "permutation within canes",
                   "p_permutation": p, "judged": f not in NOT_JUDGED}
            if level == "within canes" and g is not None:
                row["p"] = max(p, within_trend_geometry(canes, r, x, g, seed=seed)["p"])
                row["null"] = "permutation within canes and caliper-line error (the larger p)"
            elif f == "log_k_model" and g is not None:  # the level moves with the line's error too
                row["p"] = max(p, level_trend_geometry(canes, r, x, g, seed=seed)["p"])
                row["null"] = "cane permutation and caliper-line error (the larger p)"
            rows.append(row)
    out = pd.DataFrame(rows)
    if len(out):
        out["p_adj"] = np.minimum(1.0, out["p"] * len(out))
    return out


def structure_flags(table: pd.DataFrame, alpha: float) -> pd.DataFrame:
    """The rows of a :func:`structure_tests` table that flag the model: judged, ``p_adj`` below ``alpha``."""
    if not len(table):
        return table
    return table[table.judged & (table.p_adj < alpha)]


def between_share(df: pd.DataFrame, resid_col: str) -> float:
    """Share of the residual variance (about zero) that lies in the cane means."""
    d = df[np.isfinite(df[resid_col])]
    r = d[resid_col].to_numpy(float)
    m = d.groupby("cane")[resid_col].transform("mean").to_numpy(float)
    tot = float(np.sum((r - r.mean()) ** 2))
    return float(np.sum((m - r.mean()) ** 2) / tot) if tot > 0 else float("nan")


def level_trend(df: pd.DataFrame, resid_col: str, level_col: str, seed: int = 0,
                n_perm: int = N_PERM) -> dict[str, float]:
    """Between-cane correlation of the cane-mean residual with the cane-mean stiffness level.

    Parameters
    ----------
    df : DataFrame
        One row per trial with ``cane``, ``resid_col`` (held-out ln k_field/k_model) and
        ``level_col`` (the model's own predicted ln k: not the field's, which contains the
        residual and would correlate with it by construction).

    Returns
    -------
    dict
        ``r``, two-sided cane-permutation ``p``, ``n_canes``.
    """
    d = df[np.isfinite(df[resid_col]) & np.isfinite(df[level_col])]
    g = d.groupby("cane").agg(r=(resid_col, "mean"), x=(level_col, "mean"))
    a, b = g.r.to_numpy(float), g.x.to_numpy(float)
    if len(g) < 4 or np.std(a) == 0 or np.std(b) == 0:
        return {"r": math.nan, "p": 1.0, "n_canes": int(len(g))}
    rng = np.random.default_rng(seed)
    obs, p = _perm_corr(a, b, np.stack([rng.permutation(b) for _ in range(n_perm)]))
    return {"r": obs, "p": p, "n_canes": int(len(g))}
