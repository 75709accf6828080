"""Figures and report sections of the paper's studies, built from their files only."""

from __future__ import annotations

import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402

from canebench.reports.build import log_ratio_plot  # noqa: E402

MARKERS = ["o", "s", "^", "D", "v", "P"]


def _finish(fig, path: Path) -> Path:  # noqa: ANN001
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def _fmt(df: pd.DataFrame) -> str:
    return df.to_html(index=False, float_format=lambda v: f"{v:.3g}")


def naive_figure(table: pd.DataFrame, path: Path) -> Path:
    """Simulated against field stiffness: colour = bush, marker = cane, size = push height; engines side by side."""
    ok = table[table.status == "ok"]
    backends = sorted(ok.backend.unique()) or ["-"]
    fig, axes = plt.subplots(1, len(backends), figsize=(5 * len(backends) + 1.6, 4.8), squeeze=False)
    bushes = sorted(table.bush.unique())
    colors = {b: plt.cm.tab10(i % 10) for i, b in enumerate(bushes)}
    canes = sorted({int(str(c).split("c")[-1]) for c in table.cane})
    hmin, hmax = table.height_mm.min(), table.height_mm.max()
    size = lambda h: 20 + 120 * (h - hmin) / max(hmax - hmin, 1e-9)  # noqa: E731
    for ax, b in zip(axes[0], backends):
        g = ok[ok.backend == b]
        for r in g.itertuples():
            cn = int(str(r.cane).split("c")[-1])
            ax.scatter(r.k_field, r.k_sim, s=size(r.height_mm), color=colors[r.bush],
                       marker=MARKERS[(cn - 1) % len(MARKERS)], edgecolor="k", lw=0.4)
        lim = [min(g.k_field.min(), g.k_sim.min()) / 2, max(g.k_field.max(), g.k_sim.max()) * 2] if len(g) else [1e-3, 1]
        ax.plot(lim, lim, "k--", lw=0.8)
        ax.set_xscale("log"), ax.set_yscale("log")
        ax.set_xlabel("field stiffness (N/mm)"), ax.set_ylabel("simulated stiffness (N/mm)")
        ax.set_title(f"{b}: naive case")
        ax.grid(alpha=0.3, which="both")
    handles = [Line2D([], [], marker="o", ls="", color=colors[b], label=f"bush {b}") for b in bushes]
    handles += [Line2D([], [], marker=MARKERS[(c - 1) % len(MARKERS)], ls="", color="grey", label=f"cane {c}")
                for c in canes]
    handles += [Line2D([], [], marker="o", ls="", color="grey", ms=np.sqrt(size(h)), label=f"{h:.0f} mm")
                for h in (hmin, (hmin + hmax) / 2, hmax)]
    handles.append(Line2D([], [], ls="--", color="k", label="1:1"))
    fig.legend(handles=handles, loc="center right", fontsize=7, title="colour, marker, size", title_fontsize=7)
    fig.tight_layout(rect=(0, 0, 1 - 1.5 / fig.get_figwidth(), 1))
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def morris_figure(indices: pd.DataFrame, path: Path) -> Path:
    """mu* against sigma: a dot per trial, the mean as a cross, the 1:1 line; one panel per engine."""
    ok = indices.dropna(subset=["mu_star"])
    backends = sorted(ok.backend.unique()) or ["-"]
    fig, axes = plt.subplots(1, len(backends), figsize=(5 * len(backends), 4.4), squeeze=False)
    for ax, b in zip(axes[0], backends):
        g = ok[ok.backend == b]
        for i, (f, h) in enumerate(g.groupby("factor")):
            c = plt.cm.tab10(i)
            ax.scatter(h.mu_star, h.sigma, s=12, color=c, alpha=0.6, label=f)
            ax.scatter(h.mu_star.mean(), h.sigma.mean(), s=120, marker="x", color=c, lw=2.5)
        top = max(g.mu_star.max(), g.sigma.max()) * 1.05 if len(g) else 1
        ax.plot([0, top], [0, top], "k--", lw=0.7)
        ax.set_xlabel("mu* (N/mm)"), ax.set_ylabel("sigma (N/mm)")
        ax.set_title(f"{b}: Method of Morris (x = mean)")
        ax.legend(fontsize=7)
    return _finish(fig, path)


def sweep_figure(best: pd.DataFrame, naive: pd.DataFrame | None, path: Path) -> Path:
    """|log ratio| per trial before (naive case) and after the sweep's best point."""
    fig, ax = plt.subplots(figsize=(max(8, 0.2 * best.trial.nunique()), 4))
    trials = list(dict.fromkeys(best.sort_values("trial").trial))
    for i, (b, g) in enumerate(best.groupby("backend")):
        x = [trials.index(t) for t in g.trial]
        ax.plot(x, g.abs_log_ratio, "o", ms=4, label=f"{b}: best of the sweep", color=plt.cm.tab10(i))
        if naive is not None and len(naive):
            nv = naive[(naive.backend == b) & (naive.status == "ok")].set_index("trial").log_ratio.abs()
            ax.plot(x, [nv.get(t, np.nan) for t in g.trial], "x", ms=4, color=plt.cm.tab10(i),
                    label=f"{b}: naive case")
    ax.axhline(np.log(2), color="k", lw=0.6, ls=":", label="2x")
    ax.set_xticks(range(len(trials)), trials, rotation=90, fontsize=6)
    ax.set_ylabel("|ln(k_sim / k_field)|")
    ax.legend(fontsize=7)
    return _finish(fig, path)


def paper_sections(run_dir: Path) -> str:
    """Every paper-study section whose files are in ``run_dir``."""
    run_dir = Path(run_dir)
    parts = []
    naive = None
    if (run_dir / "naive.csv").exists():
        naive = pd.read_csv(run_dir / "naive.csv")
        naive_figure(naive, run_dir / "naive.png")
        log_ratio_plot(naive, run_dir / "naive_log_ratio.png")  # the run report's figure, on the naive rows
        ok = naive[naive.status == "ok"]
        per_b = ok.groupby("backend").log_ratio.agg(
            median_abs=lambda v: v.abs().median(), min="min", max="max", n="size").reset_index()
        parts.append("<h2>The naive case</h2><p>E = 4.57 GPa for every cane, measured diameters, K = 2EI/L, the "
                     "greedy 5 mm chain, on every engine.</p><img src='naive.png'><img src='naive_log_ratio.png'>"
                     f"<h3>ln(k_sim/k_field) per engine</h3>{_fmt(per_b)}")
        if (run_dir / "naive_by_rank.csv").exists():
            parts.append("<h3>Error by push-height rank (1 = highest point of the cane)</h3>"
                         + _fmt(pd.read_csv(run_dir / "naive_by_rank.csv")))
        if (run_dir / "naive_variance.csv").exists():
            parts.append("<h3>Share of the log-ratio variance between canes</h3>"
                         + _fmt(pd.read_csv(run_dir / "naive_variance.csv")))
        if (run_dir / "naive_truncation.csv").exists():
            tr = pd.read_csv(run_dir / "naive_truncation.csv")
            parts.append("<h3>The truncation rule: partial trials scored up to the contact</h3><p>Run with "
                         "<code>--truncate-contacts</code>: a trial with a detected contact (the IMU rule where a log "
                         "exists, else the force-only detector) is scored only up to it, its field slope from the "
                         "partial trial and its simulation pushed as far; the whole trials are scored too. "
                         + " ".join(f"{r.backend}: {r.partial} partial trials ({r.partial_unscorable} too short to "
                                    f"score); median |ln ratio| {r.median_abs_log_ratio_whole:.3f} over {r.scored_whole} "
                                    f"whole trials, {r.median_abs_log_ratio_truncated:.3f} over {r.scored_truncated} "
                                    f"with the rule (on the partial trials alone {r.partial_median_abs_whole:.3f} -> "
                                    f"{r.partial_median_abs_truncated:.3f})." for r in tr.itertuples())
                         + f"</p>{_fmt(tr)}")
    if (run_dir / "morris.csv").exists():
        idx = pd.read_csv(run_dir / "morris.csv")
        morris_figure(idx, run_dir / "morris.png")
        rank = pd.read_csv(run_dir / "morris_ranking.csv") if (run_dir / "morris_ranking.csv").exists() else None
        from canebench.studies.paper import morris_engine_comparison, morris_engine_sentence

        engines = pd.read_csv(run_dir / "morris_engines.csv") if (run_dir / "morris_engines.csv").exists() \
            else morris_engine_comparison(idx)

        cmp = ""
        if rank is not None and len(rank):
            piv = rank.pivot(index="factor", columns="backend", values="rank").sort_values(rank.backend.iloc[0])
            cmp = f"<h3>Does the ranking change between engines?</h3><p>{morris_engine_sentence(engines)}</p>"
            cmp += "<p>Rank of each factor (1 = largest mean mu*) per engine:</p>" + piv.to_html()
            if engines is not None and len(engines):
                cmp += _fmt(engines.drop(columns=["overall_order"]))
        cost = ""
        runs = pd.read_csv(run_dir / "morris_runs.csv") if (run_dir / "morris_runs.csv").exists() else pd.DataFrame()
        if "cpu_s" not in runs and (run_dir / "results.csv").exists() and (run_dir / "run.json").exists():
            try:  # written before morris_runs.csv carried the CPU: the run's own table, if it is this study's
                if json.loads((run_dir / "run.json").read_text()).get("study") == "morris":
                    runs = pd.read_csv(run_dir / "results.csv")
            except ValueError:
                pass
        if len(runs):
            if "cpu_s" in runs and runs.cpu_s.notna().any():
                c = runs.groupby("backend").agg(runs=("cpu_s", "size"), cpu_s=("cpu_s", "sum"),
                                                cpu_per_run_s=("cpu_s", "mean"), failed=(
                                                    "status", lambda v: int(v.isin(["failed", "timeout"]).sum())))
                c["vs_pinocchio"] = c.cpu_per_run_s / c.cpu_per_run_s.get("pinocchio", np.nan)
                cost = ("<h3>What this study cost per engine (CPU seconds of the jobs, as run)</h3>"
                        + c.reset_index().to_html(index=False, float_format=lambda v: f"{v:.3g}")
                        + "<p><code>canebench bench --morris</code> times the same study per engine on a subset "
                          "and extrapolates it to 1,040 runs, with the paper (40 kHz) protocol's estimate.</p>")
        parts.append("<h2>Method of Morris</h2><p>Segments 3-20, probe angle -30..30 degrees, modulus "
                     "1.82-8.05 GPa, diameter factor 0-1; 6 levels, 4 trajectories (SALib, fixed seed); one "
                     "analysis per trial and engine on the simulated stiffness.</p><img src='morris.png'>"
                     + (f"<h3>Factor ranking by mean mu* per engine</h3>{_fmt(rank)}" if rank is not None else "")
                     + cmp + cost)
    if (run_dir / "sweep_best.csv").exists():
        best = pd.read_csv(run_dir / "sweep_best.csv")
        sweep_figure(best, naive, run_dir / "sweep.png")
        summ = json.loads((run_dir / "sweep_summary.json").read_text()) if (run_dir / "sweep_summary.json").exists() \
            else {}
        rows = pd.DataFrame([{"backend": b, **v} for b, v in summ.items()])
        parts.append("<h2>Parameter sweep: modulus x diameter factor</h2><p>5 levels each over the Morris bounds; "
                     "per trial the lowest |log ratio|. A best point on the highest modulus, still more than 2x "
                     "too soft, means the sweep's box does not contain the answer for that trial.</p>"
                     f"<img src='sweep.png'>{_fmt(rows) if len(rows) else ''}")
    return "".join(parts)

