"""Which trial features carry the residual, and how strongly (permutation tests grouped by cane).

A residual r (ln k_sim/k_field or after an effect) is split into its cane
means (between canes) and the deviations from them (within canes). Each
feature is split the same way and correlated with the matching part:

* between: Pearson r of cane-mean residual on cane-mean feature; null by
  permuting the canes' means (canes are the independent units);
* within: Pearson r of the deviations; null by permuting trials within each
  cane (a cane's offset is never mistaken for a height effect).

p-values are Bonferroni-adjusted over all tests in the table. The share of
the residual variance between canes is reported beside it.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

N_PERM = 2000

FEATURES = {
    "height_m": "push height above the base",
    "s_push_m": "arc length to the push point",
    "rel_push": "push arc length / cane length",
    "diameter_mm": "diameter at the push point (caliper fit)",
    "above_lowest_caliper_m": "arc length from the lowest caliper up to the push point",
    "log_k_field": "stiffness level (ln k_field)",
    "curvature": "trace curvature: slope of the second half / first half of contact",
    "trial_no": "position of the push point on the cane (1 = highest)",
}


#: features that describe a push point's place on its cane: tested within canes only
WITHIN_ONLY = ("trial_no", "above_lowest_caliper_m", "curvature")


def _corr(a: np.ndarray, b: np.ndarray) -> float:
    a = a - a.mean()
    b = b - b.mean()
    den = np.sqrt((a @ a) * (b @ b))
    return float(a @ b / den) if den > 0 else 0.0


def structure_tests(df: pd.DataFrame, resid_col: str, features: list[str] | None = None, seed: int = 0,
                    n_perm: int = N_PERM) -> pd.DataFrame:
    """One row per (feature, level): correlation, permutation p, Bonferroni-adjusted p."""
    rng = np.random.default_rng(seed)
    d = df[np.isfinite(df[resid_col])].copy()
    feats = [f for f in (features or list(FEATURES)) if f in d.columns and d[f].notna().all() and d[f].std() > 0]
    canes = d["cane"].to_numpy()
    uniq, inv = np.unique(canes, return_inverse=True)
    r = d[resid_col].to_numpy(float)
    rm = np.bincount(inv, r) / np.bincount(inv)
    rw = r - rm[inv]
    rows = []
    for f in feats:
        x = d[f].to_numpy(float)
        xm = np.bincount(inv, x) / np.bincount(inv)
        xw = x - xm[inv]
        for level, (a, b) in (("between canes", (rm, xm)), ("within canes", (rw, xw))):
            if level == "between canes" and f in WITHIN_ONLY:
                continue  # their cane means differ only through missing trials
            if np.std(b) == 0 or np.std(a) == 0:
                continue
            obs = _corr(a, b)
            if level == "between canes":
                B = np.stack([rng.permutation(b) for _ in range(n_perm)])
            else:  # shuffle within each cane: sort by (cane, random key)
                order = np.argsort(inv, kind="stable")
                idx = np.argsort(inv[None, :] * 10.0 + rng.random((n_perm, len(b))), axis=1)
                B = np.empty((n_perm, len(b)))
                B[:, order] = b[idx]
            Bc = B - B.mean(axis=1, keepdims=True)
            ac = a - a.mean()
            null = (Bc @ ac) / np.sqrt((Bc**2).sum(axis=1) * (ac @ ac))
            p = float((np.sum(np.abs(null) >= abs(obs) - 1e-12) + 1) / (n_perm + 1))
            rows.append({"feature": f, "level": level, "r": obs, "p": p, "what": FEATURES.get(f, f)})
    out = pd.DataFrame(rows)
    if len(out):
        out["p_adj"] = np.minimum(1.0, out["p"] * len(out))
    return out


def between_share(df: pd.DataFrame, resid_col: str) -> float:
    """Share of the residual variance (about zero) that lies in the cane means."""
    d = df[np.isfinite(df[resid_col])]
    r = d[resid_col].to_numpy(float)
    m = d.groupby("cane")[resid_col].transform("mean").to_numpy(float)
    tot = float(np.sum((r - r.mean()) ** 2))
    return float(np.sum((m - r.mean()) ** 2) / tot) if tot > 0 else float("nan")
