"""Kill tests: an interrupted run (SIGINT, or SIGKILL of the parent) leaves a
store that resumes to the same results, and no worker outlives its parent."""

from __future__ import annotations

import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import psutil
import pytest

TRIALS = "b1*,b2*,b3*"  # 27 trials x 2 engines: several seconds of work on 2 workers
CMD = [sys.executable, "-m", "canebench", "run", "--backends", "mujoco,pinocchio", "--trials", TRIALS,
       "--jobs", "2", "--no-report"]


def done_jobs(out: Path) -> int:
    db = out / "store.sqlite"
    if not db.exists():
        return 0
    try:
        with sqlite3.connect(f"file:{db}?mode=ro", uri=True, timeout=1) as c:
            return int(c.execute("SELECT COUNT(*) FROM results").fetchone()[0])
    except sqlite3.Error:
        return 0


def _sigint_default() -> None:
    # a shell starts background commands with SIGINT ignored, and Python then installs no
    # KeyboardInterrupt handler: a run under `.ci/run &` would ignore the test's SIGINT.
    # Give the child the terminal's default, as a user pressing Ctrl-C has.
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def start_and_wait(out: Path, at_least: int) -> tuple[subprocess.Popen, list[psutil.Process]]:
    p = subprocess.Popen([*CMD, "--out", str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         preexec_fn=_sigint_default)
    deadline = time.monotonic() + 120
    while done_jobs(out) < at_least:
        assert p.poll() is None, p.communicate()
        assert time.monotonic() < deadline, "no progress"
        time.sleep(0.05)
    kids = psutil.Process(p.pid).children(recursive=True)
    assert kids, "the local executor should have worker processes"
    return p, kids


def running(procs: list[psutil.Process]) -> list[psutil.Process]:
    out = []
    for k in procs:
        try:
            if k.is_running() and k.status() != psutil.STATUS_ZOMBIE:
                out.append(k)
        except psutil.NoSuchProcess:
            pass
    return out


def wait_gone(procs: list[psutil.Process], seconds: float = 10.0) -> list[psutil.Process]:
    deadline = time.monotonic() + seconds
    while running(procs) and time.monotonic() < deadline:
        time.sleep(0.1)
    return running(procs)


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    out = tmp_path_factory.mktemp("reference")
    r = subprocess.run([*CMD, "--out", str(out), "--quiet"], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    return pd.read_csv(out / "results.csv")


def resume_and_compare(out: Path, reference: pd.DataFrame, n_before: int) -> None:
    r = subprocess.run([*CMD, "--out", str(out)], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stdout + r.stderr
    reused = int(r.stdout.split("reusing ")[1].split()[0])
    assert reused >= n_before  # every job finished before the kill is reused
    res = pd.read_csv(out / "results.csv")
    cols = [c for c in reference.columns if c not in ("wall_s", "cpu_s")]
    pd.testing.assert_frame_equal(res[cols], reference[cols])


def test_sigint_writes_outputs_and_resumes(tmp_path, reference):
    out = tmp_path / "run"
    p, kids = start_and_wait(out, 6)
    p.send_signal(signal.SIGINT)
    stdout, stderr = p.communicate(timeout=60)
    assert p.returncode == 130, stdout + stderr
    assert "resume" in stderr.lower() and str(out) in stderr
    assert not wait_gone(kids), "workers outlived the interrupted parent"
    partial = pd.read_csv(out / "results.csv")  # written from what was done
    n = done_jobs(out)
    assert 6 <= len(partial) == n < len(reference)
    assert '"state": "interrupted"' in (out / "run.json").read_text()
    from canebench.reports.build import build_report

    assert "Incomplete run" in build_report(out).read_text()
    resume_and_compare(out, reference, n)


def test_sigkill_of_the_parent_takes_the_workers_and_the_store_resumes(tmp_path, reference):
    out = tmp_path / "run"
    p, kids = start_and_wait(out, 6)
    p.kill()
    p.communicate(timeout=30)
    assert not wait_gone(kids), "workers outlived their killed parent"
    n = done_jobs(out)
    assert n >= 6
    resume_and_compare(out, reference, n)


@pytest.mark.parametrize("how", ["SIGINT", "SIGKILL"])
def test_busy_workers_do_not_outlive_the_parent(tmp_path, how):
    # each worker is deep in a job that would take hours (100000 links):
    # only the parent's cancel (SIGINT) or the lifeline (SIGKILL) can stop it
    p = subprocess.Popen([sys.executable, "-m", "canebench", "run", "--backends", "pinocchio", "--trials",
                          "b1c1t1,b1c1t2", "--set", "segments=100000", "--jobs", "2", "--no-report", "--quiet",
                          "--out", str(tmp_path / "run")], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                         preexec_fn=_sigint_default)
    deadline = time.monotonic() + 60
    kids: list[psutil.Process] = []
    while time.monotonic() < deadline:
        kids = psutil.Process(p.pid).children(recursive=True)
        busy = [k for k in kids if k.cpu_times().user > 0.5]  # workers past start-up, inside the job
        if len(busy) >= 2:
            break
        time.sleep(0.2)
    assert len(kids) >= 2
    p.send_signal(signal.SIGINT if how == "SIGINT" else signal.SIGKILL)
    p.wait(timeout=60)
    assert not wait_gone(kids, 15), f"{how}: workers outlived the parent"
