"""What runs in a worker: one job under its time limit, and the local pool's worker loop.

A local-pool worker ignores SIGINT (the parent decides what an interrupt
means) and exits as soon as its parent dies: a watchdog thread blocks on a
*lifeline* pipe whose only writer is the parent, and the kernel closes that
end when the parent exits, however it exits (SIGKILL included).
"""

from __future__ import annotations

import os
import signal
import threading
import time
import traceback
from typing import Any

from ..limits import JobTimeout, time_limit
from .jobs import Job, JobResult
from .pipeline import failed_result, run_job


def execute(job: Job, timeout_s: float | None) -> JobResult:
    """Run ``job``; a timeout or an unexpected error becomes a failed row, never an exception."""
    t0 = time.perf_counter()
    try:
        with time_limit(timeout_s):
            return run_job(job)
    except JobTimeout as exc:
        return failed_result(job, "timeout", str(exc), time.perf_counter() - t0)
    except Exception as exc:  # a bug must cost one job, not the run
        tb = traceback.format_exc(limit=3).strip().splitlines()[-1]
        return failed_result(job, "failed", f"worker error: {type(exc).__name__}: {exc} ({tb})",
                             time.perf_counter() - t0)


def execute_many(jobs: list[Job], timeout_s: float | None) -> list[JobResult]:
    """Several jobs in a row (a Dask task), each under its own time limit."""
    return [execute(job, timeout_s) for job in jobs]


def _warm_up() -> None:
    """Import the engines before the first job, so a job's time limit counts the job, not start-up."""
    import warnings

    from ..registry import discover

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        discover()


def _die_with_parent() -> None:
    """Linux: ask the kernel to SIGKILL this worker when its parent (the forkserver, which
    exits with the run) dies; a second guard beside the lifeline thread, for a worker
    stuck in C code that holds the GIL."""
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        PR_SET_PDEATHSIG = 1
        libc.prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
    except Exception:  # not Linux: the lifeline thread still works
        pass


def _watch_parent(lifeline: Any) -> None:
    try:
        lifeline.recv()  # the parent never sends: this returns only by EOF
    except (EOFError, OSError):
        pass
    os._exit(3)


def worker_main(conn: Any, lifeline: Any, timeout_s: float | None, workdir: Any = None) -> None:
    """Loop: receive a job, run it, send the result; ``None`` ends the loop."""
    if workdir is not None:
        os.chdir(workdir)  # engine side files (MUJOCO_LOG.TXT) land in the run folder
    _die_with_parent()
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    threading.Thread(target=_watch_parent, args=(lifeline,), daemon=True).start()
    _warm_up()
    while True:
        try:
            job = conn.recv()
        except (EOFError, OSError):
            return
        if job is None:
            return
        conn.send(execute(job, timeout_s))
