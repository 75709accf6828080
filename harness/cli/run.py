"""``canebench run``: probe trials on backends and score them against field stiffness."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from ..errors import CanebenchError, InputError, InputWarning

from . import common


def add_parser(sub: argparse._SubParsersAction) -> None:
    r = sub.add_parser("run", help="probe trials on backends and score them against field stiffness")
    common.add_data_options(r)
    r.add_argument("--backends", default="mujoco,pinocchio", help="comma-separated backend names")
    r.add_argument("--protocol", default="fast", help="probe protocol: fast (default) or paper")
    r.add_argument("--out", help="run folder (default canebench-runs/run-<time>); an existing one resumes")
    r.add_argument("--limit", type=int, help="only the first N selected trials")
    r.add_argument("--max-steps", type=int, help="cap on protocol steps per trial")
    r.add_argument("--fit-window", type=float, metavar="MM",
                   help="fit stiffness over the first MM of the push, field and simulation alike (default: all)")
    common.add_model_options(r)
    common.add_executor_options(r)
    r.add_argument("--no-report", action="store_true")
    r.set_defaults(fn=main)


def main(a: argparse.Namespace) -> int:
    if a.limit is not None and a.limit < 1:
        raise InputError("--limit", "limit", f"must be >= 1, got {a.limit}")
    if a.max_steps is not None and a.max_steps < 3:
        raise InputError("--max-steps", "max_steps", f"must be >= 3 (a slope needs 3 samples), got {a.max_steps}")
    created = a.out is None or not Path(a.out).exists()
    out = common.out_dir(a.out, "run")  # a bad --out fails before any work
    try:
        return _run(a, out)
    except (CanebenchError, InputWarning):  # a bad file, value or engine name
        if created and out.is_dir() and not any(out.iterdir()):
            out.rmdir()  # refused input leaves no empty run folder behind
        raise


def _run(a: argparse.Namespace, out: Path) -> int:
    from ..execute.pipeline import field_stage, make_jobs
    from ..execute.provenance import provenance
    from ..execute.runner import run_jobs
    from ..probe.protocol import get_protocol

    data_dir, trials = common.trials(a)
    if a.limit:
        trials = trials[: a.limit]
    usable, skipped = common.backends(a.backends)
    if not usable:
        print("no usable backend", file=sys.stderr)
        return 2
    proto = get_protocol(a.protocol)
    if a.fit_window is not None:
        if not a.fit_window > 0:
            raise InputError("--fit-window", "fit_window_mm", f"must be > 0 mm, got {a.fit_window}")
        proto = proto.replace(fit_window_mm=a.fit_window)
    config = common.model_config(a)
    ex = common.executor(a)
    synthetic = all(t.cane.provenance.get("synthetic", False) for t in trials)
    assumptions = common.assumptions(trials, config)
    print(f"canebench run: {len(trials)} trials from {data_dir}"
          f"{' (SYNTHETIC data)' if synthetic else ''}, backends {','.join(usable)}, protocol {proto.name}, "
          f"executor {a.executor} -> {out}")
    for s in assumptions:
        print(f"  assumption: {s}")
    t0 = time.perf_counter()
    fields = field_stage(trials, proto.fit_window_mm, config)
    jobs = make_jobs(trials, usable, proto, config, fields, a.max_steps)
    meta = provenance(usable, proto, config, {
        "command": " ".join(sys.argv), "dataset": str(data_dir.resolve()),
        "dataset_provenance": trials[0].cane.provenance if trials else {}, "synthetic": synthetic,
        "assumptions": assumptions, "skipped_backends": skipped, "n_trials": len(trials), "preset": a.preset,
    })
    common.sigterm_as_interrupt()
    outcome = run_jobs(jobs, out, ex, fields=fields, timeout_s=a.timeout or None, fresh=a.fresh,
                       progress=common.progress(a), meta=meta, label="run")
    res = outcome.results
    print(f"done in {time.perf_counter() - t0:.1f} s: {outcome.summary()}")
    ok = res[res.status == "ok"] if len(res) else res
    for b, g in (ok.groupby("backend") if len(ok) else []):
        print(f"  {b:10s} median |ln(k_sim/k_field)| = {g.log_ratio.abs().median():.3f} over {len(g)} trials")
    if not a.no_report:
        from canebench.reports.build import build_report

        print(f"report: {build_report(out)}")
    elif (out / "report.html").exists():
        (out / "report.html").unlink()  # it described an earlier run in this folder: stale now
    print(f"results: {out / 'results.csv'}")
    if outcome.interrupted:
        common.say_interrupted(outcome, out)
    elif outcome.exit_code:
        reasons = res.reason.value_counts().head(5) if len(res) else []
        print("every job failed; most common reasons:", file=sys.stderr)
        for r, n in (reasons.items() if len(res) else []):
            print(f"  {n:4d} x {r}", file=sys.stderr)
    return outcome.exit_code
