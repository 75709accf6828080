"""Discovery figures and report section, rebuilt from the files ``canebench discover`` wrote."""

from __future__ import annotations

import html
import json
from pathlib import Path

import numpy as np
import pandas as pd


def figures(out: str | Path) -> list[Path]:
    """``discovery_gap.png`` (per trial, before vs out-of-sample after) and ``discovery_residuals.png``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out)
    df = pd.read_csv(out / "discovery.csv")
    doc = json.loads((out / "discovery.json").read_text())
    d = df[np.isfinite(df.r_before)].sort_values("r_before")
    paths = []
    fig, ax = plt.subplots(figsize=(9, 4))
    x = np.arange(len(d))
    ax.axhline(0, color="k", lw=0.8)
    ax.plot(x, d.r_before, "o", ms=4, label=f"before ({doc['baseline']} baseline)")
    ax.plot(x, d.r_after_cv, "s", ms=4, mfc="none",
            label=("partial model (not named)" if doc.get("partial") else "after") + ", out of sample (leave one cane out)")
    for xi, a, b in zip(x, d.r_before, d.r_after_cv):
        ax.plot([xi, xi], [a, b], color="0.7", lw=0.6)
    ax.set_xticks(x)
    ax.set_xticklabels(d.trial, rotation=90, fontsize=6)
    ax.set_ylabel("ln(k_field / k_model)")
    named = ", ".join(n["effect"] for n in doc["named"]) or "nothing named"
    g = doc["gap"]
    after = g["after_cv"]
    if doc.get("partial"):  # the points are the library's best account, whose names were withheld
        named += "; partial (not named): " + ", ".join(n["effect"] for n in doc["partial"])
        after = g["partial_after_cv"]
    ax.set_title(f"{named}: median |ln| {g['before']['median_abs_log_ratio']:.3f} -> "
                 f"{after['median_abs_log_ratio']:.3f} out of sample", fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    p = out / "discovery_gap.png"
    fig.savefig(p, dpi=120)
    plt.close(fig)
    paths.append(p)
    # the level on the baseline's ln k, one x for both residuals (the field's ln k contains them)
    if "k_base" in d:
        d = d.assign(log_k_base=np.log(d.k_base.where(d.k_base > 0)))
    feats = ["height_m", "diameter_mm", "above_lowest_caliper_m", "log_k_base"]
    fig, axes = plt.subplots(1, len(feats), figsize=(12, 3), sharey=True)
    for ax, f in zip(axes, feats):
        if f in d:
            ax.plot(d[f], d.r_before, "o", ms=3, label="before")
            ax.plot(d[f], d.r_after_cv, "s", ms=3, mfc="none",
                    label="partial model, not named (CV)" if doc.get("partial") else "after (CV)")
        ax.axhline(0, color="k", lw=0.6)
        ax.set_xlabel(f)
    axes[0].set_ylabel("ln(k_field / k_model)")
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    p = out / "discovery_residuals.png"
    fig.savefig(p, dpi=120)
    plt.close(fig)
    paths.append(p)
    return paths


def section(folder: str | Path) -> str:
    """HTML section for a folder holding ``discovery.json`` (empty string if none)."""
    from canebench.discovery.checks_text import adequacy_lines, change_text, rivals_text, scope_text
    from canebench.discovery.verdict import UNEXPLAINED_WHY

    folder = Path(folder)
    f = folder / "discovery.json"
    if not f.exists():
        return ""
    doc = json.loads(f.read_text())
    g = doc["gap"]
    rows = []
    partial = doc.get("partial") or []
    for n in doc["named"] + partial:
        ps = "; ".join(f"{k} = {v:.4g} [{n['ci95'][k][0]:.4g}, {n['ci95'][k][1]:.4g}] {n.get('units', {}).get(k, '')}"
                       if k in n.get("ci95", {}) else f"{k} = {v:.4g}" for k, v in n["params"].items())
        if c := change_text(n):
            ps += f"; alone: {c}"
        if c := scope_text(n):
            ps += f"; {c}"
        if n["effect"] == "obstruction":
            ps = f"{n.get('n_trials', len(n.get('local', {})))} trial(s): " + ", ".join(
                f"{t} at {v['onset_mm']:.1f} mm" + (" (soft contact before it: left out)" if v.get("excluded") else "")
                for t, v in n.get("local", {}).items())
        label = html.escape(n["effect"]) + (" <i>(partial: not named)</i>" if n in partial else "") + (
            f" <i>({html.escape(r)})</i>" if (r := rivals_text(n)) else "")
        rows.append(f"<tr><td>{label}</td><td>{n['scope']}</td><td>{html.escape(ps)}</td></tr>")
    eng = ""
    if "per_backend" in g:
        which = "the partial model" if any(v.get("model") == "partial" for v in g["per_backend"].values()) else \
            "the named model"
        eng = f"<p>Every engine before and with {which}:</p>" \
              "<table><tr><th>backend</th><th>before median / worst</th><th>after (in sample)</th>" \
              "<th>after, out of sample</th><th>screen vs engine (max |d ln k|): anchored / linear only</th></tr>" + "".join(
            f"<tr><td>{b}</td><td>{v['before_median']:.3f} / {v['before_worst']:.3f}</td>"
            f"<td>{v['after_median']:.3f} / {v['after_worst']:.3f}</td>"
            f"<td>{v['after_cv_median']:.3f} / {v['after_cv_worst']:.3f}</td><td>{v['screen_vs_engine_max']:.2g} / "
            f"{v.get('linear_screen_vs_engine_max', float('nan')):.2g}</td></tr>"
            for b, v in g["per_backend"].items()) + "</table>"
    notes = "".join(f"<li>{html.escape(n)}</li>" for n in doc.get("notes", []))
    anc = doc.get("anchors") or []
    if anc:
        last = anc[-1]
        notes += (f"<li>the screen was re-anchored on the {html.escape(str(last['engine']))} engine {len(anc)} time(s) "
                  f"during the selection; before each re-anchoring the engine differed from the screen by at most "
                  f"{max(a['engine_minus_screen_max_abs'] for a in anc):.3g} in ln k, at the last by "
                  f"{last['engine_minus_screen_max_abs']:.3g}</li>")
    bs = doc.get("between_cane_share", {})
    notes += "".join(f"<li>{html.escape(line)}</li>" for line in adequacy_lines(doc))
    if "partial_after_cv" in g:
        notes += (f"<li>the partial model's gap, out of sample: median {g['partial_after_cv']['median_abs_log_ratio']:.3f}"
                  f" (worst {g['partial_after_cv']['worst_abs_log_ratio']:.3f}); model_partial.yaml holds it</li>")
    return f"""
<h2>Discovery: what the model misses</h2>
<p>Baseline <b>{html.escape(doc['baseline'])}</b>. Median |ln(k_model/k_field)|
{g['before']['median_abs_log_ratio']:.3f} (worst {g['before']['worst_abs_log_ratio']:.3f}) before;
{g['after_cv']['median_abs_log_ratio']:.3f} (worst {g['after_cv']['worst_abs_log_ratio']:.3f}) after, out of sample
(leave one cane out). Share of the residual variance between canes: {bs.get('before', float('nan')):.2f} before,
{bs.get('after_cv', float('nan')):.2f} after{' (the partial model)' if doc.get('partial') else ''}. Unexplained ({UNEXPLAINED_WHY}): <b>{doc['unexplained']}</b>.
Selection stopped: {html.escape(doc.get('stop_reason', ''))}.</p>
<table><tr><th>named effect</th><th>scope</th><th>parameters (95 % cane-bootstrap interval)</th></tr>{''.join(rows) or '<tr><td colspan=3>nothing named</td></tr>'}</table>
{eng}
<ul>{notes}</ul>
<img src="discovery_gap.png" width="800"><br><img src="discovery_residuals.png" width="800">
"""
