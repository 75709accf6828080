"""The main job: probe every selected trial on every selected backend and score it.

``run_trials`` is the one pipeline behind ``canebench run``, the sensitivity
studies and sweeps: they differ only in the :class:`ModelConfig` they pass.
Rows are appended to ``results.partial.csv`` as trials finish, so a crash or
an interrupt loses nothing already computed.
"""

from __future__ import annotations

import datetime as _dt
import json
import math
import os
import platform
import subprocess
import sys
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np
import pandas as pd

from . import __version__
from .chain import build_chain
from .config import ModelConfig
from .dataset import Trial
from .field import FieldFit, extract_field_stiffness, read_rig_csv
from .probe import run_probe
from .protocol import Protocol
from .registry import discover, get_backend

RESULT_COLUMNS = [
    "trial", "cane", "push_point", "bush", "backend", "protocol", "k_sim", "k_field", "log_ratio", "status",
    "reason", "wall_s", "n_steps", "n_samples", "r2_sim", "k_linear", "n_links", "height_mm", "diameter_mm",
    "field_usable", "field_reason", "synthetic", "chain_hash",
]


@dataclass
class TrialOutcome:
    rows: list[dict[str, Any]]
    traces: list[dict[str, Any]]
    field: dict[str, Any]


def field_fit_for(trial: Trial) -> FieldFit | None:
    if trial.csv is None or not trial.csv.exists():
        return None
    return extract_field_stiffness(read_rig_csv(trial.csv))


def probe_trial(trial: Trial, backends: list[str], proto: Protocol, config: ModelConfig,
                max_steps: int | None = None) -> TrialOutcome:
    """Field fit, chain and one probe per backend for one trial. Never raises
    for a failing engine: the row carries the failure and its reason."""
    try:
        ff = field_fit_for(trial)
        field_err = ""
    except Exception as exc:  # bad field CSV: still simulate, but do not score
        ff, field_err = None, f"field data unreadable: {exc}"
    n_steps = proto.max_steps
    if ff is not None and ff.n_steps > 0:
        n_steps = min(n_steps, ff.n_steps)  # paper: 90 s or the field trial's duration
    if max_steps is not None:
        n_steps = min(n_steps, max_steps)
    k_field = ff.k_n_per_mm if ff is not None else float("nan")
    field_reason = field_err or (ff.reason if ff is not None else "no field trial")
    base = {
        "trial": trial.id, "cane": trial.cane.id, "push_point": trial.push_id, "bush": trial.bush,
        "protocol": proto.name, "k_field": k_field, "height_mm": trial.height_mm, "diameter_mm": trial.diameter_mm,
        "field_usable": bool(ff is not None and ff.usable), "field_reason": field_reason,
        "synthetic": bool(trial.cane.provenance.get("synthetic", False)), "n_steps": n_steps,
    }
    rows, traces = [], []
    try:
        chain = build_chain(trial.cane, trial.push_id, config)
    except Exception as exc:
        for b in backends:
            rows.append({**base, "backend": b, "status": "failed", "reason": f"chain: {exc}", "k_sim": math.nan,
                         "log_ratio": math.nan, "wall_s": 0.0, "n_samples": 0})
        return TrialOutcome(rows, traces, _field_row(trial, ff, field_reason))
    for b in backends:
        tr = run_probe(get_backend(b), chain, proto, n_steps)
        fit = tr.fit() if tr.status == "ok" else None
        k_sim = fit.slope_n_per_mm if fit is not None else math.nan
        status, reason = tr.status, tr.reason
        if status == "ok" and fit is None:
            status, reason = "failed", "too few samples to fit a slope"
        log_ratio = math.log(k_sim / k_field) if (status == "ok" and k_field > 0 and k_sim > 0) else math.nan
        if status == "ok" and not math.isfinite(log_ratio):
            status, reason = "unscored", f"no field stiffness: {field_reason}"
        rows.append({
            **base, "backend": b, "k_sim": k_sim, "log_ratio": log_ratio, "status": status, "reason": reason,
            "wall_s": tr.wall_s, "n_samples": len(tr.force), "r2_sim": fit.r2 if fit else math.nan,
            "k_linear": tr.extras.get("k_linear", math.nan) * 1e-3, "n_links": chain.n_links,
            "chain_hash": chain.fingerprint(), "settings": json.dumps(tr.settings, sort_keys=True),
            "controller": tr.extras.get("controller", ""), "dt": tr.extras.get("dt", math.nan),
        })
        for i, (x, f) in enumerate(zip(tr.displacement, tr.force)):
            traces.append({"trial": trial.id, "backend": b, "step": i + 1, "displacement_mm": x * 1e3, "force_n": f})
    if ff is not None and ff.displacement_mm is not None:
        for i, (x, f) in enumerate(zip(ff.displacement_mm, ff.force_n)):
            traces.append({"trial": trial.id, "backend": "field", "step": i + 1, "displacement_mm": float(x),
                           "force_n": float(f)})
    return TrialOutcome(rows, traces, _field_row(trial, ff, field_reason))


def _field_row(trial: Trial, ff: FieldFit | None, reason: str) -> dict[str, Any]:
    if ff is None:
        return {"trial": trial.id, "usable": False, "reason": reason}
    return {"trial": trial.id, "k_field": ff.k_n_per_mm, "r2": ff.r2, "rms_n": ff.rms_n, "n_contact": ff.n_contact,
            "onset_mm": ff.onset_mm, "tare_gf": ff.tare_gf, "usable": ff.usable, "reason": ff.reason,
            "flags": "; ".join(ff.flags)}


def _worker(args: tuple) -> TrialOutcome:
    return probe_trial(*args)


def provenance(backends: list[str], proto: Protocol, config: ModelConfig, extra: dict | None = None) -> dict:
    reg = discover()
    try:
        commit = subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True,
                                cwd=Path(__file__).parent, timeout=5).stdout.strip() or None
    except Exception:
        commit = None
    return {
        "canebench": __version__,
        "git_commit": commit,
        "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "python": sys.version.split()[0],
        "platform": platform.platform(),
        "numpy": np.__version__,
        "pandas": pd.__version__,
        "engines": {b: reg[b].version for b in backends if b in reg},
        "backend_settings": {b: get_backend(b).settings(proto) for b in backends},
        "protocol": proto.to_dict(),
        "model_config": config.to_dict(),
        "seed": None,  # the probe is deterministic; dataset seeds live in their provenance
        **(extra or {}),
    }


def run_trials(trials: list[Trial], backends: list[str], proto: Protocol, config: ModelConfig,
               out_dir: Path | None = None, jobs: int = 1, max_steps: int | None = None,
               progress: Callable[[int, int, TrialOutcome], None] | None = None) -> tuple[pd.DataFrame, pd.DataFrame, pd.DataFrame]:
    """Probe ``trials`` on ``backends``; return (results, traces, field) tables.

    With ``out_dir``, rows are appended to ``results.partial.csv`` as they come.
    """
    rows, traces, fields = [], [], []
    partial = None
    if out_dir is not None:
        out_dir.mkdir(parents=True, exist_ok=True)
        partial = out_dir / "results.partial.csv"
        partial.unlink(missing_ok=True)

    def collect(o: TrialOutcome) -> None:
        rows.extend(o.rows)
        traces.extend(o.traces)
        fields.append(o.field)
        if partial is not None:
            pd.DataFrame(o.rows).to_csv(partial, mode="a", header=not partial.exists(), index=False)
        if progress:
            progress(len(fields), len(trials), o)

    args = [(t, backends, proto, config, max_steps) for t in trials]
    if jobs > 1 and len(trials) > 1:
        with ProcessPoolExecutor(max_workers=jobs) as ex:
            futs = {ex.submit(_worker, a): a[0].id for a in args}
            for fut in as_completed(futs):
                collect(fut.result())
    else:
        for a in args:
            collect(_worker(a))
    res = pd.DataFrame(rows)
    for c in RESULT_COLUMNS:
        if c not in res.columns:
            res[c] = np.nan
    order = {t.id: i for i, t in enumerate(trials)}
    res = res.sort_values(["trial", "backend"], key=lambda s: s.map(order) if s.name == "trial" else s)
    res = res[RESULT_COLUMNS + [c for c in res.columns if c not in RESULT_COLUMNS]].reset_index(drop=True)
    return res, pd.DataFrame(traces), pd.DataFrame(fields)


def write_run(out_dir: Path, results: pd.DataFrame, traces: pd.DataFrame, fields: pd.DataFrame, meta: dict) -> None:
    out_dir.mkdir(parents=True, exist_ok=True)
    results.to_csv(out_dir / "results.csv", index=False)
    traces.to_csv(out_dir / "traces.csv", index=False)
    fields.to_csv(out_dir / "field.csv", index=False)
    (out_dir / "run.json").write_text(json.dumps(meta, indent=2, default=str))
    (out_dir / "results.partial.csv").unlink(missing_ok=True)


def default_jobs() -> int:
    return max(1, min(2, os.cpu_count() or 1))

