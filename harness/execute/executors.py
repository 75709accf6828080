"""Executors: where jobs run. Serial, a local process pool, or Dask.

Every executor has one method, :meth:`Executor.map`, a generator of
``(job, result)`` pairs in completion order; closing it (or an interrupt in
the caller) cancels what is still queued or running. The results are the
same rows whatever the executor (wall times aside): every engine is
deterministic and a job carries everything it needs.

* ``serial``: in this process, in order (debugging, tests).
* ``local`` (default): our own pool of worker processes from a
  ``forkserver`` (engines are imported once per worker, not per job). Its
  parent enforces the time limit a second time: a worker still busy a grace
  period past the limit (stuck inside an engine's C code) is killed and
  replaced, and its job is marked ``timeout``. A worker that dies (segfault
  of an engine) costs its job only: the row says ``failed`` and the exit code.
* ``dask``: ``dask.distributed``, on the cluster at ``scheduler`` or on a
  LocalCluster started for the run. A Dask worker runs jobs in a thread, so
  only the cooperative time limit applies there (checked every protocol step);
  jobs stuck in C code are abandoned by the client after the grace period.
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import os
import sys
import time
from abc import ABC, abstractmethod
from collections import deque
from pathlib import Path
from multiprocessing.connection import wait
from typing import Any, Iterator

from ..registry import Registry
from .jobs import Job, JobResult
from .pipeline import failed_result
from .worker import execute, execute_many, worker_main

DEFAULT_TIMEOUT_S = 600.0  # generous: a full 40 kHz MuJoCo trial takes about 15 s


def grace(timeout_s: float) -> float:
    return max(5.0, 0.2 * timeout_s)


class Executor(ABC):
    """Runs jobs somewhere and yields their results as they finish."""

    name = ""

    @abstractmethod
    def map(self, jobs: list[Job], timeout_s: float | None,
            workdir: Path | None = None) -> Iterator[tuple[Job, JobResult]]:
        """Yield ``(job, result)`` for every job, in completion order.

        ``workdir`` is where jobs run (the run folder), so files an engine
        writes into its working directory (MuJoCo's ``MUJOCO_LOG.TXT``) land
        there and not wherever the command was started.
        """

    def describe(self) -> dict[str, Any]:
        return {"executor": self.name}


EXECUTORS: Registry[type[Executor]] = Registry("executor")


@EXECUTORS.register("serial", ("in-process",), "in this process, one job after another")
class SerialExecutor(Executor):
    name = "serial"

    def map(self, jobs: list[Job], timeout_s: float | None,
            workdir: Path | None = None) -> Iterator[tuple[Job, JobResult]]:
        for job in jobs:
            with contextlib.chdir(workdir) if workdir is not None else contextlib.nullcontext():
                res = execute(job, timeout_s)
            yield job, res


@contextlib.contextmanager
def _no_phantom_main() -> Iterator[None]:
    """Hide a ``__main__.__file__`` that is not a file (``python - <<EOF``, ``python -c``).

    multiprocessing re-runs the parent's main file in each new worker; for
    standard input that "file" does not exist and every worker would die at
    start. Workers never need the caller's main module: jobs carry canebench
    objects only.
    """
    main = sys.modules.get("__main__")
    path = getattr(main, "__file__", None)
    phantom = path is not None and not os.path.isfile(path)
    if phantom:
        del main.__file__
    try:
        yield
    finally:
        if phantom:
            main.__file__ = path


class _Worker:
    def __init__(self, ctx: Any, lifeline: Any, timeout_s: float | None, workdir: Path | None = None) -> None:
        self.conn, child = ctx.Pipe()
        self.proc = ctx.Process(target=worker_main, args=(child, lifeline, timeout_s, workdir), daemon=True)
        with _no_phantom_main():
            self.proc.start()
        child.close()
        self.job: Job | None = None
        self.started = 0.0

    def give(self, job: Job) -> None:
        self.job, self.started = job, time.monotonic()
        try:
            self.conn.send(job)
        except OSError:
            pass  # the worker died (at start?): wait() sees EOF and reports the job failed

    def kill(self) -> None:
        if self.proc.is_alive():
            self.proc.kill()
        self.proc.join(timeout=5)
        self.conn.close()


@EXECUTORS.register("local", ("default", "processes"), "a pool of worker processes on this machine")
class LocalExecutor(Executor):
    """A pool of ``jobs`` worker processes (default: every core)."""

    name = "local"

    def __init__(self, jobs: int | None = None, start_method: str = "forkserver") -> None:
        self.n = max(1, jobs or os.cpu_count() or 1)
        self.start_method = start_method

    def describe(self) -> dict[str, Any]:
        return {"executor": self.name, "workers": self.n, "start_method": self.start_method}

    def map(self, jobs: list[Job], timeout_s: float | None,
            workdir: Path | None = None) -> Iterator[tuple[Job, JobResult]]:
        if not jobs:
            return
        ctx = mp.get_context(self.start_method)
        if self.start_method == "forkserver":
            ctx.set_forkserver_preload(["canebench.execute.worker"])
        # the parent holds the only writer; its death closes the pipe and the workers exit
        life_r, life_w = ctx.Pipe(duplex=False)
        workers = [_Worker(ctx, life_r, timeout_s, workdir) for _ in range(min(self.n, len(jobs)))]
        queue = deque(jobs)
        hard = (timeout_s + grace(timeout_s)) if timeout_s and timeout_s > 0 else None
        try:
            for w in workers:
                if queue:
                    w.give(queue.popleft())
            while any(w.job is not None for w in workers):
                busy = {w.conn: w for w in workers if w.job is not None}
                for conn in wait(list(busy), timeout=0.25):
                    w = busy[conn]
                    job = w.job
                    try:
                        res = conn.recv()
                    except (EOFError, OSError):
                        w.proc.join(timeout=5)
                        res = failed_result(job, "failed", f"worker process died (exit code {w.proc.exitcode})",
                                            time.monotonic() - w.started)
                        w.kill()
                        workers[workers.index(w)] = w = _Worker(ctx, life_r, timeout_s, workdir)
                    w.job = None
                    yield job, res
                    if queue:
                        w.give(queue.popleft())
                if hard is not None:
                    now = time.monotonic()
                    for i, w in enumerate(workers):
                        if w.job is not None and now - w.started > hard:
                            job = w.job
                            w.kill()
                            workers[i] = nw = _Worker(ctx, life_r, timeout_s, workdir)
                            yield job, failed_result(job, "timeout", f"timeout: no answer {hard:g} s after start "
                                                     "(worker killed)", now - w.started)
                            if queue:
                                nw.give(queue.popleft())
        finally:
            for w in workers:
                if w.job is None and w.proc.is_alive():
                    try:
                        w.conn.send(None)
                    except OSError:
                        pass
            for w in workers:
                if w.job is not None:
                    w.kill()  # cancelled: in flight when the caller stopped
                else:
                    w.proc.join(timeout=2)
                    w.kill()
            life_w.close()
            life_r.close()


@EXECUTORS.register("dask", ("cluster", "distributed"), "dask.distributed: a cluster, or a LocalCluster")
class DaskExecutor(Executor):
    """Jobs as Dask futures.

    Parameters
    ----------
    scheduler : str, optional
        Address of a running scheduler (``tcp://host:8786``); without it a
        ``LocalCluster`` of ``workers`` single-threaded processes is started
        for the run and closed after it.
    """

    name = "dask"

    def __init__(self, scheduler: str | None = None, workers: int | None = None, chunk: int | None = None) -> None:
        self.scheduler = scheduler
        self.n = max(1, workers or os.cpu_count() or 1)
        self.chunk = chunk  # jobs per Dask task (None: sized from the job count)

    def describe(self) -> dict[str, Any]:
        return {"executor": self.name, "scheduler": self.scheduler or f"LocalCluster({self.n} workers)"}

    def map(self, jobs: list[Job], timeout_s: float | None,
            workdir: Path | None = None) -> Iterator[tuple[Job, JobResult]]:
        # workdir is not applied: Dask workers may be other machines (their own working directories)
        if not jobs:
            return
        from dask.distributed import Client, LocalCluster

        cluster = None
        if self.scheduler:
            client = Client(self.scheduler, set_as_default=False)
        else:
            with _no_phantom_main():
                cluster = LocalCluster(n_workers=self.n, threads_per_worker=1, processes=True,
                                       dashboard_address=None, silence_logs=40)
            client = Client(cluster, set_as_default=False)
        hard = (timeout_s + grace(timeout_s)) if timeout_s and timeout_s > 0 else None
        futs: dict[Any, list[Job]] = {}
        try:
            # Several jobs per task: a Dask task costs milliseconds of scheduling and
            # serialization, about what a Pinocchio job costs to run. Chunks stay small
            # enough (at least 8 per worker) to balance the load and report progress.
            size = self.chunk or max(1, min(16, len(jobs) // (8 * self.n)))
            chunks = [jobs[i:i + size] for i in range(0, len(jobs), size)]
            keys = [f"canebench-{c[0].key}-{i}" for i, c in enumerate(chunks)]
            for f, c in zip(client.map(execute_many, chunks, [timeout_s] * len(chunks), key=keys, pure=False),
                            chunks):
                futs[f] = c
            started: dict[Any, float] = {}
            pending = dict.fromkeys(futs)  # insertion-ordered set
            while pending:
                # the futures' own states (no default client: several may coexist in one process)
                batch = [f for f in pending if f.done()]
                if not batch:
                    time.sleep(0.02)
                for f in batch:
                    pending.pop(f)
                # one round trip for the whole batch, not one per future
                ok = [f for f in batch if f.status == "finished"]
                results = dict(zip(ok, client.gather(ok))) if ok else {}
                for f in batch:
                    if f in results:
                        yield from zip(futs[f], results[f])
                    else:  # worker lost, unpicklable result...
                        exc = f.exception()
                        for job in futs[f]:
                            yield job, failed_result(job, "failed", f"dask: {type(exc).__name__}: {exc}")
                if hard is not None and pending and not batch:
                    # a chunk's clock starts when the scheduler reports it processing
                    now = time.monotonic()
                    processing = {k for keys in client.processing().values() for k in keys}
                    for f in list(pending):
                        if f.key in processing:
                            started.setdefault(f, now)
                            if now - started[f] > hard * len(futs[f]):
                                pending.pop(f)
                                f.cancel()
                                for job in futs[f]:
                                    yield job, failed_result(job, "timeout", f"timeout: no answer {hard:g} s per "
                                                             "job after start (abandoned)", now - started[f])
        finally:
            for f in futs:
                if not f.done():
                    f.cancel()
            client.close()
            if cluster is not None:
                cluster.close()


def make_executor(name: str = "local", jobs: int | None = None, scheduler: str | None = None) -> Executor:
    """An executor by registry name, configured from CLI-style options.

    A ``scheduler`` address is tried at once, so a wrong one is an input
    error before any work, not a traceback after a connection timeout.
    """
    from ..errors import InputError

    cls = EXECUTORS[name]
    if cls is LocalExecutor:
        return LocalExecutor(jobs)
    if cls is DaskExecutor:
        if scheduler:
            from dask.distributed import Client

            try:
                Client(scheduler, timeout=10, set_as_default=False).close()
            except Exception as exc:
                raise InputError("--scheduler", "scheduler",
                                 f"cannot reach a Dask scheduler at {scheduler}: {type(exc).__name__}: {exc}") from None
        return DaskExecutor(scheduler, jobs)
    return cls()
