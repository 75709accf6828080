"""Field-trial contact detection as a study (paper: "Field Trial Contact Detection").

Every trial of a dataset (``push_points.csv`` and rig CSVs) gets the force-only
detector (:func:`canebench.measure.contact.detect_force`); trials with an IMU
log beside their rig CSV (``<stem>.imu.csv``) also get the paper's IMU rule,
which then decides the trial's status (full, partial, excluded). Writes
``contact.csv`` (one row per trial and method), ``contact_events.csv`` (force
events), ``contact_meta.json`` (counts beside the paper's) and, when the
dataset carries ``truth/contact_truth.json`` (synthetic only; read after
detection, for scoring), ``contact_scores.json``.
"""

from __future__ import annotations

import html
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from ..data.dataset import read_push_points
from ..data.imu import CHANNELS, imu_path, read_imu_csv
from ..data.rig import read_rig_csv
from ..measure.contact import ContactResult, detect_force, detect_imu
from ..units import GF_TO_N

PAPER = {"trials": 54, "contact": 12, "full": 41, "partial": 11, "excluded": 2}
TRUTH = Path("truth") / "contact_truth.json"


@dataclass
class ContactStudyResult:
    """Per-trial detections, force events, counts and (synthetic) scores."""

    rows: pd.DataFrame
    events: pd.DataFrame
    meta: dict
    scores: dict | None = None
    files: list[Path] = field(default_factory=list)

    def to_df(self) -> pd.DataFrame:
        """One row per trial and method (``imu`` when logged, always ``force``)."""
        return self.rows


def _row(tid: str, method: str, r: ContactResult, n_rig: int) -> dict:
    return {"trial": tid, "method": method, "detected": r.detected, "contact_time_s": r.contact_time_s,
            "rule": r.method, "status": r.status, "truncate_index": r.truncate_index, "n_rig": n_rig,
            "n_spikes": len(r.spikes_s),
            "n_stiffening": sum(e["kind"] == "stiffening" for e in r.events),
            "n_softening": sum(e["kind"] == "softening" for e in r.events),
            "n_drops": sum(e["kind"] == "drop" for e in r.events)}


def score(rows: pd.DataFrame, truth: dict, method: str, tol_s: float = 2.0) -> dict:
    """Precision, recall and median timing error of ``method`` against the truth (excluded trials left out).

    A detection is a true positive when the trial has contact and the detected time is
    within ``tol_s`` of it.
    """
    r = rows[rows.method == method].set_index("trial")
    keep = [t for t, v in truth.items() if not v["excluded"] and t in r.index]
    tp = fp = fn = 0
    errs = []
    for t in keep:
        det, tc = bool(r.loc[t, "detected"]), truth[t]["contact_time_s"]
        err = abs(float(r.loc[t, "contact_time_s"]) - tc) if det and tc is not None else np.inf
        if truth[t]["contact"] and err <= tol_s:
            tp += 1
            errs.append(err)
        else:
            fp += det
            fn += truth[t]["contact"]
    excl = rows[(rows.method == method) & (rows.status == "excluded")].trial.tolist()
    return {"precision": tp / (tp + fp) if tp + fp else float("nan"), "recall": tp / (tp + fn) if tp + fn else
            float("nan"), "median_timing_error_s": float(np.median(errs)) if errs else float("nan"),
            "tp": tp, "fp": int(fp), "fn": int(fn), "tolerance_s": tol_s, "n_scored": len(keep),
            "excluded_detected": excl, "excluded_true": sorted(t for t, v in truth.items() if v["excluded"])}


def contact_study(data_dir: str | Path, out_dir: str | Path | None = None) -> ContactStudyResult:
    """Detect contact in every trial of ``data_dir``; write the outputs to ``out_dir`` (if given).

    Parameters
    ----------
    data_dir : str or Path
        A dataset folder (``push_points.csv`` and the rig CSVs it names; IMU logs optional).
    out_dir : str or Path, optional
        Where ``contact.csv``, ``contact_events.csv``, ``contact_meta.json``,
        ``contact_scores.json`` (truth present) and ``contact_example.png`` go.

    Returns
    -------
    ContactStudyResult
    """
    data_dir = Path(data_dir)
    pp = read_push_points(data_dir / "push_points.csv")
    rows, events = [], []
    for p in pp.itertuples():
        tid = f"b{int(p.bush)}c{int(p.cane)}t{int(p.trial)}"
        rig = read_rig_csv(data_dir / p.file)
        rf = detect_force(rig.displacement_mm, rig.force_gf * GF_TO_N)
        rf.contact_time_s = float(rig.time_s[rf.truncate_index]) if rf.detected else float("nan")
        rows.append(_row(tid, "force", rf, len(rig.time_s)))
        events += [{"trial": tid, **e} for e in rf.events]
        ip = imu_path(data_dir / p.file)
        if ip.exists():
            rows.append(_row(tid, "imu", detect_imu(read_imu_csv(ip), rig.time_s), len(rig.time_s)))
    df = pd.DataFrame(rows)
    primary = "imu" if (df.method == "imu").any() else "force"
    status = df[df.method == primary].status.value_counts()
    counts = {k: int(status.get(k, 0)) for k in ("full", "partial", "excluded")}
    ev = pd.DataFrame(events, columns=["trial", "kind", "index", "displacement_mm", "slope_before", "slope_after",
                                       "drop_gf"])
    meta = {"data_dir": str(data_dir), "primary_method": primary, "n_trials": len(pp), "counts": counts,
            "contact": counts["partial"] + counts["excluded"], "paper": PAPER,
            "force_events": {k: int((ev.kind == k).sum()) for k in ("stiffening", "softening", "drop")},
            "force_partial": int((df[df.method == "force"].status == "partial").sum()),
            "synthetic": "SYNTHETIC" in (data_dir / "canes").joinpath("b1c1.yaml").read_text()
            if (data_dir / "canes" / "b1c1.yaml").exists() else False}
    scores = None
    if (data_dir / TRUTH).exists():  # scoring only, after every detection ran
        truth = json.loads((data_dir / TRUTH).read_text())["trials"]
        scores = {m: score(df, truth, m) for m in sorted(set(df.method))}
    res = ContactStudyResult(df, ev, meta, scores)
    if out_dir is not None:
        res.files = _write(res, data_dir, Path(out_dir))
    return res


def _write(res: ContactStudyResult, data_dir: Path, out: Path) -> list[Path]:
    out.mkdir(parents=True, exist_ok=True)
    res.rows.to_csv(out / "contact.csv", index=False)
    res.events.to_csv(out / "contact_events.csv", index=False)
    (out / "contact_meta.json").write_text(json.dumps(res.meta, indent=1))
    files = [out / "contact.csv", out / "contact_events.csv", out / "contact_meta.json"]
    if res.scores is not None:
        (out / "contact_scores.json").write_text(json.dumps(res.scores, indent=1))
        files.append(out / "contact_scores.json")
    files.append(example_figure(res, data_dir, out / "contact_example.png"))
    return files


def example_figure(res: ContactStudyResult, data_dir: Path, path: Path) -> Path:
    """IMU channels (if logged) and force-displacement of the first trial with a detection."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    r = res.rows[res.rows.detected & (res.rows.status != "excluded")]
    r = r[r.method == res.meta["primary_method"]]
    tid = r.trial.iloc[0] if len(r) else res.rows.trial.iloc[0]
    pp = read_push_points(data_dir / "push_points.csv")
    file = pp.file[[f"b{int(a)}c{int(b)}t{int(c)}" == tid for a, b, c in zip(pp.bush, pp.cane, pp.trial)]].iloc[0]
    rig = read_rig_csv(data_dir / file)
    ip = imu_path(data_dir / file)
    fig, axes = plt.subplots(1, 2 if ip.exists() else 1, figsize=(10 if ip.exists() else 5, 3.8), squeeze=False)
    ax_f = axes[0, -1]
    truth = json.loads((data_dir / TRUTH).read_text())["trials"].get(tid, {}) if (data_dir / TRUTH).exists() else {}
    if ip.exists():
        imu = read_imu_csv(ip)
        for k, ch in enumerate(CHANNELS):
            y = imu[ch] - imu[ch].rolling(20, center=True, min_periods=1).mean()
            axes[0, 0].plot(imu.time_s, y + 1.0 * k, lw=0.4, color="C0" if ch.startswith("pushed") else "C2")
        axes[0, 0].set_yticks(range(9), CHANNELS, fontsize=6)
        axes[0, 0].set_xlabel("time (s)")
        axes[0, 0].set_title(f"{tid}: detrended accelerations (offset 1 m/s^2 each)", fontsize=9)
    ax_f.plot(rig.displacement_mm, rig.force_gf * GF_TO_N, ".-", ms=3, lw=0.6, color="k")
    ax_f.set_xlabel("displacement (mm)")
    ax_f.set_ylabel("force (N, untared)")
    ax_f.set_title(f"{tid}: force-displacement", fontsize=9)
    for _, row in res.rows[res.rows.trial == tid].iterrows():
        if row.detected:
            style = {"imu": ("C3", "--"), "force": ("C1", ":")}[row.method]
            for ax in axes[0]:
                t = row.contact_time_s
                ax.axvline(t if ax is not ax_f else np.interp(t, rig.time_s, rig.displacement_mm), color=style[0],
                           ls=style[1], label=f"detected ({row.method})")
    if truth.get("contact"):
        for ax in axes[0]:
            t = truth["contact_time_s"]
            ax.axvline(t if ax is not ax_f else np.interp(t, rig.time_s, rig.displacement_mm), color="C4", lw=2,
                       alpha=0.4, label="true contact")
    ax_f.legend(fontsize=7)
    if res.meta.get("synthetic"):
        fig.text(0.01, 0.01, "SYNTHETIC DATA: not measurements", color="#a33", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def contact_section_html(out_dir: str | Path) -> str:
    """The report's contact-detection section, rebuilt from the files :func:`contact_study` wrote."""
    out_dir = Path(out_dir)
    meta = json.loads((out_dir / "contact_meta.json").read_text())
    rows = pd.read_csv(out_dir / "contact.csv")
    c, p = meta["counts"], meta["paper"]
    cmp = pd.DataFrame([{"quantity": k, "paper": p[k], "this data": v} for k, v in
                        (("contact", meta["contact"]), ("full", c["full"]), ("partial", c["partial"]),
                         ("excluded", c["excluded"]))])
    banner = ('<p style="color:#a33"><b>SYNTHETIC data</b>: injected obstruction contacts; not measurements.</p>'
              if meta.get("synthetic") else "")
    scores = ""
    if (out_dir / "contact_scores.json").exists():
        sc = json.loads((out_dir / "contact_scores.json").read_text())
        scores = "<h3>Against the injected truth</h3>" + pd.DataFrame(sc).T[
            ["precision", "recall", "median_timing_error_s", "tp", "fp", "fn"]].to_html(float_format="{:.3g}".format)
    ev = meta["force_events"]
    fmt = {"index": False, "float_format": lambda v: f"{v:.3g}", "na_rep": ""}
    return (f"<h2>Field trial contact detection</h2>{banner}"
            f"<p>Data: <code>{html.escape(meta['data_dir'])}</code>, {meta['n_trials']} trials; trial status from "
            f"the <b>{meta['primary_method']}</b> detector. IMU rule as the paper: 9 channels at 40 Hz, minus a "
            f"20-sample rolling mean, rbf binary segmentation with penalty 22.5 log n; contact when 4 channels "
            f"(one pushed) change within 1 s or the pushed cane spikes above 1.5 m/s<sup>2</sup>; a partial trial "
            f"ends at contact. Force-only events: {ev['stiffening']} stiffening elbows, {ev['softening']} softening "
            f"elbows, {ev['drop']} drops &gt; 30 gf; {meta['force_partial']} trials partial by force.</p>"
            f"<h3>Counts against the paper</h3>{cmp.to_html(index=False)}{scores}"
            f'<img src="contact_example.png">'
            f"<h3>Per trial</h3>{rows.to_html(**fmt)}")
