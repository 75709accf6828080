"""Progress of a run: a bar on a terminal, plain lines otherwise, nothing with ``--quiet``.

The bar (tqdm) shows done/total, failures so far and an ETA; the plain
form prints one line per finished job with the same counts, for logs and CI.
"""

from __future__ import annotations

import math
import sys
import time
from typing import Any, TextIO

from .jobs import Job, JobResult


class Progress:
    """Receives run events; the base class prints nothing (``--quiet``)."""

    def start(self, total: int, reused: int, label: str = "") -> None:
        pass

    def update(self, job: Job, result: JobResult) -> None:
        pass

    def close(self) -> None:
        pass


class PlainProgress(Progress):
    """One line per finished job: ``[done/total] trial backend k=... status (failed so far, ETA)``."""

    def __init__(self, stream: TextIO | None = None) -> None:
        self.stream = stream or sys.stdout

    def start(self, total: int, reused: int, label: str = "") -> None:
        self.total, self.done, self.failed, self.t0 = total, reused, 0, time.monotonic()
        self.run_total = total - reused
        if reused:
            print(f"reusing {reused} finished job(s) from the store; {total - reused} to run", file=self.stream,
                  flush=True)

    def update(self, job: Job, result: JobResult) -> None:
        self.done += 1
        st = result.row.get("status", "?")
        self.failed += st not in ("ok",)
        k = result.row.get("k_sim", math.nan)
        ks = f"k={k:.4g}" if isinstance(k, float) and math.isfinite(k) else "k=-"
        ran = self.done - (self.total - self.run_total)
        el = time.monotonic() - self.t0
        eta = el / ran * (self.run_total - ran) if ran else math.nan
        extra = "" if st == "ok" else f" [{st}: {str(result.row.get('reason', ''))[:80]}]"
        print(f"[{self.done:4d}/{self.total}] {job.trial.id:10s} {job.backend:10s} {ks}{extra}  "
              f"(failed {self.failed}, ETA {eta:.0f} s)", file=self.stream, flush=True)


class BarProgress(Progress):
    def start(self, total: int, reused: int, label: str = "") -> None:
        from tqdm import tqdm

        tqdm.monitor_interval = 0  # no monitor thread: worker processes are forked from a clean server anyway
        self.failed = 0
        self.bar = tqdm(total=total, initial=reused, desc=label or "jobs", unit="job", dynamic_ncols=True,
                        file=sys.stderr)
        if reused:
            self.bar.write(f"reusing {reused} finished job(s) from the store")

    def update(self, job: Job, result: JobResult) -> None:
        if result.row.get("status") != "ok":
            self.failed += 1
        self.bar.set_postfix(failed=self.failed, last=f"{job.trial.id}/{job.backend}", refresh=False)
        self.bar.update(1)

    def close(self) -> None:
        self.bar.close()


def make_progress(quiet: bool = False, stream: Any = None) -> Progress:
    if quiet:
        return Progress()
    s = stream or sys.stderr
    if hasattr(s, "isatty") and s.isatty():
        return BarProgress()
    return PlainProgress(stream or sys.stdout)
