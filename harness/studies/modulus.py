"""Flexural modulus from three-point bending (paper: "Flexural modulus testing").

For a simply supported solid circular section of radius r on span L, a
central load F deflects the midspan by F L^3 / (48 E I) with I = pi r^4 / 4,
so with m = F / deflection (the slope of the force-displacement line)

    E = L^3 m / (12 pi r^4)

(the paper's equation). Everything here is SI (m, N/m, Pa); tables report
GPa. The paper states L and r in mm and m in N/mm with E in GPa: with those
units the formula gives N/mm^2 = MPa, so the paper's GPa values are that
result divided by 1000.

The slope rule (paper): a test that stays linear until 20 N gets the
least-squares line through its readings below 20 N (those before the first
one at or above it); a non-linear one ("thin, flexible new growth") gets the
least-squares line over its first 10 mm of displacement. The paper gives no
linearity criterion, so this module uses one (:data:`MIN_LINEARITY`): split
the readings below 20 N at half their displacement and fit a line to each
half; the curve is linear when the upper slope is at least 0.9 x the lower
one. A curve that never reaches 20 N is non-linear. A *sample* is linear
when all its tests are; otherwise all its tests use the 10 mm rule (the
paper applies the rule to samples). The 10 mm window is used whatever the
span (the paper's non-linear samples were at the default 203.2 mm). Lines
have an intercept; displacement counts from the first reading (contact).
r is half the mean of the six caliper diameters; a sample's E is the mean of
its tests' E (the paper's n counts samples, so groups and t-tests use
sample means).

Welch's t-tests (``scipy.stats.ttest_ind(equal_var=False)``, two-sided,
alpha 0.05, no multiple-comparison correction, as in the paper) cover the
paper's comparisons: dormant vs fruiting; dormant vs fruiting within each
variety sampled in both; and, in the fruiting season, every pair of
varieties and every pair of ages.
"""

from __future__ import annotations

import html
import json
import re
from dataclasses import dataclass, field
from itertools import combinations
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats

from ..data.bending import BendingSample, read_bending_dataset

FORCE_CAP_N = 20.0
WINDOW_M = 0.010
MIN_LINEARITY = 0.9
ALPHA = 0.05
SEASONS = ("dormant", "fruiting")
PAPER = {"dormant": (19, 4.57), "fruiting": (40, 3.00), "dormant Duke": (5, 4.33), "fruiting Duke": (11, 3.59),
         "range_gpa": (1.82, 8.05), "season_p": 0.0015}


def flexural_modulus(span_m: float, slope_n_per_m: float, radius_m: float) -> float:
    """E = L^3 m / (12 pi r^4) (Pa) for three-point bending of a solid circular section."""
    return span_m**3 * slope_n_per_m / (12.0 * np.pi * radius_m**4)


@dataclass(frozen=True)
class SlopeFit:
    """A test's slope (N/m), the rule that gave it and the linearity check."""

    slope_n_per_m: float
    method: str  # "20N" or "10mm"
    linear: bool
    ratio: float  # upper-half / lower-half slope of the readings up to the force cap
    n_points: int
    fit_max_disp_m: float
    reason: str


def _slope(x: np.ndarray, y: np.ndarray) -> float:
    return float(np.polyfit(x, y, 1)[0]) if len(x) >= 2 and np.ptp(x) > 0 else float("nan")


def linearity(disp_m: np.ndarray, force_n: np.ndarray, force_cap_n: float = FORCE_CAP_N,
              min_ratio: float = MIN_LINEARITY) -> tuple[bool, float, int, str]:
    """Whether a curve is linear up to ``force_cap_n``.

    Returns
    -------
    linear, ratio, end, reason
        ``end`` is the index of the first reading at or above the cap (the
        20 N fit uses the readings before it); ``ratio`` the upper/lower half slopes.
    """
    reached = np.flatnonzero(force_n >= force_cap_n)
    if not len(reached):
        return False, float("nan"), len(force_n) - 1, f"did not reach {force_cap_n:g} N (max {force_n.max():.3g} N)"
    end = int(reached[0])
    d, f = disp_m[:end], force_n[:end]
    mid = d[0] + 0.5 * (d[-1] - d[0])
    lo, hi = d <= mid, d >= mid
    if lo.sum() < 3 or hi.sum() < 3:
        return True, float("nan"), end, f"linear: too few readings below {force_cap_n:g} N to judge ({end})"
    ratio = _slope(d[hi], f[hi]) / _slope(d[lo], f[lo])
    ok = bool(ratio >= min_ratio)
    return ok, float(ratio), end, (f"linear to {force_cap_n:g} N" if ok else
                                   f"curved below {force_cap_n:g} N (slope ratio {ratio:.2f} < {min_ratio:g})")


def fit_slope(disp_m: np.ndarray, force_n: np.ndarray, method: str | None = None,
              force_cap_n: float = FORCE_CAP_N, window_m: float = WINDOW_M,
              min_ratio: float = MIN_LINEARITY) -> SlopeFit:
    """The slope of one test by the paper's rule.

    Parameters
    ----------
    disp_m, force_n : ndarray
        Readings (m, N), displacement non-decreasing.
    method : {"20N", "10mm"} or None
        Force a rule; ``None`` picks "20N" when :func:`linearity` says linear.
    force_cap_n, window_m, min_ratio : float
        The 20 N cap, the 10 mm window and the linearity threshold.
    """
    linear, ratio, end, reason = linearity(disp_m, force_n, force_cap_n, min_ratio)
    method = method or ("20N" if linear else "10mm")
    if method == "20N":
        sel = np.arange(max(end, 2))
    else:
        sel = np.flatnonzero(disp_m - disp_m[0] <= window_m + 1e-12)
        if disp_m[-1] - disp_m[0] < window_m - 1e-9:
            reason += (f"; curve ends at {(disp_m[-1] - disp_m[0]) * 1e3:.3g} mm, "
                       f"before the {window_m * 1e3:g} mm window")
    return SlopeFit(_slope(disp_m[sel], force_n[sel]), method, linear, ratio, len(sel),
                    float(disp_m[sel][-1] - disp_m[0]), reason)


def _sample_rows(s: BendingSample, cap: float, window: float, min_ratio: float) -> list[dict]:
    fits = [fit_slope(t.displacement_m, t.force_n, None, cap, window, min_ratio) for t in s.tests]
    method = "20N" if all(f.linear for f in fits) else "10mm"
    rows = []
    for t, f0 in zip(s.tests, fits):
        f = f0 if f0.method == method else fit_slope(t.displacement_m, t.force_n, method, cap, window, min_ratio)
        e = flexural_modulus(s.span_m, f.slope_n_per_m, s.radius_m)
        rows.append({"sample_id": s.sample_id, "test": t.test, "season": s.season, "variety": s.variety,
                     "age": s.age, "span_mm": s.span_m * 1e3, "mean_diameter_mm": 2e3 * s.radius_m,
                     "method": method, "test_linear": f0.linear, "linearity_ratio": f0.ratio, "reason": f0.reason,
                     "fit_points": f.n_points, "fit_max_disp_mm": f.fit_max_disp_m * 1e3,
                     "slope_n_per_mm": f.slope_n_per_m * 1e-3, "E_gpa": e * 1e-9, "notes": s.notes,
                     "file": t.path})
    return rows


def group_table(samples: pd.DataFrame) -> pd.DataFrame:
    """n, mean, sd, min, max of sample E (GPa): all, by season, season x variety, season x age."""
    rows = []
    for keys in ((), ("season",), ("season", "variety"), ("season", "age")):
        groups = samples.groupby(list(keys), sort=False) if keys else [((), samples)]
        for k, g in groups:
            k = k if isinstance(k, tuple) else (k,)
            e = g["E_gpa"]
            rows.append({"grouping": " x ".join(keys) or "all", **dict(zip(keys, k)), "n_samples": len(g),
                         "mean_gpa": e.mean(), "sd_gpa": e.std(ddof=1) if len(g) > 1 else np.nan,
                         "min_gpa": e.min(), "max_gpa": e.max()})
    cols = ["grouping", "season", "variety", "age", "n_samples", "mean_gpa", "sd_gpa", "min_gpa", "max_gpa"]
    return pd.DataFrame(rows).reindex(columns=cols)


def _paper_claim(family: str, a: str, b: str) -> str:
    pair = {a.lower(), b.lower()}
    if family == "season" and pair == {"dormant", "fruiting"}:
        return "p = 0.0015 (significant)"
    if family == "season within variety" and a.lower().startswith("duke"):
        return "not significant"
    if family == "fruiting variety" and pair in ({"duke", "liberty"}, {"draper", "liberty"}):
        return "significant"
    if family == "fruiting variety" and pair == {"duke", "draper"}:
        return "not significant (implied)"
    if family == "fruiting age":
        return "not significant"
    return ""


def welch(a: pd.Series, b: pd.Series) -> tuple[float, float, float]:
    """Welch's t, its Satterthwaite degrees of freedom and the two-sided p."""
    if len(a) < 2 or len(b) < 2:
        return np.nan, np.nan, np.nan
    r = stats.ttest_ind(a, b, equal_var=False)
    return float(r.statistic), float(r.df), float(r.pvalue)


def welch_tests(samples: pd.DataFrame, alpha: float = ALPHA, within: str = "fruiting") -> pd.DataFrame:
    """The paper's Welch comparisons on sample E."""
    comps: list[tuple[str, str, str, pd.Series, pd.Series]] = []
    e = samples.set_index("season")["E_gpa"]
    if {"dormant", "fruiting"} <= set(samples.season):
        comps.append(("season", "dormant", "fruiting", e.loc[["dormant"]], e.loc[["fruiting"]]))
        for v in sorted(set(samples.variety)):
            sv = samples[samples.variety == v]
            if {"dormant", "fruiting"} <= set(sv.season):
                comps.append(("season within variety", f"{v} dormant", f"{v} fruiting",
                              sv[sv.season == "dormant"].E_gpa, sv[sv.season == "fruiting"].E_gpa))
    fr = samples[samples.season == within]
    for col in ("variety", "age"):
        levels = sorted(set(fr[col]), key=_age_key if col == "age" else str)
        for a, b in combinations(levels, 2):
            comps.append((f"{within} {col}", a, b, fr[fr[col] == a].E_gpa, fr[fr[col] == b].E_gpa))
    rows = []
    for fam, a, b, xa, xb in comps:
        t, df, p = welch(xa, xb)
        rows.append({"family": fam, "group_a": a, "group_b": b, "n_a": len(xa), "n_b": len(xb),
                     "mean_a_gpa": xa.mean(), "mean_b_gpa": xb.mean(), "t": t, "df": df, "p": p,
                     "significant": bool(p < alpha) if np.isfinite(p) else False,
                     "paper": _paper_claim(fam, a, b)})
    return pd.DataFrame(rows)


def _age_key(label: str) -> tuple[float, str]:
    """Age labels in growth order: 'new'/'current' first, then by their first number."""
    m = re.search(r"\d+(\.\d+)?", str(label))
    return (float(m.group()) if m else -1.0, str(label))


@dataclass
class ModulusResult:
    """Per-test and per-sample E, group table, Welch tests and the files written."""

    tests: pd.DataFrame
    samples: pd.DataFrame
    groups: pd.DataFrame
    ttests: pd.DataFrame
    meta: dict
    files: list[Path] = field(default_factory=list)

    def to_df(self) -> pd.DataFrame:
        """One row per test, with its sample's E (``E_sample_gpa``)."""
        return self.tests.merge(self.samples[["sample_id", "E_gpa"]].rename(columns={"E_gpa": "E_sample_gpa"}),
                                on="sample_id")


def modulus_study(data_dir: str | Path, out_dir: str | Path | None = None, *, force_cap_n: float = FORCE_CAP_N,
                  window_mm: float = WINDOW_M * 1e3, min_linearity: float = MIN_LINEARITY,
                  alpha: float = ALPHA) -> ModulusResult:
    """Flexural modulus of every sample of a three-point-bending folder.

    Parameters
    ----------
    data_dir : str or Path
        Folder in the :mod:`canebench.data.bending` format.
    out_dir : str or Path, optional
        Where ``modulus.csv`` (per test, with the sample's E), ``modulus_samples.csv``,
        ``modulus_groups.csv``, ``modulus_tests.csv`` (Welch t-tests),
        ``modulus_meta.json`` and the figures go; nothing written when None.
    force_cap_n, window_mm, min_linearity : float
        The slope rule (20 N, 10 mm, 0.9).
    alpha : float
        Significance level of the t-tests.

    Returns
    -------
    ModulusResult
    """
    samples = read_bending_dataset(data_dir)
    tests = pd.DataFrame([r for s in samples for r in
                          _sample_rows(s, force_cap_n, window_mm * 1e-3, min_linearity)])
    per = tests.groupby("sample_id", sort=False)
    smp = per.first()[["season", "variety", "age", "span_mm", "mean_diameter_mm", "method", "notes"]]
    smp = smp.assign(n_tests=per.size(), E_gpa=per.E_gpa.mean(), E_cv_tests=per.E_gpa.std(ddof=0) / per.E_gpa.mean())
    smp = smp.reset_index()
    synthetic = bool(smp.notes.str.contains("SYNTHETIC", case=False).any())
    meta = {"data_dir": str(data_dir), "force_cap_n": force_cap_n, "window_mm": window_mm,
            "min_linearity": min_linearity, "alpha": alpha, "synthetic": synthetic,
            "n_samples": len(smp), "n_tests": len(tests)}
    res = ModulusResult(tests, smp, group_table(smp), welch_tests(smp, alpha), meta)
    if out_dir is not None:
        res.files = write_outputs(res, Path(out_dir))
    return res


def write_outputs(res: ModulusResult, out_dir: Path) -> list[Path]:
    """CSV, JSON and PNG files of a result (see :func:`modulus_study`)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    files = {"modulus.csv": res.to_df(), "modulus_samples.csv": res.samples, "modulus_groups.csv": res.groups,
             "modulus_tests.csv": res.ttests}
    paths = []
    for name, df in files.items():
        df.to_csv(out_dir / name, index=False)
        paths.append(out_dir / name)
    (out_dir / "modulus_meta.json").write_text(json.dumps(res.meta, indent=1))
    paths.append(out_dir / "modulus_meta.json")
    paths.append(season_figure(res.samples, res.ttests, out_dir / "modulus_by_season.png", res.meta["synthetic"]))
    paths.append(fruiting_figure(res.samples, res.ttests, out_dir / "modulus_fruiting.png", res.meta["synthetic"]))
    return paths


# ------------------------------------------------------------------ figures


def _stars(p: float) -> str:
    return "***" if p < 1e-3 else "**" if p < 1e-2 else "*"


def _panel(ax, samples: pd.DataFrame, col: str, levels: list[str], tests: pd.DataFrame, family: str,
           colors: dict[str, str]) -> None:
    """Box, jittered sample points (coloured by variety), dashed black mean, brackets over significant pairs."""
    rng = np.random.default_rng(0)
    for i, lv in enumerate(levels):
        g = samples[samples[col] == lv]
        ax.boxplot(g.E_gpa.to_numpy(), positions=[i], widths=0.5, showfliers=False,
                   medianprops={"color": "0.6"}, boxprops={"color": "0.6"}, whiskerprops={"color": "0.6"},
                   capprops={"color": "0.6"})
        ax.scatter(i + rng.uniform(-0.15, 0.15, len(g)), g.E_gpa, s=18, alpha=0.85,
                   c=[colors[v] for v in g.variety], edgecolors="none", zorder=3)
        ax.hlines(g.E_gpa.mean(), i - 0.32, i + 0.32, colors="k", linestyles="--", zorder=4)
    ax.set_xticks(range(len(levels)), [f"{lv}\n(n={(samples[col] == lv).sum()})" for lv in levels])
    ax.set_ylabel("flexural modulus E (GPa)")
    top, step = samples.E_gpa.max(), 0.07 * np.ptp(samples.E_gpa)
    sig = tests[(tests.family == family) & tests.significant]
    for k, r in enumerate(sig.itertuples()):
        xa, xb = levels.index(str(r.group_a)), levels.index(str(r.group_b))
        y = top + step * (k + 1)
        ax.plot([xa, xa, xb, xb], [y - step / 3, y, y, y - step / 3], color="k", lw=0.8)
        ax.text((xa + xb) / 2, y, f"{_stars(r.p)} p={r.p:.2g}", ha="center", va="bottom", fontsize=7)
    ax.set_ylim(top=top + step * (len(sig) + 1.5))


def _finish(fig, path: Path, synthetic: bool, colors: dict[str, str]) -> Path:
    """Legend of the varieties in ``colors``, the SYNTHETIC stamp, save."""
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    fig.legend([Line2D([], [], ls="", marker="o", color=c) for c in colors.values()], list(colors), fontsize=7,
               loc="upper right", title="variety", title_fontsize=7)
    if synthetic:
        fig.text(0.01, 0.01, "SYNTHETIC DATA: not measurements", color="#a33", fontsize=8)
    fig.tight_layout(rect=(0, 0.03, 0.86, 1))
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def _colors(samples: pd.DataFrame) -> dict[str, str]:
    return {v: f"C{i % 10}" for i, v in enumerate(sorted(set(samples.variety)))}


def season_figure(samples: pd.DataFrame, tests: pd.DataFrame, path: Path, synthetic: bool = False) -> Path:
    """Sample E by season (the paper's first modulus figure)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    seasons = [s for s in SEASONS if s in set(samples.season)] + sorted(set(samples.season) - set(SEASONS))
    fig, ax = plt.subplots(figsize=(5.5, 4))
    _panel(ax, samples, "season", seasons, tests, "season", _colors(samples))
    ax.set_title("Flexural modulus by season", fontsize=10)
    return _finish(fig, path, synthetic, _colors(samples))


def fruiting_figure(samples: pd.DataFrame, tests: pd.DataFrame, path: Path, synthetic: bool = False,
                    season: str = "fruiting") -> Path:
    """Fruiting-season E by age (left) and by variety (right), significant pairs marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fr = samples[samples.season == season]
    fig, axes = plt.subplots(1, 2, figsize=(9, 4), sharey=True)
    if len(fr):
        _panel(axes[0], fr, "age", sorted(set(fr.age), key=_age_key), tests, f"{season} age", _colors(samples))
        _panel(axes[1], fr, "variety", sorted(set(fr.variety)), tests, f"{season} variety", _colors(samples))
    axes[0].set_title(f"{season} season, by age", fontsize=10)
    axes[1].set_title(f"{season} season, by variety", fontsize=10)
    return _finish(fig, path, synthetic, {v: c for v, c in _colors(samples).items() if v in set(fr.variety)})


# ------------------------------------------------------------------ report section


def paper_comparison(samples: pd.DataFrame, ttests: pd.DataFrame) -> pd.DataFrame:
    """The paper's published numbers next to this data's."""
    rows = []
    for key in ("dormant", "fruiting", "dormant Duke", "fruiting Duke"):
        season, _, variety = key.partition(" ")
        g = samples[(samples.season == season) & ((samples.variety == variety) if variety else True)]
        rows.append({"quantity": f"{key}: n, mean E (GPa)", "paper": f"{PAPER[key][0]}, {PAPER[key][1]:.2f}",
                     "this data": f"{len(g)}, {g.E_gpa.mean():.2f}" if len(g) else "-"})
    rows.append({"quantity": "range of E (GPa)", "paper": "1.82-8.05",
                 "this data": f"{samples.E_gpa.min():.2f}-{samples.E_gpa.max():.2f}"})
    s = ttests[ttests.family == "season"]
    rows.append({"quantity": "Welch p, dormant vs fruiting", "paper": "0.0015",
                 "this data": f"{s.p.iloc[0]:.2g}" if len(s) else "-"})
    return pd.DataFrame(rows)


def modulus_section_html(out_dir: str | Path) -> str:
    """The report's flexural-modulus section, rebuilt from the files :func:`modulus_study` wrote."""
    out_dir = Path(out_dir)
    meta = json.loads((out_dir / "modulus_meta.json").read_text())
    smp = pd.read_csv(out_dir / "modulus_samples.csv", keep_default_na=False, na_values=[""])
    groups = pd.read_csv(out_dir / "modulus_groups.csv")
    tt = pd.read_csv(out_dir / "modulus_tests.csv", keep_default_na=False, na_values=[""])
    fmt = {"index": False, "float_format": lambda v: f"{v:.3g}", "na_rep": ""}
    banner = ('<p style="color:#a33"><b>SYNTHETIC data</b>: drawn to match the paper\'s published counts, means '
              'and range; not measurements.</p>' if meta.get("synthetic") else "")
    rules = smp.method.value_counts().to_dict()
    return (
        f"<h2>Flexural modulus (three-point bending)</h2>{banner}"
        f"<p>Data: <code>{html.escape(str(meta['data_dir']))}</code>; {meta['n_samples']} samples, "
        f"{meta['n_tests']} tests. E = L<sup>3</sup> m / (12 &pi; r<sup>4</sup>), m the slope of the force-"
        f"displacement line through the readings below {meta['force_cap_n']:g} N for linear samples "
        f"({rules.get('20N', 0)}) or over the first {meta['window_mm']:g} mm for non-linear ones "
        f"({rules.get('10mm', 0)}; linear when the upper-half slope is &ge; {meta['min_linearity']:g} x the "
        f"lower-half slope), r half the mean of six caliper diameters; a sample's E is the mean of its tests.</p>"
        f"<h3>Against the paper</h3>{paper_comparison(smp, tt).to_html(index=False)}"
        f'<img src="modulus_by_season.png"><img src="modulus_fruiting.png">'
        f"<h3>Groups (sample E, GPa)</h3>{groups.to_html(**fmt)}"
        f"<h3>Welch's t-tests (two-sided, alpha {meta['alpha']:g}, uncorrected)</h3>{tt.to_html(**fmt)}")
