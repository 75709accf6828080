"""The pipeline's stages as plain functions: make jobs, run one, score results.

* :func:`field_stage` reads and fits every field trial once, in the client
  (workers never need the field CSVs: on a cluster the data stays where the
  client is).
* :func:`make_jobs` turns trials x backends x configurations into
  :class:`Job` objects; every study builds its list with it.
* :func:`run_job` is what a worker executes: chain, probe, slope. It never
  raises for a failing engine or a bad chain: the row carries the failure
  and its reason.
* :func:`score` joins simulation rows with field stiffness, in one place:
  ``log_ratio = ln(k_sim / k_field)``.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass
from typing import Any, Iterable

import numpy as np
import pandas as pd

from ..data.dataset import Trial
from ..data.rig import read_rig_csv
from ..errors import InputError, warn_input
from ..measure.field import FieldFit, extract_field_stiffness
from ..model.chain import build_chain
from ..model.config import ModelConfig
from ..probe.driver import run_probe
from ..probe.protocol import Protocol
from ..registry import backend_version, discover, get_backend
from .jobs import Job, JobResult, config_hash

RESULT_COLUMNS = [
    "trial", "cane", "push_point", "bush", "backend", "answer", "protocol", "k_sim", "k_field", "log_ratio", "status",
    "reason", "wall_s", "cpu_s", "n_steps", "n_samples", "r2_sim", "k_linear", "n_links", "height_mm", "diameter_mm",
    "field_usable", "field_reason", "synthetic", "assumptions", "chain_hash", "config_hash", "job_key",
]
SIM_STATUSES = ("ok", "failed", "timeout")
ASSUMPTION_SEP = " | "  # assumptions themselves contain semicolons


@dataclass
class FieldResult:
    """One trial's field stiffness (or why there is none)."""

    trial: Trial
    fit: FieldFit | None
    reason: str

    @property
    def k(self) -> float:
        return self.fit.k_n_per_mm if self.fit is not None else math.nan

    def n_steps(self, proto: Protocol, max_steps: int | None = None) -> int:
        n = proto.max_steps
        if self.fit is not None and self.fit.n_steps > 0:
            n = min(n, self.fit.n_steps)  # paper: 90 s or the field trial's duration
        if max_steps is not None:
            n = min(n, max_steps)
        return n

    def row(self) -> dict[str, Any]:
        ff = self.fit
        geo = ASSUMPTION_SEP.join(a for a in self.trial.cane.provenance.get("assumptions", [])
                                  if a.startswith("geometry"))
        if ff is None:
            return {"trial": self.trial.id, "usable": False, "reason": self.reason, "assumptions": geo}
        return {"trial": self.trial.id, "assumptions": geo, "k_field": ff.k_n_per_mm, "k_se": ff.se,
                "k_ci_low": ff.ci_low, "k_ci_high": ff.ci_high, "window_mm": ff.window_mm,
                "k_first_10mm": ff.k_first_10mm, "r2": ff.r2, "rms_n": ff.rms_n,
                "n_contact": ff.n_contact, "onset_mm": ff.onset_mm, "tare_gf": ff.tare_gf, "usable": ff.usable,
                "reason": ff.reason, "flags": "; ".join(ff.flags)}

    def trace_rows(self) -> list[dict[str, Any]]:
        ff = self.fit
        if ff is None or ff.displacement_mm is None:
            return []
        return [{"trial": self.trial.id, "backend": "field", "step": i + 1, "displacement_mm": float(x),
                 "force_n": float(f)} for i, (x, f) in enumerate(zip(ff.displacement_mm, ff.force_n))]


def assumptions_for(trial: Trial, config: ModelConfig | None) -> list[str]:
    """The assumptions behind a trial's result, true for its configuration.

    A dataset's statement about the modulus no longer holds when the
    configuration sets one, so it is replaced, never left standing; with
    ``config=None`` (a study that varies the modulus itself) it is dropped.
    """
    out = list(trial.cane.provenance.get("assumptions", []))
    if config is None or config.modulus_pa is not None:
        out = [a for a in out if not a.lower().startswith("modulus")]
    if config is not None and config.modulus_pa is not None:
        out.append(f"modulus: {config.modulus_pa:.4g} Pa for every cane (model configuration)")
    return out


def trial_assumptions(trial: Trial, config: ModelConfig) -> str:
    """:func:`assumptions_for` as one cell, joined by :data:`ASSUMPTION_SEP`."""
    return ASSUMPTION_SEP.join(assumptions_for(trial, config))


#: the contact travel (mm) a simulated push covers: the protocols' longest trial, 90 steps of
#: 0.5 mm (the paper's 90 s). The rig's own stroke ends there too (the real traces' contact runs
#: to 43.5 mm at most), but a rig that pushes further writes a longer trace, and a slope fitted
#: over 80 mm of a cane that stiffens or softens as it bends is not the slope of the 45 mm the
#: simulation pushes: such a trace is fitted over its first ``SIM_TRAVEL_MM`` of contact.
SIM_TRAVEL_MM = Protocol.max_steps * Protocol.step_m * 1e3


#: how far the rig file's push height may lie from push_points.csv's (tape and rounding)
RIG_HEIGHT_TOL_MM = 10.0


def field_fit_for(trial: Trial, window_mm: float | None = None, record_end_mm: float | None = None) -> FieldFit | None:
    """The field fit of one trial's rig record, cut at ``record_end_mm`` of travel (an effect's)."""
    if trial.csv is None or not trial.csv.exists():
        return None
    rig = read_rig_csv(trial.csv)
    h = getattr(trial, "height_mm", math.nan)  # (a study's stand-in trial may carry only its file)
    if math.isfinite(h) and abs(rig.height_mm - h) > RIG_HEIGHT_TOL_MM:
        # the rig writes the push height into every row: another trial's file (a mistyped name in
        # push_points.csv) would otherwise be scored as this one without a word
        warn_input(str(trial.csv), "Height (mm)", f"{rig.height_mm:g} mm, where push_points.csv gives "
                                                  f"{h:g} mm for trial {trial.id}: is it this trial's file?")
    if record_end_mm is not None:
        rig = rig.up_to(record_end_mm)
    return extract_field_stiffness(rig, window_mm=window_mm, max_travel_mm=SIM_TRAVEL_MM)


def field_stage(trials: Iterable[Trial], window_mm: float | None = None,
                config: ModelConfig | None = None) -> dict[str, FieldResult]:
    """Field stiffness of every trial, by trial id (a bad CSV is a reason, not a crash).

    ``window_mm`` must be the protocol's ``fit_window_mm`` so both sides of a score use one window;
    a trace whose contact runs past :data:`SIM_TRAVEL_MM` (the registered protocols' push) is fitted
    over that much of it (flagged);
    a ``config`` whose effects shorten a trial's window (an obstruction onset)
    shortens it here too, as :func:`run_job` does for the simulation, and one that cuts a trial's
    record (an obstruction's ``record_end_mm``) fits the record up to there.

    Raises
    ------
    InputError
        A rig CSV that is named but missing, unreadable or malformed: input is
        refused before any simulation (the message names the file and field).
    """
    out: dict[str, FieldResult] = {}
    for t in trials:
        if t.id in out:
            continue
        if t.csv is not None and not t.csv.exists():
            raise InputError(str(t.csv), "<file>", f"rig CSV of trial {t.id} not found")
        win = config.fit_window_mm(t.cane.id, t.id, window_mm) if config is not None else window_mm
        end = config.record_end_mm(t.cane.id, t.id) if config is not None else None
        ff = field_fit_for(t, win, end)
        out[t.id] = FieldResult(t, ff, ff.reason if ff is not None else "no field trial")
    return out


def make_jobs(trials: list[Trial], backends: list[str], proto: Protocol,
              configs: ModelConfig | list[ModelConfig], fields: dict[str, FieldResult] | None = None,
              max_steps: int | None = None, labels: list[dict[str, Any]] | None = None) -> list[Job]:
    """Jobs for every trial x backend, with one configuration for all trials or one per trial.

    Parameters
    ----------
    configs : ModelConfig or list of ModelConfig
        A single configuration, or one per trial (``len(configs) == len(trials)``);
        trials may repeat, so a list of (trial, configuration) pairs is a job list.
    labels : list of dict, optional
        Per-trial labels copied into each row (a study's sample index...).
    """
    if fields is None:
        one = configs if isinstance(configs, ModelConfig) else None
        fields = field_stage(trials, proto.fit_window_mm, one)
    if isinstance(configs, ModelConfig):
        configs = [configs] * len(trials)
    if len(configs) != len(trials):
        raise ValueError(f"{len(configs)} configurations for {len(trials)} trials")
    reg = discover()
    versions = {b: backend_version(b) for b in backends}
    classes = {b: (reg[b].cls if b in reg and not reg[b].from_entry_point else None) for b in backends}
    modules = {b: (reg[b].target.partition(":")[0] if b in reg else "") for b in backends}
    jobs = []
    for i, (t, cfg) in enumerate(zip(trials, configs)):
        n = fields[t.id].n_steps(proto, max_steps)
        lab = labels[i] if labels else {}
        cfg = cfg.localized(t.cane.id, t.id)  # per-cane/per-trial effect values: only this trial's
        for b in backends:
            jobs.append(Job(t, b, versions[b], proto, cfg, n, dict(lab), classes[b], modules[b]))
    return jobs


def run_job(job: Job) -> JobResult:
    """Build the chain, probe it on the job's backend, fit the slope.

    Never raises for a failing engine or chain: the row says ``failed`` and why.
    """
    t, cfg = job.trial, job.config
    row: dict[str, Any] = {"backend": job.backend, "k_sim": math.nan, "wall_s": 0.0, "n_samples": 0,
                           "n_steps": job.n_steps}
    t0, c0 = time.perf_counter(), time.process_time()
    try:
        chain = build_chain(t.cane, t.push_id, cfg)
    except Exception as exc:
        row.update(status="failed", reason=f"chain: {exc}", wall_s=time.perf_counter() - t0,
                   cpu_s=time.process_time() - c0)
        return JobResult(job.key, row)
    backend = job.backend_cls() if job.backend_cls is not None else get_backend(job.backend)
    tr = run_probe(backend, chain, job.protocol, job.n_steps)
    win = cfg.fit_window_mm(t.cane.id, t.id, job.protocol.fit_window_mm)
    if cfg.effects and tr.status == "ok" and tr.force:
        # effects on what the rig records (rig compliance): the slope is fit to the recorded trace
        x, f = cfg.applied_effects(t.cane.id, t.id).measured(np.array(tr.displacement), np.array(tr.force))
        tr.displacement, tr.force = [float(v) for v in x], [float(v) for v in f]
    fit = tr.fit(win * 1e-3 if win is not None else None) if tr.status == "ok" else None
    status, reason = tr.status, tr.reason
    if status == "ok" and fit is None:
        status, reason = "failed", "too few samples to fit a slope" + (
            f" ({tr.extras['finer_push']})" if "finer_push" in tr.extras else "")
    k_sim = fit.slope_n_per_mm if fit is not None else math.nan
    if status == "ok" and not (k_sim > 0):
        # a cane pushed forward never pulls back: this is the simulation's fault, not the field's
        status, reason = "failed", f"non-positive simulated stiffness ({k_sim:.3g} N/mm)"
    row.update(
        k_sim=k_sim, status=status, reason=reason, wall_s=tr.wall_s, cpu_s=time.process_time() - c0,
        n_samples=len(tr.force),
        r2_sim=fit.r2 if fit else math.nan, k_linear=tr.extras.get("k_linear", math.nan) * 1e-3,
        n_links=chain.n_links, chain_hash=chain.fingerprint(), settings=json.dumps(tr.settings, sort_keys=True),
        controller=tr.extras.get("controller", ""), dt=tr.extras.get("dt", math.nan),
        answer=tr.extras.get("answer", ""),
        step_mm=tr.extras.get("step_mm", job.protocol.step_m * 1e3),  # finer than the protocol's: see run_probe
    )
    for key in ("beam_elements", "beam_rel_error"):  # the beam reference's mesh and error estimate
        if key in tr.extras:
            row[key] = tr.extras[key]
    return JobResult(job.key, row, [float(x) for x in tr.displacement], [float(f) for f in tr.force])


def failed_result(job: Job, status: str, reason: str, wall_s: float = 0.0) -> JobResult:
    """The row of a job that did not return (timeout, worker crash)."""
    return JobResult(job.key, {"backend": job.backend, "k_sim": math.nan, "status": status, "reason": reason,
                               "wall_s": wall_s, "n_samples": 0, "n_steps": job.n_steps})


def score(job: Job, result: JobResult, field: FieldResult) -> dict[str, Any]:
    """One results row: the job's simulation columns, its trial, its field stiffness and the log ratio."""
    t = job.trial
    row = {
        "trial": t.id, "cane": t.cane.id, "push_point": t.push_id, "bush": t.bush, "protocol": job.protocol.name,
        "height_mm": t.height_mm, "diameter_mm": t.diameter_mm,
        "field_usable": bool(field.fit is not None and field.fit.usable), "field_reason": field.reason,
        "synthetic": bool(t.cane.provenance.get("synthetic", False)),
        "assumptions": trial_assumptions(t, job.config),
        "config_hash": config_hash(job.config), "job_key": job.key,
        **result.row, **job.labels,
    }
    k_field = field.k
    row["k_field"] = k_field
    if field.fit is not None and field.fit.usable:
        row["k_field_ci_low"], row["k_field_ci_high"] = field.fit.ci_low, field.fit.ci_high
    row["log_ratio"] = math.nan
    usable = field.fit is not None and field.fit.usable
    if row["status"] == "failed" and not usable and str(row.get("reason", "")).startswith("too few samples"):
        # the simulation pushes as far as the field record: a record too short to score leaves it short
        # too, and that is the record's doing, not the engine's
        row["status"], row["reason"] = "unscored", f"no field stiffness: {field.reason}"
    if row["status"] == "ok":
        if k_field > 0:
            row["log_ratio"] = math.log(row["k_sim"] / k_field)
        else:
            row["status"], row["reason"] = "unscored", f"no field stiffness: {field.reason}"
    return row


def results_table(rows: list[dict[str, Any]]) -> pd.DataFrame:
    res = pd.DataFrame(rows)
    for c in RESULT_COLUMNS:
        if c not in res.columns:
            res[c] = np.nan
    return res[RESULT_COLUMNS + [c for c in res.columns if c not in RESULT_COLUMNS]].reset_index(drop=True)


def trace_rows(job: Job, result: JobResult) -> list[dict[str, Any]]:
    lab = {"config_hash": config_hash(job.config)}
    return [{"trial": job.trial.id, "backend": job.backend, **lab, "step": i + 1, "displacement_mm": x * 1e3,
             "force_n": f} for i, (x, f) in enumerate(zip(result.displacement_m, result.force_n))]
