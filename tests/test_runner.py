"""The job runner: stable keys, the store and resume, executors, time limits, failures."""

from __future__ import annotations

import dataclasses
import os

import pandas as pd
import pytest

from canebench.backends.base import StaticBackend
from canebench.execute.executors import DaskExecutor, LocalExecutor, SerialExecutor
from canebench.execute.jobs import Job
from canebench.execute.pipeline import field_stage, make_jobs
from canebench.execute.runner import run_jobs
from canebench.execute.store import Store
from canebench.model.config import ModelConfig
from canebench.probe.protocol import PROTOCOLS
from canebench.registry import register_backend, unregister_backend

FAST = PROTOCOLS["fast"]
VOLATILE = ["wall_s", "cpu_s"]  # the only columns allowed to differ between identical runs


@pytest.fixture(scope="module")
def two_trials(bundled_trials):
    return [t for t in bundled_trials if t.id in ("b1c1t1", "b3c2t2")]


def stable(df: pd.DataFrame) -> pd.DataFrame:
    return df.drop(columns=[c for c in VOLATILE if c in df.columns]).reset_index(drop=True)


# ---------------------------------------------------------------- keys


def test_key_is_stable_and_covers_everything_the_result_depends_on(two_trials):
    _check_keys(two_trials)


def _check_keys(two_trials):
    t = two_trials[0]
    base = Job(t, "pinocchio", "4.1.0", FAST, ModelConfig(), 40)
    assert base.key == Job(t, "pinocchio", "4.1.0", FAST, ModelConfig(), 40).key
    assert base.key == Job(t, "pinocchio", "4.1.0", FAST, ModelConfig(), 40, {"sample": 7}).key  # labels aside
    # the same cane read from another path is the same physics
    moved = dataclasses.replace(t, cane=dataclasses.replace(t.cane, source="/elsewhere/b1c1.yaml"))
    assert Job(moved, "pinocchio", "4.1.0", FAST, ModelConfig(), 40).key == base.key
    variants = [
        Job(t, "mujoco", "4.1.0", FAST, ModelConfig(), 40),
        Job(t, "pinocchio", "4.2.0", FAST, ModelConfig(), 40),
        Job(t, "pinocchio", "4.1.0", PROTOCOLS["paper"], ModelConfig(), 40),
        Job(t, "pinocchio", "4.1.0", FAST.replace(kp=751.0), ModelConfig(), 40),
        Job(t, "pinocchio", "4.1.0", FAST, ModelConfig(modulus_pa=3e9), 40),
        Job(t, "pinocchio", "4.1.0", FAST, ModelConfig(effects=("root_compliance(k_root=50)",)), 40),
        Job(t, "pinocchio", "4.1.0", FAST, ModelConfig(effects=("root_compliance(k_root=60)",)), 40),
        Job(t, "pinocchio", "4.1.0", FAST, ModelConfig(), 41),
        Job(two_trials[1], "pinocchio", "4.1.0", FAST, ModelConfig(), 40),
        Job(dataclasses.replace(t, cane=dataclasses.replace(t.cane, polyline=t.cane.polyline * 1.001)),
            "pinocchio", "4.1.0", FAST, ModelConfig(), 40),
    ]
    keys = {base.key} | {v.key for v in variants}
    assert len(keys) == len(variants) + 1


# ---------------------------------------------------------------- store and resume


def test_rerun_resumes_and_fresh_starts_over(tmp_path, two_trials):
    jobs = make_jobs(two_trials, ["pinocchio"], FAST, ModelConfig())
    first = run_jobs(jobs, tmp_path, SerialExecutor())
    assert (first.n_reused, first.n_run, first.exit_code) == (0, 2, 0)
    again = run_jobs(jobs, tmp_path, SerialExecutor())
    assert (again.n_reused, again.n_run) == (2, 0)
    pd.testing.assert_frame_equal(stable(again.results), stable(first.results))
    # the exports come from the store: identical files
    assert pd.read_csv(tmp_path / "results.csv").k_sim.tolist() == first.results.k_sim.tolist()
    fresh = run_jobs(jobs, tmp_path, SerialExecutor(), fresh=True)
    assert (fresh.n_reused, fresh.n_run) == (0, 2)


def test_changed_configuration_reuses_nothing(tmp_path, two_trials):
    run_jobs(make_jobs(two_trials, ["pinocchio"], FAST, ModelConfig()), tmp_path, SerialExecutor())
    other = run_jobs(make_jobs(two_trials, ["pinocchio"], FAST, ModelConfig(modulus_pa=3e9)), tmp_path,
                     SerialExecutor())
    assert other.n_reused == 0 and len(other.results) == 2
    assert len(Store.in_folder(tmp_path)) == 4  # the old results stay for whoever asks for them


def test_store_commits_each_job_whole(tmp_path, two_trials):
    jobs = make_jobs(two_trials, ["pinocchio"], FAST, ModelConfig())
    run_jobs(jobs, tmp_path, SerialExecutor())
    with Store.in_folder(tmp_path) as st:
        got = st.get_many([j.key for j in jobs])
    assert set(got) == {j.key for j in jobs}
    for j in jobs:
        r = got[j.key]
        assert r.row["status"] == "ok" and len(r.displacement_m) == len(r.force_n) == r.row["n_samples"]


# ---------------------------------------------------------------- executors


def multi_config_jobs(trials):
    """Two trials, each under two configurations, on two engines: 8 jobs."""
    configs = [ModelConfig(), ModelConfig(modulus_pa=3.0e9, segments=6)]
    pairs = [(t, c) for t in trials for c in configs]
    return make_jobs([p[0] for p in pairs], ["pinocchio", "mujoco"], FAST, [p[1] for p in pairs],
                     labels=[{"config": i % 2} for i in range(len(pairs))])


def test_serial_local_and_dask_give_identical_rows(tmp_path, two_trials):
    jobs = multi_config_jobs(two_trials)
    serial = run_jobs(jobs, tmp_path / "serial", SerialExecutor()).results
    local = run_jobs(jobs, tmp_path / "local", LocalExecutor(2)).results
    dask = run_jobs(jobs, tmp_path / "dask", DaskExecutor(workers=2)).results
    assert len(serial) == 8 and (serial.status == "ok").all()
    assert serial.config_hash.nunique() == 2 and set(serial.config) == {0, 1}
    pd.testing.assert_frame_equal(stable(local), stable(serial))
    pd.testing.assert_frame_equal(stable(dask), stable(serial))
    # and the trace files, in trial order whatever the completion order
    for d in ("local", "dask"):
        pd.testing.assert_frame_equal(pd.read_csv(tmp_path / d / "traces.csv"),
                                      pd.read_csv(tmp_path / "serial" / "traces.csv"))


@pytest.mark.parametrize("executor", [SerialExecutor(), LocalExecutor(2)], ids=["serial", "local"])
def test_a_hung_job_times_out_and_the_run_goes_on(tmp_path, two_trials, executor):
    # 100000 links: the greedy discretization alone would take hours
    configs = [ModelConfig(segments=100000), ModelConfig()]
    jobs = make_jobs(two_trials, ["pinocchio"], FAST, configs)
    out = run_jobs(jobs, tmp_path, executor, timeout_s=3.0)  # a normal job takes well under 0.5 s
    st = out.results.set_index("trial").status
    assert st[two_trials[0].id] == "timeout" and st[two_trials[1].id] == "ok"
    assert "time limit" in out.results.set_index("trial").reason[two_trials[0].id]
    assert out.exit_code == 0


class Crasher(StaticBackend):
    """An engine that kills its process (as a segfault would)."""

    name = "crasher"
    engine_module = "os"

    def settings(self, protocol):
        return {}

    def build(self, chain):
        os._exit(7)


def test_a_dying_worker_costs_its_job_only(tmp_path, two_trials):
    register_backend(Crasher)
    try:
        out = run_jobs(make_jobs(two_trials, ["crasher", "pinocchio"], FAST, ModelConfig()), tmp_path,
                       LocalExecutor(2))
    finally:
        unregister_backend("crasher")
    res = out.results.set_index(["trial", "backend"])
    for t in two_trials:
        assert res.loc[(t.id, "crasher"), "status"] == "failed"
        assert "exit code 7" in res.loc[(t.id, "crasher"), "reason"]
        assert res.loc[(t.id, "pinocchio"), "status"] == "ok"


def test_every_job_failing_is_a_failed_run(tmp_path, two_trials):
    jobs = make_jobs(two_trials, ["pinocchio"], FAST, ModelConfig(segments=100000))
    out = run_jobs(jobs, tmp_path, SerialExecutor(), timeout_s=0.5)
    assert out.all_failed and out.exit_code == 1
    from canebench.reports.build import build_report

    page = build_report(tmp_path)  # no scored row: a report that says so, not a crash
    assert "No scored trial" in page.read_text()


def test_field_fits_run_once_in_the_client(two_trials):
    fields = field_stage(two_trials)
    assert set(fields) == {t.id for t in two_trials}
    jobs = make_jobs(two_trials, ["pinocchio"], FAST, ModelConfig(), fields)
    assert [j.n_steps for j in jobs] == [fields[t.id].n_steps(FAST) for t in two_trials]


def test_cooperative_time_limit_stops_a_job_in_a_thread(two_trials):
    """A Dask worker runs jobs in threads, where no timer signal reaches: the loops check the deadline."""
    import threading

    from canebench.execute.worker import execute

    job = make_jobs(two_trials[:1], ["pinocchio"], FAST, ModelConfig(segments=100000))[0]
    box = {}
    th = threading.Thread(target=lambda: box.setdefault("r", execute(job, 1.0)))
    th.start()
    th.join(30)
    assert not th.is_alive() and box["r"].row["status"] == "timeout"
