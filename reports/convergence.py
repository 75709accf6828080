"""Figures and summary of the beam/chain convergence study (from CSV files)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.ticker import NullFormatter, ScalarFormatter  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from canebench.studies.convergence import closed_form_ratio  # noqa: E402

COLORS = {"paper": "tab:red", "end_angle": "tab:blue", "dual_length": "tab:green", "dual_length+twist": "tab:purple"}


def _segment_axis(ax) -> None:
    ax.set_xscale("log")
    ax.set_xticks([3, 5, 10, 20, 40])
    ax.xaxis.set_major_formatter(ScalarFormatter())
    ax.xaxis.set_minor_formatter(NullFormatter())


def chain_plot(df: pd.DataFrame, path: Path) -> Path:
    """k_chain / k_beam against segment count: the straight cantilevers (with
    the closed forms dashed) and the bundled canes (median and range)."""
    discs = sorted(df.discretization.unique())
    fig, axes = plt.subplots(1, len(discs) + 1, figsize=(5.2 * (len(discs) + 1), 4.4), squeeze=False)
    ax = axes[0][0]
    for formula, g in df[df.trial.isin(["uniform-cantilever", "tapered-cantilever"])
                         & (df.discretization == "uniform")].groupby("formula"):
        for tid, h in g.groupby("trial"):
            ls = "-" if tid.startswith("uniform") else ":"
            ax.plot(h.segments, h.ratio, ls, marker="o", ms=3, color=COLORS.get(formula), label=f"{formula} ({tid.split('-')[0]})")
        n = np.array(sorted(g.segments.unique()))
        ax.plot(n, [1 / closed_form_ratio(formula, k) for k in n], "--", color="k", lw=0.7)
    ax.axhline(1, color="k", lw=0.5)
    _segment_axis(ax)
    ax.set_title("straight cantilevers (dashed: closed forms)")
    ax.set_xlabel("segments")
    ax.set_ylabel("k_chain / k_beam (small deflection)")
    ax.legend(fontsize=7)
    canes = df[~df.trial.isin(["uniform-cantilever", "tapered-cantilever"])]
    for ax, disc in zip(axes[0][1:], discs):
        for formula, g in canes[canes.discretization == disc].groupby("formula"):
            s = g.groupby("segments").ratio
            ax.plot(s.median().index, s.median(), marker="o", ms=3, color=COLORS.get(formula), label=formula)
            ax.fill_between(s.min().index, s.min(), s.max(), color=COLORS.get(formula), alpha=0.2)
        ax.axhline(1, color="k", lw=0.5)
        ax.axhspan(0.99, 1.01, color="k", alpha=0.08)
        ax.set_yscale("log")
        _segment_axis(ax)
        ax.set_title(f"bundled canes, {disc} discretization (median, range)")
        ax.set_xlabel("segments")
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def rod_plot(df: pd.DataFrame, path: Path) -> Path:
    fig, ax = plt.subplots(figsize=(5, 4))
    ax.loglog(df.elements, df.rel_error, "o-", label="tapered cantilever, tip deflection")
    n = df.elements.to_numpy(float)
    ax.loglog(n, df.rel_error.iloc[0] * (n / n[0]) ** -4, "k--", lw=0.8, label="slope -4")
    ax.set_xlabel("RK4 elements")
    ax.set_ylabel("relative error vs closed form")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def summary(df: pd.DataFrame, segments=(10, 20)) -> pd.DataFrame:
    """Per formula and discretization, at 10 and 20 segments: the chain's
    stiffness error against the beam over the bundled canes."""
    canes = df[~df.trial.isin(["uniform-cantilever", "tapered-cantilever"])]
    rows = []
    for (disc, formula, n), g in canes[canes.segments.isin(segments)].groupby(["discretization", "formula", "segments"]):
        err = g.ratio - 1
        err_rigid = g.k_chain / g.k_beam_rigid_twist - 1
        rows.append({"discretization": disc, "formula": formula, "segments": n, "trials": g.trial.nunique(),
                     "median error": err.median(), "worst |error|": err.abs().max(),
                     "within 1 %": int((err.abs() <= 0.01).sum()),
                     "worst |error| vs torsion-free beam": err_rigid.abs().max()})
    return pd.DataFrame(rows)


def exceedances(df: pd.DataFrame, formula: str = "dual_length", segments: int = 20, tol: float = 0.01) -> pd.DataFrame:
    """Trials where the chain misses the beam by more than ``tol``, with the
    part of the gap a chain without twist joint cannot close: the beam's own
    stiffening when its torsion is made rigid."""
    g = df[(df.formula == formula) & (df.segments == segments)].copy()
    g["error"] = g.ratio - 1
    g["beam torsion effect"] = g.k_beam_rigid_twist / g.k_beam - 1
    g["error vs torsion-free beam"] = g.k_chain / g.k_beam_rigid_twist - 1
    g = g[g.error.abs() > tol]
    return g[["discretization", "trial", "error", "beam torsion effect", "error vs torsion-free beam"]]


def beam_mesh_summary(df: pd.DataFrame) -> str:
    """One line on the beam's own mesh convergence (``beam_mesh.csv``)."""
    if df is None or not len(df):
        return "beam mesh: no push points"
    worst = df.loc[df.rel_error.idxmax()]
    worst_c = df.loc[df.rel_error_continuum.idxmax()]
    return (f"beam mesh: {int(df['pass'].sum())}/{len(df)} push points within 1e-4 of the same beam at twice "
            f"its mesh (worst {worst.rel_error:.1e} on {worst.trial} at {int(worst.elements)} elements; "
            f"elements {int(df.elements.min())}-{int(df.elements.max())}); worst against the independent "
            f"small-deflection continuum solution {worst_c.rel_error_continuum:.1e} ({worst_c.trial}); "
            f"rest probe point off the centreline by at most {df.rest_offset_m.max():.1e} m")


def beam_mesh_html(df: pd.DataFrame) -> str:
    """An HTML section for ``beam_mesh.csv``: the summary line and the five
    push points with the largest mesh error."""
    cols = ["trial", "elements", "rel_error", "pass", "rel_error_continuum", "rest_offset_m"]
    worst = df.sort_values("rel_error", ascending=False).head(5)[cols]
    return ("<h3>Beam mesh convergence on every push point</h3>"
            "<p>The beam as the runs build it (mesh doubled from 48 elements until its small-deflection stiffness "
            "changes by less than 1e-4) against the same rod at twice its mesh, and against an independent "
            "small-deflection solution (Castigliano's integral over the smoothed centreline). "
            f"{beam_mesh_summary(df)}.</p>"
            + worst.to_html(index=False, float_format=lambda v: f"{v:.2e}"))


# ------------------------------------------------------------------ continuum engines

CONTINUUM_COLORS = {"mujoco_rod": "tab:orange", "exudyn_beam": "tab:cyan"}


def _bundled(df: pd.DataFrame) -> pd.DataFrame:
    return df[~df.trial.isin(["uniform-cantilever", "tapered-cantilever"])]


def continuum_summary(df: pd.DataFrame) -> pd.DataFrame:
    """Per engine, variant and element count (``continuum_convergence.csv``): the
    error against the beam over the bundled canes (median, worst |error|, how
    many failed), the closed-form error on the two straight cantilevers, and
    the cost: median wall time per probe and its median ratio to the MuJoCo
    chain on the same case."""
    rows = []
    canes = _bundled(df)
    for (b, v, n), g in df.groupby(["backend", "variant", "elements"], sort=False):
        c = canes[(canes.backend == b) & (canes.variant == v) & (canes.elements == n)]
        ok = c[c.status == "ok"]
        row = {"backend": b, "variant": v, "elements": int(n), "trials": int(c.trial.nunique()),
               "failed": int((c.status != "ok").sum()),
               "median error vs beam": ok.rel_error.median() if len(ok) else np.nan,
               "worst |error| vs beam": ok.rel_error.abs().max() if len(ok) else np.nan}
        for tid, label in (("uniform-cantilever", "uniform cantilever vs closed form"),
                           ("tapered-cantilever", "tapered cantilever vs closed form")):
            h = g[g.trial == tid]
            row[label] = float(h.rel_error_closed.iloc[0]) if len(h) else np.nan
        row["median wall s per probe"] = c.wall_s.median() if len(c) else np.nan
        row["median wall / mujoco chain"] = c.wall_ratio.median() if len(c) else np.nan
        rows.append(row)
    return pd.DataFrame(rows)


def _element_axis(ax, n) -> None:
    ax.set_xscale("log")
    ax.set_xticks([int(v) for v in n])
    ax.xaxis.set_major_formatter(ScalarFormatter())
    ax.xaxis.set_minor_formatter(NullFormatter())


def _label_panel(ax, ylabel: str, title: str) -> None:  # noqa: ANN001
    """Axis labels against element count, log grid, legend when anything is labelled."""
    ax.set_xlabel("elements")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(alpha=0.3, which="both")
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=7)


def continuum_plot(df: pd.DataFrame, path: Path) -> Path:
    """|k / k_ref - 1| against element count: the straight cantilevers against
    their closed forms (with the slope -2 guide), the bundled canes against the
    beam (median and range); cost per probe relative to the MuJoCo chain."""
    fig, axes = plt.subplots(1, 3, figsize=(15.6, 4.4))
    main = df[df.variant.isin(["per-vertex", ""]) & (df.elements > 0)]
    ax = axes[0]
    for (b, tid), g in main[main.trial.isin(["uniform-cantilever", "tapered-cantilever"])].groupby(["backend", "trial"]):
        ls = "-" if tid.startswith("uniform") else ":"
        ax.loglog(g.elements, g.rel_error_closed.abs(), ls, marker="o", ms=3, color=CONTINUUM_COLORS.get(b),
                  label=f"{b} ({tid.split('-')[0]})")
    n = np.array(sorted(main.elements.unique()), float)
    if len(n):
        ax.loglog(n, 0.5 / n**2, "k--", lw=0.7, label="1/(2n^2)")
    _label_panel(ax, "|k / k_closed - 1|", "straight cantilevers vs closed form")
    ax = axes[1]
    canes = _bundled(main)
    for b, g in canes.groupby("backend"):
        e = g.assign(err=g.rel_error.abs()).groupby("elements").err
        ax.loglog(e.median().index, e.median(), marker="o", ms=3, color=CONTINUUM_COLORS.get(b), label=f"{b} median")
        ax.fill_between(e.min().index, e.min().clip(lower=1e-7), e.max(), color=CONTINUUM_COLORS.get(b), alpha=0.2)
    for (b, v), g in _bundled(df[df.variant.isin(["uniform-radius", "first-edge-clamp"])]).groupby(["backend", "variant"]):
        ax.scatter(g.elements, g.rel_error.abs(), s=8, marker="x" if v == "uniform-radius" else "+",
                   color="k" if v == "uniform-radius" else "tab:red", label=f"{b} {v}")
    _label_panel(ax, "|k / k_beam - 1|", "bundled canes vs beam (median, range)")
    ax = axes[2]
    for b, g in canes.groupby("backend"):
        w = g.groupby("elements").wall_ratio.median()
        ax.loglog(w.index, w, marker="o", ms=3, color=CONTINUUM_COLORS.get(b), label=b)
    ax.axhline(1, color="k", lw=0.5)
    _label_panel(ax, "wall time / MuJoCo chain (median)", "cost per probe")
    for ax in axes:
        _element_axis(ax, sorted(main.elements.unique()))
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def continuum_section(run_dir) -> str:
    """HTML section of the continuum engines' convergence (``canebench converge``
    writes ``continuum_convergence.csv``); empty string when absent. Rebuilds
    the figure from the CSV."""
    run_dir = Path(run_dir)
    path = run_dir / "continuum_convergence.csv"
    if not path.exists():
        return ""
    df = pd.read_csv(path, keep_default_na=False, na_values=[""])
    df["variant"] = df["variant"].fillna("")
    continuum_plot(df, run_dir / "continuum_convergence.png")
    summ = continuum_summary(df)
    table = summ.to_html(index=False, float_format=lambda v: f"{v:.3g}", na_rep="")
    return ("<h2>Continuum engines against the beam: convergence with elements</h2>"
            "<p>MuJoCo's 1D elastic flex (discrete elastic rod) and Exudyn's geometrically exact beam, compiled "
            "from the chain's continuum (not its links), probed by the harness (fast protocol, small push, gravity "
            "off) at each element count; errors against the beam reference on the same push, and against the closed "
            "forms on the straight cantilevers (reference-values sec. 1). The MuJoCo rod's variants: "
            "<code>uniform-radius</code> (one documented flex radius, the diameter at the middle of the probed span, "
            "instead of per-vertex stiffness) and <code>first-edge-clamp</code> (the cane's first element pinned "
            "instead of a stub edge below the base). Cost: wall time of build and probe, as a ratio to the MuJoCo "
            "chain (default model) on the same case.</p>"
            '<img src="continuum_convergence.png">' + table)
