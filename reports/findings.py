"""A short, numeric findings section, each finding beside the paper's statement.

Built only from files: a folder's ``naive.csv``, ``morris_ranking.csv``,
``sweep_best.csv`` / ``sweep_summary.json`` (the paper studies, run into one
folder) and the dataset named in ``run.json`` (for the published-data checks).
"""

from __future__ import annotations

import html
import json
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

PAPER = {
    "naive": "field stiffness 0.009-1.2 N/mm, simulation 0.003-10.4 N/mm; errors as high as 10x",
    "height": "the best alignment is almost always the highest push point, then the middle, then the lowest",
    "morris": "flexural modulus most important; diameter factor second; segments middle; probe angle low",
    "sweep": "in most cases a reasonable model lies in the sweep's parameter space, but not the same for every cane",
    "protocol": "setpoint +0.5 mm every second, 90 s per trial (0.5 mm/s)",
    "spacing": "push points about four inches (102 mm) apart, trial 1 the highest",
    "contact": "IMU contact detection: 12 trials with contact; 41 full, 11 partial, 2 excluded",
    "truncation": "a trial with contact is truncated at the contact (a partial trial)",
    "engines": "(one engine, MuJoCo, in the paper)",
}


def data_checks(dataset: Path) -> dict[str, Any]:
    """What the published field data says about the protocol and the push points."""
    from canebench.data.rig import read_rig_csv

    pp = pd.read_csv(dataset / "push_points.csv")
    steps, durations, speeds = [], [], []
    for f in pp.file:
        tr = read_rig_csv(dataset / f)
        dt = np.diff(tr.time_s)
        steps.append(float(np.median(dt)))
        durations.append(float(tr.time_s[-1]))
        dx = np.diff(tr.displacement_mm)
        speeds.append(float(np.median(dx / dt)))
    spacing, not_top = [], []
    for (b, c), g in pp.groupby(["bush", "cane"]):
        h = g.sort_values("height_mm").height_mm.to_numpy()
        spacing += list(np.diff(h))
        if int(g.loc[g.height_mm.idxmax(), "trial"]) != 1:
            not_top.append(f"b{b}c{c}")
    return {"sample_period_s": float(np.median(steps)), "speed_mm_per_s": float(np.median(speeds)),
            "longest_trial_s": float(max(durations)), "spacing_mm": (float(min(spacing)), float(np.median(spacing)),
                                                                     float(max(spacing))),
            "trial1_not_highest": not_top}


def findings(run_dir: Path) -> list[tuple[str, str, str]]:
    """(topic, what this run measured, what the paper says) for every study found in ``run_dir``."""
    run_dir = Path(run_dir)
    rows: list[tuple[str, str, str]] = []
    if (run_dir / "naive.csv").exists():
        t = pd.read_csv(run_dir / "naive.csv")
        ok = t[t.status == "ok"]
        for b, g in ok.groupby("backend"):
            worst = g.reindex(g.log_ratio.abs().sort_values(ascending=False).index).head(3)
            rows.append(("naive case", f"{b}: {len(g)} scored trials; field {g.k_field.min():.3g}-{g.k_field.max():.3g} "
                         f"N/mm, simulation {g.k_sim.min():.3g}-{g.k_sim.max():.3g} N/mm; median |ln ratio| "
                         f"{g.log_ratio.abs().median():.2f} (x{np.exp(g.log_ratio.abs().median()):.1f}), worst "
                         + ", ".join(f"{r.trial} x{np.exp(abs(r.log_ratio)):.1f}" for r in worst.itertuples()),
                         PAPER["naive"]))
        b0 = sorted(ok.backend.unique())[0] if len(ok) else None
        if b0 is not None:
            g = ok[ok.backend == b0].copy()
            g["abs"] = g.log_ratio.abs()
            by_rank = g.groupby("height_rank")["abs"].median()
            best_rank = g.loc[g.groupby("cane")["abs"].idxmin()].height_rank.value_counts().sort_index()
            rows.append(("push height", "median |ln ratio| by height rank (1 = highest): "
                         + ", ".join(f"{int(k)}: {v:.2f}" for k, v in by_rank.items())
                         + "; the best-fitting point of a cane is rank "
                         + ", ".join(f"{int(k)} on {v} canes" for k, v in best_rank.items()), PAPER["height"]))
            rho = g[["abs", "diameter_mm"]].corr(method="spearman").iloc[0, 1]
            from canebench.studies.paper import variance_between

            share = variance_between(g, "cane")["share_between"]
            rows.append(("where the error lies", f"{share:.0%} of the log-ratio variance lies between canes (the "
                         f"error is a property of the cane); Spearman rho of |ln ratio| with caliper diameter "
                         f"{rho:.2f}", "a local diameter is insufficient; lower points rely on extrapolated diameters"))
    if (run_dir / "naive_truncation.csv").exists():
        for r in pd.read_csv(run_dir / "naive_truncation.csv").itertuples():
            rows.append(("truncation rule", f"{r.backend}: {r.partial} partial trials scored up to the contact; "
                         f"median |ln ratio| {r.median_abs_log_ratio_whole:.2f} whole, "
                         f"{r.median_abs_log_ratio_truncated:.2f} with the rule ({r.scored_truncated} trials scored)",
                         PAPER["truncation"]))
    if (run_dir / "morris_ranking.csv").exists():
        r = pd.read_csv(run_dir / "morris_ranking.csv").sort_values(["backend", "rank"])
        for b, g in r.groupby("backend"):
            rows.append(("Method of Morris", f"{b}: " + " > ".join(g.factor), PAPER["morris"]))
        if (run_dir / "morris_engines.csv").exists():
            from canebench.studies.paper import morris_engine_sentence

            rows.append(("Method of Morris across engines",
                         morris_engine_sentence(pd.read_csv(run_dir / "morris_engines.csv")), PAPER["engines"]))
    if (run_dir / "contact_meta.json").exists():
        m = json.loads((run_dir / "contact_meta.json").read_text())
        c = m["counts"]
        ev, evt = m.get("force_events", {}), m.get("force_event_trials", {})
        rows.append(("contact detection", f"{m['primary_method']} detector: {c['full']} full, {c['partial']} "
                     f"partial, {c['excluded']} excluded of {m['n_trials']}; force-only events: "
                     f"{ev.get('stiffening', 0)} stiffening elbows ({evt.get('stiffening', 0)} trials), "
                     f"{ev.get('softening', 0)} softening ({evt.get('softening', 0)} trials), {ev.get('drop', 0)} "
                     f"slips over 30 gf ({evt.get('drop', 0)} trials)", PAPER["contact"]))
    if (run_dir / "sweep_summary.json").exists():
        for b, v in json.loads((run_dir / "sweep_summary.json").read_text()).items():
            rows.append(("parameter sweep", f"{b}: best point at the highest modulus (8.05 GPa) on "
                         f"{v['best_at_highest_modulus']} of {v['trials']} trials, on a bound on {v['best_on_a_bound']}; "
                         f"{v['still_2x_too_soft']} remain more than 2x too soft at the box's stiffest corner, so for "
                         f"them the box does not contain the answer; median best |ln ratio| "
                         f"{v['median_abs_log_ratio_best']:.2f}", PAPER["sweep"]))
    meta = {}
    if (run_dir / "run.json").exists():
        try:
            meta = json.loads((run_dir / "run.json").read_text())
        except ValueError:
            meta = {}
    ds = Path(meta.get("dataset", ""))
    if ds.is_dir() and (ds / "push_points.csv").exists() and not (ds / "canes").is_dir():
        d = data_checks(ds)
        rows.append(("published data: protocol", f"rig samples every {d['sample_period_s']:.2f} s at "
                     f"{d['speed_mm_per_s']:.2f} mm/s (0.5 mm per sample), longest trial {d['longest_trial_s']:.0f} s",
                     PAPER["protocol"]))
        lo, med, hi = d["spacing_mm"]
        rows.append(("published data: push points", f"spacing {lo:.0f}-{hi:.0f} mm (median {med:.0f}); trial 1 is "
                     f"not the highest push point on {len(d['trial1_not_highest'])} cane(s) "
                     f"({', '.join(d['trial1_not_highest'])})", PAPER["spacing"]))
    return rows


def findings_html(run_dir: Path) -> str:
    rows = findings(run_dir)
    if not rows:
        return ""
    body = "".join(f"<tr><td>{html.escape(a)}</td><td>{html.escape(b)}</td><td>{html.escape(c)}</td></tr>"
                   for a, b, c in rows)
    return ("<h2>Findings</h2><table><tr><th>topic</th><th>measured here</th><th>the paper says</th></tr>"
            f"{body}</table>")
