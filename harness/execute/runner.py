"""The one job runner every command, study and workflow submits to.

:func:`run_jobs` takes a job list (any mix of trials, backends and model
configurations), skips the jobs whose keys are already in the run folder's
store, runs the rest on an executor, commits each result as it arrives, and
writes the exports (``results.csv``, ``traces.csv``, ``field.csv``,
``run.json``) from the store, atomically, in job-list order: identical inputs
give identical files apart from wall times, whatever the completion order.

An interrupt (SIGINT, or SIGTERM, which the CLI turns into one) stops
submitting, cancels what is in flight, writes every output from what is done
and returns with ``interrupted`` set; running the same command again with the
same ``--out`` resumes.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd

from .executors import DEFAULT_TIMEOUT_S, Executor, LocalExecutor
from .jobs import Job, JobResult
from ..model.config import ModelConfig
from .pipeline import FieldResult, field_stage, results_table, score, trace_rows
from .progress import Progress
from .store import Store, atomic_csv, atomic_text


@dataclass
class RunOutcome:
    """What a run produced.

    Attributes
    ----------
    results, traces, field : DataFrame
        The exported tables (rows of finished jobs only).
    n_jobs, n_reused, n_run : int
        Jobs asked for, taken from the store, and run now.
    interrupted : bool
        True when an interrupt stopped the run before every job finished.
    missing : list of str
        Keys of jobs without a result (interrupted runs).
    """

    results: pd.DataFrame
    traces: pd.DataFrame
    field: pd.DataFrame
    n_jobs: int
    n_reused: int
    n_run: int
    interrupted: bool = False
    missing: list[str] = field(default_factory=list)
    wall_s: float = 0.0
    out_dir: Path | None = None

    def to_df(self) -> pd.DataFrame:
        return self.results

    @property
    def n_failed(self) -> int:
        return int(self.results.status.isin(["failed", "timeout"]).sum()) if len(self.results) else 0

    @property
    def all_failed(self) -> bool:
        return self.n_jobs > 0 and len(self.results) > 0 and self.n_failed == len(self.results)

    @property
    def exit_code(self) -> int:
        """0 when every job ran and at least one succeeded; 130 interrupted; 1 when every job failed."""
        if self.interrupted:
            return 130
        if self.n_jobs > 0 and (len(self.results) == 0 or self.all_failed):
            return 1
        return 0

    def summary(self) -> str:
        st = self.results.status.value_counts().to_dict() if len(self.results) else {}
        parts = [f"{self.n_jobs} job(s): {self.n_reused} reused, {self.n_run} run"]
        parts += [f"{v} {k}" for k, v in sorted(st.items())]
        if self.missing:
            parts.append(f"{len(self.missing)} not run")
        return ", ".join(parts)


def _field_table(fields: dict[str, FieldResult], trial_order: list[str]) -> pd.DataFrame:
    return pd.DataFrame([fields[t].row() for t in trial_order])


def assemble(jobs: list[Job], done: dict[str, JobResult], fields: dict[str, FieldResult],
             with_traces: bool = True) -> tuple[pd.DataFrame, pd.DataFrame, pd.DataFrame]:
    """Results, traces and field tables of the finished jobs, in job-list and trial order."""
    rows, traces = [], []
    trial_order: list[str] = []
    by_trial: dict[str, list[Job]] = {}
    for j in jobs:
        if j.trial.id not in by_trial:
            trial_order.append(j.trial.id)
            by_trial[j.trial.id] = []
        by_trial[j.trial.id].append(j)
    for j in jobs:
        if j.key in done:
            rows.append(score(j, done[j.key], fields[j.trial.id]))
    if with_traces:
        for tid in trial_order:
            seen = set()
            for j in by_trial[tid]:
                if j.key in done and j.key not in seen:
                    seen.add(j.key)
                    traces.extend(trace_rows(j, done[j.key]))
            traces.extend(fields[tid].trace_rows())
    tcols = ["trial", "backend", "config_hash", "step", "displacement_mm", "force_n"]
    return results_table(rows), pd.DataFrame(traces, columns=tcols), _field_table(fields, trial_order)


RETRY_REASONS = ("worker process died", "worker error", "dask:")


def retryable(result: JobResult) -> bool:
    """True for results a resume must not reuse: time limits and infrastructure failures."""
    row = result.row
    return row.get("status") == "timeout" or str(row.get("reason", "")).startswith(RETRY_REASONS)


def run_jobs(jobs: list[Job], out_dir: str | Path | None = None, executor: Executor | None = None,
             fields: dict[str, FieldResult] | None = None, timeout_s: float | None = DEFAULT_TIMEOUT_S,
             fresh: bool = False, progress: Progress | None = None, meta: dict[str, Any] | None = None,
             with_traces: bool = True, label: str = "") -> RunOutcome:
    """Run ``jobs`` (resuming from ``out_dir``'s store) and write the exports.

    Parameters
    ----------
    jobs : list of Job
        Any mix of trials, backends, protocols and configurations. Jobs with
        equal keys run once.
    out_dir : path, optional
        Run folder (store and exports). Without it nothing is written and
        nothing resumes.
    executor : Executor, optional
        Default: :class:`LocalExecutor` with every core.
    fields : dict, optional
        Field results by trial id (computed from the jobs' trials if absent).
    timeout_s : float, optional
        Per-job time limit (``None``: none).
    fresh : bool
        Ignore (delete) the folder's store and start over.
    meta : dict, optional
        Provenance merged into ``run.json``.
    """
    t0 = time.perf_counter()
    executor = executor or LocalExecutor()
    progress = progress or Progress()
    if fields is None:  # each trial's field fit under its own job's configuration (effects may shorten its window)
        fields = {}
        for j in jobs:
            if j.trial.id not in fields:
                fields.update(field_stage([j.trial], j.protocol.fit_window_mm, j.config))
    out = Path(out_dir).resolve() if out_dir is not None else None
    store = Store.in_folder(out, fresh=fresh) if out is not None else None
    keys = list(dict.fromkeys(j.key for j in jobs))
    done: dict[str, JobResult] = store.get_many(keys) if store is not None else {}
    # a timeout or a lost worker says nothing about the physics: run those again
    done = {k: r for k, r in done.items() if not retryable(r)}
    n_reused = len(done)
    todo, queued = [], set()
    for j in jobs:
        if j.key not in done and j.key not in queued:
            queued.add(j.key)
            todo.append(j)
    run_meta = {**(meta or {}), **executor.describe(), "timeout_s": timeout_s}
    if out is not None:
        _write_state(out, run_meta, "running", len(keys), len(done), n_reused, [])
    interrupted = False
    error: BaseException | None = None
    progress.start(len(keys), n_reused, label)
    try:
        gen = executor.map(todo, timeout_s, out)
        try:
            for job, res in gen:
                res.row.setdefault("trial", job.trial.id)
                if store is not None:
                    store.put(res)
                done[res.key] = res
                progress.update(job, res)
        except KeyboardInterrupt:
            interrupted = True
        finally:
            gen.close()
            progress.close()
    except BaseException as exc:  # the executor itself failed: outputs from what is done, then re-raise
        error = exc
    # one ending for every way out: exports and run.json from what is done
    missing = [k for k in keys if k not in done]
    interrupted = interrupted or bool(missing)
    res_df, traces, field_df = assemble(jobs, done, fields, with_traces)
    outcome = RunOutcome(res_df, traces, field_df, len(keys), n_reused, len(done) - n_reused, interrupted,
                         missing, time.perf_counter() - t0, out)
    if out is not None:
        write_exports(out, outcome)
        state = "error" if error is not None else "interrupted" if interrupted else "complete"
        extra = {"error": f"{type(error).__name__}: {error}"} if error is not None else {"wall_s": outcome.wall_s}
        _write_state(out, {**run_meta, **extra}, state, len(keys), len(done), n_reused, missing)
    if store is not None:
        store.close()
    if error is not None:
        raise error
    return outcome


def write_exports(out: Path, outcome: RunOutcome) -> None:
    atomic_csv(outcome.results, out / "results.csv")
    atomic_csv(outcome.traces, out / "traces.csv")
    atomic_csv(outcome.field, out / "field.csv")


def _write_state(out: Path, meta: dict[str, Any], state: str, n_jobs: int, n_done: int, n_reused: int,
                 missing: list[str]) -> None:
    doc = {**meta, "state": state, "jobs_total": n_jobs, "jobs_done": n_done, "jobs_reused": n_reused,
           "jobs_missing": len(missing)}
    if state == "interrupted":
        doc["resume"] = "run the same command again with the same --out: finished jobs are reused"
    atomic_text(json.dumps(doc, indent=2, default=_json_default), out / "run.json")


def _json_default(obj: Any) -> Any:
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return str(obj)


def run_trials(trials: list, backends: list[str], proto: Any, config: Any, out_dir: str | Path | None = None,
               jobs: int | None = None, executor: Executor | None = None, max_steps: int | None = None,
               **kw: Any) -> RunOutcome:
    """Every trial on every backend with one configuration (or one per trial): the common case.

    ``jobs`` sets the local pool's size when no ``executor`` is given.
    """
    from .pipeline import make_jobs

    fields = field_stage(trials, proto.fit_window_mm, config if isinstance(config, ModelConfig) else None)
    job_list = make_jobs(trials, backends, proto, config, fields, max_steps)
    return run_jobs(job_list, out_dir, executor or LocalExecutor(jobs), fields=fields, **kw)
