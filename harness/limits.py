"""Per-job time limits.

A job runs under :func:`time_limit`. In a process's main thread (the serial
executor, the local pool's workers) an interval timer raises
:class:`JobTimeout` between Python bytecodes, which stops a runaway Python
loop (a greedy discretization asked for 100000 links) wherever it is. In any
thread, long loops also call :func:`check_deadline` at natural points (each
protocol step, each discretization split), which is how a job on a Dask
worker thread stops. A call stuck inside an engine's C code answers neither;
the local pool then kills the worker process after a grace period.

:class:`JobTimeout` derives from ``BaseException`` so that an engine-error
handler (``except Exception``) cannot swallow it and report a timeout as an
engine failure.
"""

from __future__ import annotations

import contextlib
import signal
import threading
import time
from typing import Iterator


class JobTimeout(BaseException):
    """A job ran past its time limit."""


_local = threading.local()


def check_deadline() -> None:
    """Raise :class:`JobTimeout` if the current thread's job is past its limit."""
    d = getattr(_local, "deadline", None)
    if d is not None and time.monotonic() > d:
        raise JobTimeout(f"time limit of {_local.limit:g} s exceeded")


@contextlib.contextmanager
def time_limit(seconds: float | None) -> Iterator[None]:
    """Run the body under a time limit (``None`` or <= 0: no limit)."""
    if not seconds or seconds <= 0:
        yield
        return
    _local.deadline, _local.limit = time.monotonic() + seconds, seconds
    use_alarm = threading.current_thread() is threading.main_thread()
    old = None
    if use_alarm:
        def _raise(signum: int, frame: object) -> None:
            raise JobTimeout(f"time limit of {seconds:g} s exceeded")

        old = signal.signal(signal.SIGALRM, _raise)
        signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        if use_alarm:
            signal.setitimer(signal.ITIMER_REAL, 0)
            signal.signal(signal.SIGALRM, old if old is not None else signal.SIG_DFL)
        _local.deadline = None
