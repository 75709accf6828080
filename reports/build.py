"""Build a run's report (PNG figures + HTML page) from its CSV and JSON files.

Everything is read back from ``results.csv``, ``traces.csv``, ``field.csv``
and ``run.json``, so any figure can be rebuilt without re-simulating:
``canebench report RUN_DIR``.
"""

from __future__ import annotations

import html
import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

MARKERS = {1: "o", 2: "s", 3: "^"}


def _height_class(df: pd.DataFrame) -> pd.Series:
    """Low / Middle / High push point on each cane (by height rank)."""
    rank = df.groupby("cane")["height_mm"].rank(method="first")
    return rank.map({1.0: 30.0, 2.0: 60.0, 3.0: 110.0}).fillna(60.0)


def _save(fig, path: Path, res: pd.DataFrame | None, dpi: int = 100) -> None:  # noqa: ANN001
    """Save a figure with the run's assumptions stamped under it (a figure travels without its page)."""
    from canebench.execute.pipeline import ASSUMPTION_SEP

    notes: list[str] = []
    if res is not None and "assumptions" in res.columns:
        for a in res["assumptions"].dropna().unique():
            notes += [x.strip() for x in str(a).split(ASSUMPTION_SEP) if x.strip()]
    notes = list(dict.fromkeys(notes))
    if notes:
        fig.subplots_adjust(bottom=min(0.35, fig.subplotpars.bottom + 0.045 * len(notes)))
        fig.text(0.01, 0.005, "\n".join(f"assumption: {n}" for n in notes), fontsize=7, va="bottom", ha="left",
                 color="#a33")
    fig.savefig(path, dpi=dpi)
    plt.close(fig)


def stiffness_plot(res: pd.DataFrame, path: Path) -> Path:
    """Paper Fig. 'doubleplot': simulated vs field stiffness per trial, log axes, 1:1 line."""
    backends = sorted(res.backend.unique())
    fig, axes = plt.subplots(1, len(backends), figsize=(5.2 * len(backends), 4.8), squeeze=False)
    cmap = plt.get_cmap("tab10")
    for ax, b in zip(axes[0], backends):
        d = res[(res.backend == b) & (res.status == "ok")].copy()
        if len(d):
            d["size"] = _height_class(d)
            cane_no = d.cane.str.extract(r"c(\d+)$")[0].astype(float).fillna(1).astype(int)
            for (bush, cn), g in d.groupby([d.bush, cane_no]):
                ax.scatter(g.k_field, g.k_sim, s=g["size"], marker=MARKERS.get(cn, "o"), color=cmap((bush - 1) % 10),
                           edgecolor="k", linewidth=0.4, label=f"bush {bush}" if cn == 1 else None)
            lo = min(d.k_field.min(), d.k_sim.min()) / 1.5
            hi = max(d.k_field.max(), d.k_sim.max()) * 1.5
            ax.plot([lo, hi], [lo, hi], "k--", lw=1, label="1:1")
            ax.set_xlim(lo, hi)
            ax.set_ylim(lo, hi)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("field stiffness (N/mm)")
        ax.set_ylabel("simulated stiffness (N/mm)")
        ax.set_title(f"{b}: marker = cane, size = push height")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    _save(fig, path, res, dpi=110)
    return path


def log_ratio_plot(res: pd.DataFrame, path: Path) -> Path:
    """Paper Fig. 'logplot': ln(k_sim / k_field) per trial and backend."""
    d = res[res.status == "ok"]
    trials = list(dict.fromkeys(res.trial))
    backends = sorted(d.backend.unique())
    fig, ax = plt.subplots(figsize=(max(8, 0.22 * len(trials) * max(1, len(backends))), 4))
    w = 0.8 / max(1, len(backends))
    x = np.arange(len(trials))
    for i, b in enumerate(backends):
        g = d[d.backend == b].set_index("trial").reindex(trials)
        ax.bar(x + (i - (len(backends) - 1) / 2) * w, g.log_ratio, width=w, label=b)
    ax.axhline(0, color="k", lw=0.8)
    ax.set_xticks(x)
    ax.set_xticklabels(trials, rotation=90, fontsize=7)
    ax.set_ylabel("ln(k_sim / k_field)")
    ax.legend(fontsize=8)
    ax.grid(True, axis="y", alpha=0.3)
    fig.tight_layout()
    _save(fig, path, res, dpi=110)
    return path


def traces_plot(traces: pd.DataFrame, res: pd.DataFrame, path: Path, n: int = 6) -> Path:
    """Force against displacement for a few trials: field samples and each backend."""
    trials = list(dict.fromkeys(res.trial))[:: max(1, len(set(res.trial)) // n)][:n]
    fig, axes = plt.subplots(1, len(trials), figsize=(3.2 * len(trials), 3), squeeze=False)
    for ax, t in zip(axes[0], trials):
        for b, g in traces[traces.trial == t].groupby("backend"):
            style = dict(ls="none", marker=".", ms=3, color="k") if b == "field" else dict(lw=1.2)
            ax.plot(g.displacement_mm, g.force_n, label=b, **style)
        ax.set_title(t, fontsize=9)
        ax.set_xlabel("displacement (mm)")
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("force (N)")
    if axes[0][0].get_legend_handles_labels()[0]:
        axes[0][0].legend(fontsize=7)
    fig.tight_layout()
    _save(fig, path, res, dpi=100)
    return path


def _per_trial_lines(series: dict[str, pd.Series], trials: list[str], ylabel: str, path: Path,
                     log: bool = False, unity: bool = False, res: pd.DataFrame | None = None) -> Path:
    """One line per backend over the trials (x axis: trial ids)."""
    fig, ax = plt.subplots(figsize=(max(8, 0.2 * len(trials)), 4))
    for name, values in series.items():
        ax.plot(range(len(trials)), values, marker="o", ms=3, lw=0.8, label=name)
    if unity:
        ax.axhline(1, color="k", lw=0.6)
    if log:
        ax.set_yscale("log")
    ax.set_xticks(range(len(trials)))
    ax.set_xticklabels(trials, rotation=90, fontsize=7)
    ax.set_ylabel(ylabel)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    _save(fig, path, res, dpi=100)
    return path


def comparison_plots(res: pd.DataFrame, run_dir: Path) -> list[Path]:
    """Engine comparison: stiffness per engine and trial, the agreement matrix
    against Pinocchio as a heat map, and wall time per engine and trial."""
    from canebench.studies.agreement import REFERENCE, agreement_table

    trials = list(dict.fromkeys(res.trial))
    backends = sorted(res.backend.unique())
    k_all = {b: res[res.backend == b].set_index("trial").reindex(trials).k_sim for b in backends}
    paths = [_per_trial_lines(k_all, trials, "k_sim (N/mm)", run_dir / "engines_stiffness.png", log=True,
                              res=res)]

    if REFERENCE in backends:
        tab = agreement_table(res)
        others = [b for b in backends if b != REFERENCE]
        M = tab.pivot(index="backend", columns="trial", values="rel_to_ref").reindex(index=others, columns=trials)
        failed = tab.assign(bad=~tab.status.isin(["ok", "unscored"])).pivot(
            index="backend", columns="trial", values="bad").reindex(index=others, columns=trials)
        val = np.log10(np.clip(M.abs().to_numpy(dtype=float), 1e-9, None))
        fig, ax = plt.subplots(figsize=(max(8, 0.2 * len(trials)), 0.5 * len(others) + 1.6))
        im = ax.imshow(val, aspect="auto", cmap="viridis", vmin=-8, vmax=-1)
        for (i, j), bad in np.ndenumerate(failed.to_numpy(dtype=bool)):
            if bad:
                ax.text(j, i, "x", ha="center", va="center", color="red", fontsize=8)
        ax.set_yticks(range(len(others)))
        ax.set_yticklabels(others)
        ax.set_xticks(range(len(trials)))
        ax.set_xticklabels(trials, rotation=90, fontsize=7)
        fig.colorbar(im, ax=ax, label=f"log10 |k / k_{REFERENCE} - 1|   (x = failed)")
        fig.tight_layout()
        paths.append(run_dir / "agreement_heatmap.png")
        _save(fig, paths[-1], res, dpi=100)

    fig, ax = plt.subplots(figsize=(7, 4))
    data = [res[res.backend == b].wall_s.to_numpy() for b in backends]
    ax.boxplot(data, tick_labels=backends)
    for i, d in enumerate(data, start=1):
        ax.plot(np.full(len(d), i) + np.random.default_rng(0).uniform(-0.15, 0.15, len(d)), d, ".", ms=3, alpha=0.6)
    ax.set_yscale("log")
    ax.set_ylabel("wall time per trial (s)")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    paths.append(run_dir / "wall_time.png")
    _save(fig, paths[-1], res, dpi=100)
    return paths


def _beam_section(res: pd.DataFrame, run_dir: Path) -> str:
    """Every engine against the geometrically exact beam, per trial."""
    if "beam" not in set(res.backend) or res.backend.nunique() < 2:
        return ""
    k = res[res.status.isin(["ok", "unscored"])].pivot(index="trial", columns="backend", values="k_sim")
    trials = [t for t in dict.fromkeys(res.trial) if t in k.index]
    k = k.reindex(trials)
    _per_trial_lines({b: k[b] / k["beam"] for b in k.columns if b != "beam"}, trials, "k_engine / k_beam",
                     run_dir / "engines_vs_beam.png", unity=True)
    ratio = (k.drop(columns="beam").div(k["beam"], axis=0)).describe().T[["mean", "min", "max"]]
    return ("<h2>Engines against the geometrically exact beam</h2><p>Each engine probes the chain; the beam is "
            "the continuous rod the chain approximates (same geometry, diameter line, modulus, protocol).</p>"
            f"{ratio.to_html(float_format=lambda v: f'{v:.4g}')}<img src=\"engines_vs_beam.png\">")


def _convergence_section(run_dir: Path) -> str:
    """The beam/chain convergence study, if ``canebench converge`` wrote here."""
    path = run_dir / "convergence.csv"
    if not path.exists():
        return ""
    from canebench.reports.convergence import beam_mesh_html, chain_plot, exceedances, rod_plot, summary

    df = pd.read_csv(path)
    mesh_html = ""
    if (run_dir / "beam_mesh.csv").exists():
        mesh_html = beam_mesh_html(pd.read_csv(run_dir / "beam_mesh.csv"))
    chain_plot(df, run_dir / "chain_convergence.png")
    rod_html = ""
    if (run_dir / "rod_convergence.csv").exists():
        rod = pd.read_csv(run_dir / "rod_convergence.csv")
        rod_plot(rod, run_dir / "rod_convergence.png")
        rod_html = ('<h3>Beam solver convergence</h3><img src="rod_convergence.png">'
                    + rod.to_html(index=False, float_format=lambda v: f"{v:.3e}"))
    summ = summary(df)
    exc = exceedances(df)
    exc_twist = exceedances(df, "dual_length+twist") if (df.formula == "dual_length+twist").any() else None
    fmt = {"float_format": lambda v: f"{v:.4f}", "index": False}
    twist_html = ""
    if exc_twist is not None:
        twist_html = ("<h3>The same with the twist joint (<code>--set twist_joint=true</code>)</h3>"
                      + (exc_twist.to_html(**fmt) if len(exc_twist) else
                         "<p>none: with a twist joint per link every bundled push point is within 1 % of the "
                         "beam (with torsion, nu = 0.3) at 20 segments</p>"))
    return ("<h2>Chain against beam: convergence with segments</h2>"
            "<p>Small deflection, gravity off: the chain's linear stiffness (Pinocchio, J K^-1 J^T) over the "
            "beam's. The paper's K = 2EI/L converges to about twice the beam's stiffness; K = EI/L approaches it "
            "from below at first order; the beam-consistent dual-length formula converges at second order. The "
            "paper's chains have no twist joint, so they cannot follow the beam's torsional compliance; "
            "<code>dual_length+twist</code> adds one per link (model option <code>twist_joint</code>).</p>"
            '<img src="chain_convergence.png">'
            f"<h3>Error against the beam at 10 and 20 segments</h3>{summ.to_html(**fmt)}"
            f"<h3>Dual-length chains more than 1 % from the beam at 20 segments, and why</h3>"
            f"{exc.to_html(**fmt) if len(exc) else '<p>none</p>'}" + twist_html + mesh_html + rod_html)


def summary_table(res: pd.DataFrame) -> pd.DataFrame:
    rows = []
    for b, g in res.groupby("backend"):
        ok = g[g.status == "ok"]
        rows.append({
            "backend": b, "trials": len(g), "scored": len(ok), "failed": int((g.status == "failed").sum()),
            "unscored": int((g.status == "unscored").sum()),
            "median |log ratio|": ok.log_ratio.abs().median(), "mean log ratio": ok.log_ratio.mean(),
            "max |log ratio|": ok.log_ratio.abs().max(), "median wall s": g.wall_s.median(),
            "total wall s": g.wall_s.sum(),
        })
    return pd.DataFrame(rows)


def _read_table(path: Path, required: bool = False) -> pd.DataFrame:
    """A run folder's CSV; an empty or missing optional file is an empty table."""
    from canebench.errors import InputError

    if not path.exists():
        if required:
            raise InputError(str(path.parent), path.name, "missing: is this a canebench run folder?")
        return pd.DataFrame()
    try:
        return pd.read_csv(path)
    except pd.errors.EmptyDataError:
        return pd.DataFrame()


def _state_section(meta: dict) -> str:
    """Say plainly when a run did not finish, and how to resume it."""
    state = meta.get("state")
    if state in (None, "complete"):
        return ""
    done, total = meta.get("jobs_done", "?"), meta.get("jobs_total", "?")
    return ('<p style="background:#ffd;padding:8px;border:1px solid #cc8"><b>Incomplete run</b> '
            f'({html.escape(str(state))}): {done} of {total} jobs have results, {meta.get("jobs_missing", "?")} '
            f'are missing. Every table and figure below shows only the finished jobs. '
            f'{html.escape(str(meta.get("resume", "")))}</p>')


def _field_section(run_dir: Path) -> str:
    """Field stiffness with its uncertainty, from ``field.csv``."""
    field = _read_table(run_dir / "field.csv")
    if not len(field) or "k_field" not in field.columns:
        return ""
    cols = [c for c in ("trial", "k_field", "k_se", "k_ci_low", "k_ci_high", "k_first_10mm", "r2", "onset_mm",
                        "tare_gf", "usable", "reason") if c in field.columns]
    usable = field[field.usable.astype(bool)] if "usable" in field.columns else field
    rel = (usable.k_ci_high - usable.k_ci_low) / (2 * usable.k_field) if "k_ci_low" in usable.columns else None
    window = field.window_mm.dropna().unique() if "window_mm" in field.columns else []
    note = (f"{len(usable)} of {len(field)} trials have a slope; 95 % bootstrap interval half-width median "
            f"{rel.median():.1%} of the slope (widest {rel.max():.1%}); fit window "
            f"{'first ' + str(window[0]) + ' mm' if len(window) else 'the whole contact'}. Thresholds apply to "
            "the tared contact force (the rig's own script tested the raw reading).") if rel is not None else ""
    return (f"<h2>Field stiffness and its uncertainty</h2><p>{html.escape(note)}</p>"
            + field[cols].to_html(index=False, float_format=lambda v: f"{v:.4g}"))


def read_meta(run_dir: Path) -> dict:
    """``run.json``, or a note that it is missing or unreadable (the tables still make a report)."""
    p = run_dir / "run.json"
    if not p.exists():
        return {"assumptions": ["run.json missing: provenance unknown"]}
    try:
        return json.loads(p.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        return {"assumptions": [f"run.json unreadable ({exc}): provenance unknown"]}


def _study_sections(run_dir: Path) -> str:
    """Sections of the studies whose files are in the folder (rebuilt from those files)."""
    from canebench.reports.findings import findings_html
    from canebench.reports.paper import paper_sections

    parts = [findings_html(run_dir), paper_sections(run_dir)]
    if (run_dir / "contact_meta.json").exists():
        from canebench.studies.contact import contact_section_html

        parts.append(contact_section_html(run_dir))
    if (run_dir / "modulus_meta.json").exists():
        from canebench.studies.modulus import modulus_section_html

        parts.append(modulus_section_html(run_dir))
    from canebench.reports.convergence import continuum_section

    parts.append(continuum_section(run_dir))
    if (run_dir / "discovery.json").exists():
        from canebench.reports.discovery import section as discovery_section

        parts.append(discovery_section(run_dir))
    return "".join(parts)


def build_report(run_dir: Path) -> Path:
    """Write figures and ``report.html`` into ``run_dir``; return the page path.

    Every section is built from the folder's files: a run's results, and any
    study's tables (a folder may hold only a study).
    """
    run_dir = Path(run_dir)
    if not (run_dir / "results.csv").exists():
        studies = _study_sections(run_dir)
        if studies:
            page = run_dir / "report.html"
            page.write_text("<!doctype html><html><head><meta charset='utf-8'><title>canebench report</title>"
                            "<style>body{font-family:sans-serif;max-width:1200px;margin:auto} "
                            "table{border-collapse:collapse;font-size:12px} td,th{border:1px solid #ccc;"
                            "padding:2px 6px} img{max-width:100%}</style></head><body><h1>canebench report</h1>"
                            f"{studies}</body></html>")
            return page
    res = _read_table(run_dir / "results.csv", required=True)
    if "status" not in res.columns:  # written by an older or an aborted run: an empty table, not a crash
        from canebench.execute.pipeline import RESULT_COLUMNS

        res = pd.DataFrame(columns=RESULT_COLUMNS)
    traces = _read_table(run_dir / "traces.csv")
    meta = read_meta(run_dir)
    # a study's folder holds many configurations per trial: its own sections show them, the
    # one-row-per-trial figures of a run do not apply
    multi = "config_hash" in res.columns and res.config_hash.nunique() > 1
    scored = len(res) > 0 and bool((res.status == "ok").any()) and not multi
    if scored:
        stiffness_plot(res, run_dir / "stiffness.png")
        log_ratio_plot(res, run_dir / "log_ratio.png")
    if len(traces) and len(res) and not multi:
        traces_plot(traces, res, run_dir / "traces.png")
    comparison = ""
    if len(res) and res.backend.nunique() > 1 and not multi:
        cmp_figs = comparison_plots(res, run_dir)
        from canebench.studies.agreement import REFERENCE, agreement_table, pairwise

        pairs = pairwise(res)
        tab = agreement_table(res) if REFERENCE in set(res.backend) else None
        per_backend = ""
        if tab is not None:
            ok = tab[tab.status.isin(["ok", "unscored"])]
            agg = ok.groupby("backend").rel_to_ref.agg(lambda v: v.abs().max()).rename("max |k/k_ref - 1|")
            fails = tab.groupby("backend").status.agg(lambda v: int((~v.isin(["ok", "unscored"])).sum()))
            parts = [agg, fails.rename("failed")]
            if "answer" in tab.columns:
                parts.insert(0, tab.groupby("backend").answer.agg(lambda v: ", ".join(sorted(set(map(str, v))))))
            per_backend = pd.concat(parts, axis=1).to_html(float_format=lambda v: f"{v:.2e}")
            if "answer" in tab.columns and (tab.answer == "quasi-static").any():
                qs = ", ".join(sorted(set(tab[tab.answer == "quasi-static"].backend)))
                per_backend += (f"<p><b>{html.escape(qs)}: quasi-static.</b> No engine time step is taken: each "
                                "protocol step is a Newton solve on the engine's own kinematics, Jacobian and "
                                "inverse dynamics. Its agreement tests the chain's compilation into the engine "
                                "(frames, joint axes, masses, gravity) and those routines, not the engine's "
                                "integrator or its joint springs in time.</p>")
        settings = meta.get("backend_settings", {})
        config_rows = "".join(
            f"<tr><td>{html.escape(b)}</td><td>{html.escape(str(st.get('integrator')))}</td>"
            f"<td>{html.escape(str(st.get('dt')))}</td><td>{html.escape(str(st.get('springs')))}</td>"
            f"<td>{html.escape(str(st.get('pid')))}</td><td>{html.escape(str(st.get('why')))}</td></tr>"
            for b, st in settings.items())
        comparison = (
            "<h2>Engine comparison</h2>"
            "<table><tr><th>backend</th><th>integrator</th><th>dt</th><th>springs</th><th>PID</th><th>why</th></tr>"
            f"{config_rows}</table>"
            f"<h3>Against the exact statics</h3>{per_backend}"
            f"<h3>Pairwise |ln(k_a/k_b)|</h3>{pairs.to_html(index=False, float_format=lambda v: f'{v:.2e}')}"
            + "".join(f'<h3>{p.stem.replace("_", " ")}</h3><img src="{p.name}">' for p in cmp_figs))
    summ = summary_table(res)
    beam_section = _beam_section(res, run_dir) if not multi else ""
    convergence_section = _convergence_section(run_dir)
    failed = res[res.status != "ok"][["trial", "backend", "status", "reason", "field_reason"]]
    banner = ""
    if meta.get("synthetic"):
        banner = ('<p style="background:#fde;padding:8px;border:1px solid #c88"><b>SYNTHETIC DATA.</b> '
                  'These trials come from the bundled generator (canebench.canes.generate), not from the field.</p>')
    assumptions = "".join(f"<li>{html.escape(a)}</li>" for a in meta.get("assumptions", []))
    per_trial = res[[c for c in ("trial", "backend", "answer", "k_sim", "k_field", "k_field_ci_low", "k_field_ci_high",
                                 "log_ratio", "status", "n_links", "n_samples", "wall_s") if c in res.columns]]
    field_html = _field_section(run_dir)
    settings = meta.get("backend_settings", {})
    page = f"""<!doctype html><html><head><meta charset="utf-8"><title>canebench report</title>
<style>body{{font-family:sans-serif;max-width:1200px;margin:auto}} table{{border-collapse:collapse;font-size:12px}}
td,th{{border:1px solid #ccc;padding:2px 6px}} img{{max-width:100%}}</style></head><body>
<h1>canebench report</h1>{banner}
<p>Dataset: <code>{html.escape(str(meta.get('dataset', '?')))}</code>; protocol <b>{html.escape(str(meta.get('protocol', {}).get('name', '?')))}</b>;
engines {html.escape(json.dumps(meta.get('engines', {})))}; canebench {html.escape(str(meta.get('canebench', '?')))}
(commit {html.escape(str(meta.get('git_commit')))}); created {html.escape(str(meta.get('created', '?')))}.</p>
{_state_section(meta)}
<h2>Assumptions</h2><ul>{assumptions or '<li>none recorded</li>'}</ul>
<h2>Summary</h2>{summ.to_html(index=False, float_format=lambda v: f'{v:.4g}') if len(summ) else '<p>no results</p>'}
{'<h2>Stiffness per trial</h2><img src="stiffness.png"><h2>Log-ratio error</h2><img src="log_ratio.png">' if scored
 else ('<p>Several model configurations per trial: see the study sections below.</p>' if multi else
       '<p><b>No scored trial</b>: no figure of stiffness against the field.</p>')}
{'<h2>Force-displacement examples</h2><img src="traces.png">' if len(traces) and len(res) and not multi else ''}
{comparison}{beam_section}{convergence_section}{_study_sections(run_dir)}
<h2>Failed or unscored</h2>{failed.to_html(index=False) if len(failed) else '<p>none</p>'}
{field_html}
<h2>Per trial</h2>{per_trial.to_html(index=False, float_format=lambda v: f'{v:.4g}')}
<h2>Configuration</h2><pre>{html.escape(json.dumps({'model_config': meta.get('model_config'), 'protocol': meta.get('protocol'), 'backend_settings': settings}, indent=1))}</pre>
</body></html>"""
    out = run_dir / "report.html"
    out.write_text(page)
    return out


def convergence_page(run_dir: Path) -> Path:
    """The convergence study's page: the full report in a run folder, else a page of its own."""
    run_dir = Path(run_dir)
    if (run_dir / "results.csv").exists():
        return build_report(run_dir)
    page = run_dir / "convergence.html"
    page.write_text("<!doctype html><html><head><meta charset='utf-8'><title>canebench convergence</title>"
                    "</head><body style='font-family:sans-serif;max-width:1200px;margin:auto'>"
                    f"{_convergence_section(run_dir)}</body></html>")
    return page
