"""``canebench bench``: benchmarks that print ratios measured in one process."""

from __future__ import annotations

import argparse

from ..errors import BackendUnavailable, InputError
from . import common


def add_parser(sub: argparse._SubParsersAction) -> None:
    be = sub.add_parser("bench", help="benchmarks: protocols, beam sweep, engines' CPU time, job runner overhead, Morris per engine, discovery, IMU change points")
    be.add_argument("--trials", help="trial globs on the bundled dataset")
    be.add_argument("--beam", action="store_true", help="time the beam backend's full 90-step sweep instead")
    be.add_argument("--engines", action="store_true",
                    help="CPU seconds per backend over the bundled trials, as ratios to MuJoCo")
    be.add_argument("--runner", action="store_true",
                    help="job runner overhead: N Pinocchio jobs on the serial, local and Dask executors")
    be.add_argument("--n-jobs", type=int, default=1000, help="jobs for --runner (default 1000)")
    be.add_argument("--memory", action="store_true",
                    help="peak memory of Pinocchio's linear stiffness at 20, 160 and 320 links")
    be.add_argument("--export", action="store_true",
                    help="time an exported population (--population N, default 100) against one single export")
    be.add_argument("--population", type=int, default=100, help="canes for --export (default 100)")
    be.add_argument("--morris", action="store_true",
                    help="Method of Morris per engine on a subset of trials, extrapolated to a 1,040-run study, "
                         "ratios to Pinocchio, and the same study's estimate on the paper's 40 kHz protocol")
    be.add_argument("--discover", action="store_true",
                    help="the whole discovery workflow with engine confirmation (--backends, default "
                         "beam,pinocchio,mujoco), by stage, as a ratio to a plain beam run of the same trials")
    be.add_argument("--contact", action="store_true",
                    help="the IMU rule's change points: ruptures' rbf cost against canebench's prefix-sum cost "
                         "(--field: a folder of *.imu.csv logs, default the bundled synthetic contact set)")
    be.add_argument("--field", help="--morris, --discover, --contact: dataset (default: the bundled synthetic set)")
    be.add_argument("--n-trials", type=int, default=2,
                    help="--morris: usable trials in the subset, spread over the dataset (default 2; --trials "
                         "overrides)")
    be.add_argument("--paper-runs", type=int, default=3,
                    help="--morris: MuJoCo runs timed on the paper protocol (default 3; 0: skip)")
    be.add_argument("--paper-steps", type=int, default=2,
                    help="--morris: setpoints of each paper-protocol run actually simulated (default 2)")
    be.add_argument("--workers", type=int, default=2, help="--morris: cores for the ideal wall time (default 2)")
    be.add_argument("--backends", default=None,
                    help="comma-separated; MuJoCo is always included as the baseline (--morris: Pinocchio, and "
                         "the default there is the five chain engines)")
    be.add_argument("--steps", type=int, default=None, help="protocol steps per trial (default: full trial)")
    be.set_defaults(fn=main)


def main(a: argparse.Namespace) -> int:
    from ..studies import bench

    if a.workers < 1:
        raise InputError("--workers", "workers", f"must be >= 1, got {a.workers}")
    names: list[str] | None = None  # None: each benchmark's own default engines
    if a.backends:
        # a mistyped engine stops here, as in ``canebench run``; one not installed is skipped, said on stderr
        names, _ = common.backends(a.backends)
        if not names:
            raise BackendUnavailable(f"--backends {a.backends}: no engine there can run")
    if a.morris:
        bench.bench_morris(backends=names, data=a.field, trials=a.trials, n_trials=a.n_trials,
                           paper_runs=a.paper_runs, paper_steps=a.paper_steps, workers=a.workers)
        return 0
    if a.discover:
        bench.bench_discover(data=a.field, backends=names, workers=a.workers)
        return 0
    if a.contact:
        bench.bench_contact(data=a.field)
        return 0
    if a.beam:
        bench.bench_beam(trials=a.trials or "b1c1t1,b3c1t2,b5c3t1,b6c2t3")
    elif a.engines:
        bench.bench_engines(trials=a.trials, backends=names)
    elif a.memory:
        bench.bench_memory()
    elif a.export:
        bench.bench_export(population=a.population)
    elif a.runner:
        bench.bench_runner(n_jobs=a.n_jobs)
    else:
        bench.bench_protocols(trials=a.trials or "b1c1t1,b1c2t1,b3c1t2", backends=names or ["mujoco"],
                              steps=a.steps)
    return 0
