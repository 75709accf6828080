"""Field-trial contact detection as a study (paper: "Field Trial Contact Detection").

Every trial of a dataset (``push_points.csv`` and rig CSVs) gets the force-only
detector (:func:`canebench.measure.contact.detect_force`); trials with an IMU
log beside their rig CSV (``<stem>.imu.csv``) also get the paper's IMU rule,
which then decides the trial's status (full, partial, excluded). Runs in
process (no simulation, nothing to resume). Writes

* ``contact.csv``: one row per trial and method (detected, contact time, status,
  event counts);
* ``contact_events.csv``: every force-only event (kind, where, slopes, test statistic);
* ``contact_trials.csv``: per trial, what was found, where, whether the trial
  becomes partial, and the field stiffness of the whole trial and of the
  partial one (the truncation rule's effect on what a score is compared with);
* ``contact_sensitivity.csv``: force-only counts (and, with truth, precision and
  recall) when the detector's slope ratio or contact-force floor change;
* ``contact_meta.json``: counts beside the paper's; ``contact_scores.json``
  when the dataset carries ``truth/contact_truth.json`` (synthetic only; read
  after detection, for scoring).

:func:`contact_fields` gives the field stiffness of every trial under the
truncation rule (partial trials scored only up to the contact); the simulation
studies take it with ``truncate_contacts=True`` (``--truncate-contacts``).
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
from ..data.rig import RigTrial, read_rig_csv
from ..measure.contact import ContactResult, detect_force, detect_imu
from ..units import GF_TO_N

KINDS = ("stiffening", "softening", "drop", "onset", "bend", "dip", "bump", "spike")
#: detector variants of the sensitivity table: (label, keyword arguments of detect_force)
VARIANTS = (("default (ratio 2, 20 gf floor)", {}), ("ratio 1.5", {"ratio": 1.5}), ("ratio 3", {"ratio": 3.0}),
            ("no 20 gf floor", {"contact_gf": 0.0}), ("alpha 0.001", {"alpha": 0.001}))

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
    trials: pd.DataFrame | None = None  # per trial: found, where, partial, field stiffness full / partial
    sensitivity: pd.DataFrame | None = None  # force-only counts per detector variant

    def to_df(self) -> pd.DataFrame:
        """One row per trial and method (``imu`` when logged, always ``force``)."""
        return self.rows


def _row(tid: str, method: str, r: ContactResult, n_rig: int) -> dict:
    row = {"trial": tid, "method": method, "detected": r.detected, "contact_time_s": r.contact_time_s,
           "rule": r.method, "status": r.status, "truncate_index": r.truncate_index, "n_rig": n_rig,
           "n_spikes": len(r.spikes_s)}
    if method == "force":
        cut = [e for e in r.events if r.truncate_index is not None
               and e["index"] + (0 if e["kind"] == "drop" else 1) == r.truncate_index]
        row["cause"] = cut[0]["kind"] if cut else ""
        row["contact_mm"] = cut[0]["displacement_mm"] if cut else float("nan")
        for k in KINDS:
            row[f"n_{k}" if k != "drop" else "n_drops"] = sum(e["kind"] == k for e in r.events)
    return row


def _rig(data_dir: Path, file: str) -> RigTrial:
    return read_rig_csv(data_dir / file)


def truncated(rig: RigTrial, n: int) -> RigTrial:
    """The partial trial: the first ``n`` rig samples."""
    return RigTrial(rig.path, rig.displacement_mm[:n], rig.force_gf[:n], rig.time_s[:n], rig.height_mm)


def detect(rig: RigTrial, imu: Path | None = None, **force_kw) -> tuple[ContactResult, ContactResult | None]:
    """Force-only and (when ``imu`` exists) IMU detection on one rig trial; times from the rig's clock."""
    rf = detect_force(rig.displacement_mm, rig.force_gf * GF_TO_N, **force_kw)
    rf.contact_time_s = float(rig.time_s[min(rf.truncate_index, len(rig.time_s) - 1)]) if rf.detected \
        else float("nan")
    ri = detect_imu(read_imu_csv(imu), rig.time_s) if imu is not None and imu.exists() else None
    return rf, ri


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

    Runs in process (no simulation): a rerun recomputes everything in seconds.

    Parameters
    ----------
    data_dir : str or Path
        A dataset folder (``push_points.csv`` and the rig CSVs it names; IMU logs optional).
    out_dir : str or Path, optional
        Where ``contact.csv``, ``contact_events.csv``, ``contact_trials.csv``,
        ``contact_sensitivity.csv``, ``contact_meta.json``, ``contact_scores.json``
        (truth present) and ``contact_example.png`` go.

    Returns
    -------
    ContactStudyResult
    """
    from ..measure.field import extract_field_stiffness

    data_dir = Path(data_dir)
    pp = read_push_points(data_dir / "push_points.csv")
    rows, events, per_trial, rigs = [], [], [], {}
    for p in pp.itertuples():
        tid = f"b{int(p.bush)}c{int(p.cane)}t{int(p.trial)}"
        rig = rigs[tid] = _rig(data_dir, p.file)
        rf, ri = detect(rig, imu_path(data_dir / p.file))
        rows.append(_row(tid, "force", rf, len(rig.time_s)))
        events += [{"trial": tid, **e} for e in rf.events]
        if ri is not None:
            rows.append(_row(tid, "imu", ri, len(rig.time_s)))
        decide = ri if ri is not None else rf
        full = extract_field_stiffness(rig, n_boot=50)
        part = extract_field_stiffness(truncated(rig, decide.truncate_index), n_boot=50) \
            if decide.detected and not decide.excluded else None
        f_row = rows[-1 if ri is None else -2]
        per_trial.append({
            "trial": tid, "method": "imu" if ri is not None else "force", "status": decide.status,
            "found": "; ".join(f"{e['kind']} at {e['displacement_mm']:.1f} mm" for e in rf.events
                               if e["kind"] not in ("bend", "onset")),
            "cause": f_row["cause"] if ri is None else decide.method, "contact_mm": (
                f_row["contact_mm"] if ri is None else
                float(np.interp(ri.contact_time_s, rig.time_s, rig.displacement_mm)) if ri.detected else np.nan),
            "kept_samples": decide.truncate_index if decide.detected else len(rig.time_s),
            "n_rig": len(rig.time_s), "k_field_full": full.k_n_per_mm,
            "k_field_partial": part.k_n_per_mm if part is not None else np.nan,
            "partial_usable": bool(part.usable) if part is not None else np.nan,
            "partial_reason": part.reason if part is not None else "",
            "noise_gf": rf.noise.get("sigma_gf", np.nan), "noise_rho": rf.noise.get("rho", np.nan)})
    df = pd.DataFrame(rows)
    primary = "imu" if (df.method == "imu").any() else "force"
    status = df[df.method == primary].status.value_counts()
    counts = {k: int(status.get(k, 0)) for k in ("full", "partial", "excluded")}
    ev = pd.DataFrame(events, columns=["trial", "kind", "index", "displacement_mm", "end_mm", "knees", "slope_before",
                                       "slope_after", "ratio", "W", "critical", "drop_gf", "samples"])
    trials = pd.DataFrame(per_trial)
    truth = json.loads((data_dir / TRUTH).read_text())["trials"] if (data_dir / TRUTH).exists() else None
    sens = sensitivity(rigs, truth)
    fr = df[df.method == "force"]
    meta = {"data_dir": str(data_dir), "primary_method": primary, "n_trials": len(pp), "counts": counts,
            "contact": counts["partial"] + counts["excluded"], "paper": PAPER,
            "force_events": {k: int((ev.kind == k).sum()) for k in KINDS},
            "force_event_trials": {k: int(ev[ev.kind == k].trial.nunique()) for k in KINDS},
            "force_partial": int((fr.status == "partial").sum()),
            "force_partial_by_cause": {k: int(v) for k, v in fr[fr.status == "partial"].cause.value_counts().items()},
            "partial_unusable": int((trials.partial_usable == False).sum()),  # noqa: E712
            "synthetic": "SYNTHETIC" in (data_dir / "canes").joinpath("b1c1.yaml").read_text()
            if (data_dir / "canes" / "b1c1.yaml").exists() else False}
    scores = None
    if truth is not None:  # scoring only, after every detection ran
        scores = {m: score(df, truth, m) for m in sorted(set(df.method))}
    res = ContactStudyResult(df, ev, meta, scores, trials=trials, sensitivity=sens)
    if out_dir is not None:
        res.files = _write(res, data_dir, Path(out_dir))
    return res


def sensitivity(rigs: dict[str, RigTrial], truth: dict | None = None) -> pd.DataFrame:
    """Force-only counts (and, with truth, precision/recall) for each detector variant in :data:`VARIANTS`."""
    out = []
    for label, kw in VARIANTS:
        rows, evs = [], []
        for tid, rig in rigs.items():
            rf, _ = detect(rig, None, **kw)
            rows.append(_row(tid, "force", rf, len(rig.time_s)))
            evs += [e["kind"] for e in rf.events]
        df = pd.DataFrame(rows)
        r = {"variant": label, "partial": int((df.status == "partial").sum()),
             **{k: evs.count(k) for k in ("stiffening", "softening", "drop")},
             **{f"{k}_trials": int((df[f"n_{k}" if k != "drop" else "n_drops"] > 0).sum())
                for k in ("stiffening", "softening", "drop")}}
        if truth is not None:
            sc = score(df, truth, "force")
            r.update(precision=sc["precision"], recall=sc["recall"], median_timing_error_s=sc["median_timing_error_s"])
        out.append(r)
    return pd.DataFrame(out)


def contact_fields(trials: list, window_mm: float | None = None, config=None) -> dict:  # noqa: ANN001
    """Field stiffness of every trial under the truncation rule (``FieldResult`` by trial id).

    A trial with a detected contact (the IMU rule where its log exists, else the
    force-only detector) is scored only up to the contact: its field stiffness
    comes from the partial trial, and the simulation pushes only as far (the
    field fit's contact samples set the protocol steps). An excluded trial has no
    field stiffness. Every field fit carries a flag naming the truncation.
    """
    from ..execute.pipeline import FieldResult, field_stage
    from ..measure.field import extract_field_stiffness

    # refuses missing or malformed CSVs, as every study does
    out = field_stage(trials, window_mm, config) if config is not None else field_stage(trials, window_mm)
    for tid, fr in list(out.items()):
        t = fr.trial
        if t.csv is None or fr.fit is None:
            continue
        rig = read_rig_csv(t.csv)
        rf, ri = detect(rig, imu_path(t.csv))
        d = ri if ri is not None else rf
        if d.excluded:
            out[tid] = FieldResult(t, None, "excluded: too many IMU spikes (contact rule)")
        elif d.detected:
            win = fr.fit.window_mm  # the window the whole trial was fitted over (a study's or an effect's)
            ff = extract_field_stiffness(truncated(rig, d.truncate_index), window_mm=win)
            where = float(rig.displacement_mm[max(d.truncate_index - 1, 0)])
            ff.flags.append(f"partial trial: {'IMU' if ri is not None else 'force-only'} contact, scored up to "
                            f"{where:.1f} mm ({d.truncate_index} of {len(rig.time_s)} samples)")
            out[tid] = FieldResult(t, ff, ff.reason if not ff.usable else "")
    return out


def _write(res: ContactStudyResult, data_dir: Path, out: Path) -> list[Path]:
    out.mkdir(parents=True, exist_ok=True)
    res.rows.to_csv(out / "contact.csv", index=False)
    res.events.to_csv(out / "contact_events.csv", index=False)
    res.trials.to_csv(out / "contact_trials.csv", index=False)
    res.sensitivity.to_csv(out / "contact_sensitivity.csv", index=False)
    (out / "contact_meta.json").write_text(json.dumps(res.meta, indent=1))
    files = [out / "contact.csv", out / "contact_events.csv", out / "contact_trials.csv",
             out / "contact_sensitivity.csv", out / "contact_meta.json"]
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


#: what the issue's careful look at the published traces found (events, not trials)
BY_EYE = {"stiffening": 13, "softening": 6, "drop": 13}


def contact_section_html(out_dir: str | Path) -> str:
    """The report's contact-detection section, rebuilt from the files :func:`contact_study` wrote."""
    out_dir = Path(out_dir)
    meta = json.loads((out_dir / "contact_meta.json").read_text())
    rows = pd.read_csv(out_dir / "contact.csv")
    c, p = meta["counts"], meta["paper"]
    cmp = pd.DataFrame([{"quantity": k, "paper (IMU)": p[k], f"this data ({meta['primary_method']})": v}
                        for k, v in (("contact", meta["contact"]), ("full", c["full"]), ("partial", c["partial"]),
                                     ("excluded", c["excluded"]))])
    banner = ('<p style="color:#a33"><b>SYNTHETIC data</b>: injected obstruction contacts; not measurements.</p>'
              if meta.get("synthetic") else "")
    scores = ""
    if (out_dir / "contact_scores.json").exists():
        sc = json.loads((out_dir / "contact_scores.json").read_text())
        scores = ("<h3>Against the injected truth</h3><p>A detection is correct when the trial has a contact "
                  "and the detected time is within 2 s of it; excluded trials are left out.</p>"
                  + pd.DataFrame(sc).T[["precision", "recall", "median_timing_error_s", "tp", "fp", "fn"]]
                  .to_html(float_format="{:.3g}".format))
    ev, evt = meta["force_events"], meta.get("force_event_trials", {})
    fmt = {"index": False, "float_format": lambda v: f"{v:.3g}", "na_rep": ""}
    kinds = pd.DataFrame([{"kind": k, "events": ev.get(k, 0), "trials": evt.get(k, ""),
                           "by eye (issue 9)": BY_EYE.get(k, "")} for k in
                          ("stiffening", "softening", "drop", "onset", "dip", "bump", "bend", "spike")])
    sens = ""
    if (out_dir / "contact_sensitivity.csv").exists():
        sens = ("<h3>How the force-only counts depend on the detector's settings</h3><p>The slope ratio (2: a "
                "second body at least as stiff as the cane) and the 20 gf contact floor are choices, not "
                "measurements; the counts below show what each moves.</p>"
                + pd.read_csv(out_dir / "contact_sensitivity.csv").to_html(**fmt))
    per = ""
    if (out_dir / "contact_trials.csv").exists():
        t = pd.read_csv(out_dir / "contact_trials.csv")
        part = t[t.status == "partial"]
        per = (f"<h3>Per trial: what was found, where, and whether it becomes partial</h3><p>{len(part)} partial "
               f"trials; the field stiffness of the partial trial (scored only up to the contact) beside the "
               f"whole trial's: median |ln(k_partial/k_full)| "
               f"{np.nanmedian(np.abs(np.log(part.k_field_partial / part.k_field_full))) if len(part) else float('nan'):.2f}"
               f"; {int((part.partial_usable == False).sum())} partial trials are too short to score "  # noqa: E712
               f"and {int(part.k_field_full.isna().sum())} were unscorable whole and become scorable partial.</p>"
               + t.to_html(**fmt))
    why = ("Force-only detector (no IMU logs): slips (falls over 30 gf; a fall back onto the trend after a "
           "one-sample jump is a load-cell spike), and knees found by binary segmentation when a continuous "
           "two-segment fit beats one line by more than the 99th percentile of its no-change maximum, in units of "
           "the trace's own long-run noise; segments at least 2.5 mm. A knee is a <b>stiffening elbow</b> when the "
           "slope at least doubles while the cane already carries more than 20 gf (the field fit's contact "
           "threshold): a second body engaging. Trials become partial at the first stiffening elbow or slip.")
    return (f"<h2>Field trial contact detection</h2>{banner}"
            f"<p>Data: <code>{html.escape(meta['data_dir'])}</code>, {meta['n_trials']} trials; trial status from "
            f"the <b>{meta['primary_method']}</b> detector. IMU rule as the paper: 9 channels at 40 Hz, minus a "
            f"20-sample rolling mean, rbf binary segmentation with penalty 22.5 log n; contact when 4 channels "
            f"(one pushed) change within 1 s or the pushed cane spikes above 1.5 m/s<sup>2</sup>; a partial trial "
            f"ends at contact. {why} Here: {meta['force_partial']} trials partial by force "
            f"({', '.join(f'{v} by {k}' for k, v in meta.get('force_partial_by_cause', {}).items())}).</p>"
            f"<h3>Counts against the paper</h3>{cmp.to_html(index=False)}"
            f"<h3>Force-only events</h3>{kinds.to_html(index=False)}{scores}{sens}"
            f'<img src="contact_example.png">{per}'
            f"<h3>Per trial and method</h3>{rows.to_html(**fmt)}")
