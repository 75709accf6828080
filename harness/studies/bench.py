"""Benchmarks measured in one process: ratios, never absolute thresholds.

``bench_morris`` times a Method of Morris study per engine on a subset of
trials and extrapolates it to a whole study (1,040 runs), with ratios to
Pinocchio and the paper (40 kHz) protocol's estimate from a few MuJoCo runs.

``bench_protocols`` probes a few bundled trials with every requested backend
under the paper protocol (40 kHz) and the fast one, and prints per trial:
the stiffness and its difference from the Pinocchio static answer, the
fast/paper stiffness difference, each engine's wall time as a ratio to
MuJoCo's in the same run and protocol, and each engine's paper/fast speed-up.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

from ..model.chain import build_chain
from ..model.config import ModelConfig
from ..data.dataset import bundled_dataset, load_dataset
from ..probe.driver import run_probe
from ..probe.protocol import PROTOCOLS
from ..registry import get_backend
from ..execute.pipeline import field_fit_for


def bench_protocols(trials: str = "b1c1t1,b1c2t1,b3c1t2", backends: list[str] | None = None,
                    steps: int | None = None, config: ModelConfig | None = None) -> pd.DataFrame:
    config = config or ModelConfig()
    backends = backends or ["mujoco"]
    if "mujoco" not in backends:
        backends = ["mujoco", *backends]  # the baseline of every ratio
    ref = get_backend("pinocchio")
    rows = []
    for t in load_dataset(bundled_dataset(), trials):
        chain = build_chain(t.cane, t.push_id, config)
        ff = field_fit_for(t)
        n = min(PROTOCOLS["paper"].max_steps, ff.n_steps if ff else 90, steps or 90)
        # timings and comparisons on the protocol's own samples: no finer repeat
        k_ref = run_probe(ref, chain, PROTOCOLS["fast"], n, repeat_finer=False).fit().slope
        for pname in ("fast", "paper"):
            for b in backends:
                tr = run_probe(get_backend(b), chain, PROTOCOLS[pname], n, repeat_finer=False)
                fit = tr.fit() if tr.status == "ok" else None
                rows.append({"trial": t.id, "links": chain.n_links, "steps": n, "protocol": pname, "backend": b,
                             "k_N/mm": fit.slope * 1e-3 if fit else math.nan,
                             "vs_pin": fit.slope / k_ref - 1 if fit else math.nan,
                             "wall_s": tr.wall_s, "status": tr.status, "reason": tr.reason})
    df = pd.DataFrame(rows)
    mj = df[df.backend == "mujoco"].set_index(["trial", "protocol"]).wall_s
    df["wall_vs_mujoco"] = [w / mj[(t, p)] for t, p, w in zip(df.trial, df.protocol, df.wall_s)]
    k = df.pivot_table(index=["trial", "backend"], columns="protocol", values="k_N/mm")
    w = df.pivot_table(index=["trial", "backend"], columns="protocol", values="wall_s")
    pd.set_option("display.width", 200)
    print(df.drop(columns=["reason"]).to_string(index=False, float_format=lambda v: f"{v:.4g}"))
    for r in df[df.status != "ok"].itertuples():
        print(f"  {r.trial} {r.protocol} {r.backend}: {r.status}: {r.reason}")
    summary = pd.DataFrame({"fast_vs_paper_k": (k["fast"] / k["paper"] - 1), "paper_over_fast_wall": w["paper"] / w["fast"]})
    print("\nper trial and backend: stiffness fast/paper - 1 and wall-time speed-up paper/fast")
    print(summary.to_string(float_format=lambda v: f"{v:.3g}"))
    tot = df.groupby(["protocol", "backend"]).wall_s.sum().unstack("protocol")
    tot["paper/fast"] = tot["paper"] / tot["fast"]
    tot["fast vs mujoco"] = tot["fast"] / tot.loc["mujoco", "fast"]
    tot["paper vs mujoco"] = tot["paper"] / tot.loc["mujoco", "paper"]
    print("\ntotals (s) and ratios, same process:")
    print(tot.to_string(float_format=lambda v: f"{v:.3g}"))
    return df


def bench_beam(trials: str = "b1c1t1,b3c1t2,b5c3t1,b6c2t3", config: ModelConfig | None = None) -> pd.DataFrame:
    """One push point's full 90-step sweep with the beam backend (force limit
    lifted so every step is solved), timed against the Pinocchio sweep of the
    chain in the same process."""
    config = config or ModelConfig()
    proto = PROTOCOLS["fast"].replace(force_limit_n=float("inf"))
    rows = []
    for t in load_dataset(bundled_dataset(), trials):
        chain = build_chain(t.cane, t.push_id, config)
        res = {b: run_probe(get_backend(b), chain, proto, 90, repeat_finer=False) for b in ("beam", "pinocchio")}
        row = {"trial": t.id, "steps": len(res["beam"].force), "status": res["beam"].status,
               "beam_s": res["beam"].wall_s, "pinocchio_s": res["pinocchio"].wall_s,
               "beam/pinocchio": res["beam"].wall_s / res["pinocchio"].wall_s,
               "k_beam": res["beam"].fit().slope * 1e-3 if res["beam"].fit() else math.nan,
               "k_chain": res["pinocchio"].fit().slope * 1e-3}
        rows.append(row)
    df = pd.DataFrame(rows)
    print(df.to_string(index=False, float_format=lambda v: f"{v:.4g}"))
    print(f"beam: slowest full 90-step sweep {df.beam_s.max():.2f} s; median {df['beam/pinocchio'].median():.1f}x "
          f"the Pinocchio chain sweep in this run")
    return df


def bench_engines(trials: str | None = None, backends: list[str] | None = None,
                  config: ModelConfig | None = None) -> pd.DataFrame:
    """CPU seconds per backend over the bundled trials (fast protocol), as ratios to MuJoCo.

    Runs every job through the serial executor of the job runner, in this
    process, so the numbers are the engines' own cost (chain build, probe,
    fit) without pool overhead; ``canebench run`` spreads the same work over
    the cores.
    """
    from ..execute.executors import SerialExecutor
    from ..execute.runner import run_trials
    from ..registry import discover

    reg = discover()
    backends = backends or sorted(n for n, i in reg.items() if i.available and "example-plugin" not in i.tags)
    if "mujoco" not in backends:
        backends = ["mujoco", *backends]
    tr = load_dataset(bundled_dataset(), trials)
    out = run_trials(tr, backends, PROTOCOLS["fast"], config or ModelConfig(), executor=SerialExecutor())
    res = out.results
    tot = res.groupby("backend").agg(cpu_s=("cpu_s", "sum"), wall_s=("wall_s", "sum"), jobs=("trial", "size"),
                                     failed=("status", lambda s: int((~s.isin(["ok", "unscored"])).sum())))
    tot["cpu_vs_mujoco"] = tot.cpu_s / tot.loc["mujoco", "cpu_s"]
    tot = tot.sort_values("cpu_s", ascending=False)
    print(f"engine cost over {len(tr)} bundled trials, fast protocol, one process (serial executor):")
    print(tot.to_string(float_format=lambda v: f"{v:.3g}"))
    print(f"total CPU {tot.cpu_s.sum():.1f} s; on 2 cores the ideal wall time is {tot.cpu_s.sum() / 2:.1f} s")
    return tot


def bench_runner(n_jobs: int = 1000, workers: int = 2) -> pd.DataFrame:
    """Job-runner overhead: ``n_jobs`` Pinocchio jobs on the serial, local and Dask executors.

    The jobs are the bundled trials under distinct modulus values (so every
    key is new: nothing is reused), 20 protocol steps each. Prints wall times
    and the ratios local/serial and dask/local measured in this process.
    """
    import tempfile
    import time
    from pathlib import Path

    import numpy as np

    from ..execute.executors import DaskExecutor, LocalExecutor, SerialExecutor
    from ..execute.pipeline import field_stage, make_jobs
    from ..execute.runner import run_jobs

    base = load_dataset(bundled_dataset())
    trials = [base[i % len(base)] for i in range(n_jobs)]
    moduli = np.linspace(2.0e9, 8.0e9, n_jobs)
    configs = [ModelConfig(modulus_pa=float(E)) for E in moduli]
    fields = field_stage(base)
    jobs = make_jobs(trials, ["pinocchio"], PROTOCOLS["fast"], configs, fields, max_steps=20)
    rows = []
    for name, ex in (("serial", SerialExecutor()), ("local", LocalExecutor(workers)),
                     ("dask", DaskExecutor(workers=workers))):
        with tempfile.TemporaryDirectory() as d:
            t0 = time.perf_counter()
            out = run_jobs(jobs, Path(d), ex, fields=fields, with_traces=False)
            wall = time.perf_counter() - t0
        rows.append({"executor": name, "jobs": len(jobs), "wall_s": wall, "ok": int((out.results.status == "ok").sum()),
                     "job_cpu_s": out.results.cpu_s.sum()})
    df = pd.DataFrame(rows).set_index("executor")
    df["per_job_ms"] = 1e3 * df.wall_s / df.jobs
    df["vs_local"] = df.wall_s / df.loc["local", "wall_s"]
    print(f"job runner: {n_jobs} Pinocchio jobs (20 steps each), {workers} workers, store and exports included")
    print(df.to_string(float_format=lambda v: f"{v:.3g}"))
    return df


_MEMORY_PROBE = """
import resource, sys, warnings
warnings.simplefilter("ignore")
from canebench.data.dataset import bundled_dataset, load_dataset
from canebench.model.chain import build_chain
from canebench.model.config import ModelConfig
from canebench.backends.pinocchio_backend import PinocchioStatic
t = load_dataset(bundled_dataset(), "b1c1t1")[0]
ch = build_chain(t.cane, t.push_id, ModelConfig(segments=int(sys.argv[1]), discretization="uniform"))
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
k = PinocchioStatic(ch).linear_stiffness()
after = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
print(before / 1024, after / 1024, k)
"""


def bench_memory(links: tuple[int, ...] = (20, 160, 320)) -> pd.DataFrame:
    """Peak memory of Pinocchio's linear stiffness against link count, each in a fresh process.

    Prints the peak resident set (MB) after building the chain and after the
    linear stiffness, and the growth over the 20-link case measured the same way.
    """
    import subprocess
    import sys

    rows = []
    for n in links:
        r = subprocess.run([sys.executable, "-c", _MEMORY_PROBE, str(n)], capture_output=True, text=True,
                           timeout=600)
        if r.returncode != 0:
            raise RuntimeError(r.stderr[-2000:])
        before, after, k = (float(v) for v in r.stdout.split()[-3:])
        rows.append({"links": n, "dofs": 2 * n, "peak_mb_chain": before, "peak_mb_linear_stiffness": after,
                     "k_linear_n_per_m": k})
    df = pd.DataFrame(rows).set_index("links")
    df["growth_vs_first"] = df.peak_mb_linear_stiffness / df.peak_mb_linear_stiffness.iloc[0]
    print("Pinocchio linear stiffness: peak resident memory (MB), fresh process per size")
    print(df.to_string(float_format=lambda v: f"{v:.4g}"))
    return df


def bench_export(population: int = 100, seed: int = 0, formats: str = "mjcf,sdf,urdf",
                 config: ModelConfig | None = None) -> pd.DataFrame:
    """Time ``canebench export --population N`` against one single export, in this process.

    A warm-up export (imports, first MuJoCo compile) is not timed; then one
    cane is exported once (the baseline), then a population of ``population``
    drawn canes over the bundled set, all formats, to temporary folders.
    Prints both wall times, the population's time per cane and the ratios
    population/single and per-cane/single.
    """
    import tempfile
    import time
    from pathlib import Path

    from ..export.bundle import export_canes, export_population, parse_formats, select

    config = config or ModelConfig()
    fmts = parse_formats(formats)
    selection = select(load_dataset(bundled_dataset()), by_trial=False)
    with tempfile.TemporaryDirectory() as d:
        export_canes(selection[:1], config, Path(d) / "warmup", fmts)
        t0 = time.perf_counter()
        export_canes(selection[:1], config, Path(d) / "single", fmts)
        single = time.perf_counter() - t0
        t0 = time.perf_counter()
        res = export_population(selection, config, Path(d) / "population", population, seed, formats=fmts)
        pop = time.perf_counter() - t0
        n_files = sum(1 for _ in (Path(d) / "population").rglob("*") if _.is_file())
    df = pd.DataFrame([{"what": "single", "canes": 1, "wall_s": single},
                       {"what": "population", "canes": len(res.manifest), "wall_s": pop}]).set_index("what")
    df["per_cane_s"] = df.wall_s / df.canes
    df["vs_single"] = df.wall_s / single
    print(f"export ({','.join(fmts)}), one process: one cane vs a population of {population} drawn canes "
          f"(seed {seed}, {n_files} files incl. manifest)")
    print(df.to_string(float_format=lambda v: f"{v:.4g}"))
    print(f"population of {population}: {pop:.2f} s ({pop / population * 1e3:.1f} ms per cane, "
          f"{df.per_cane_s['population'] / single:.2f}x one single export per cane)")
    return df


#: the issue's targets for one Method of Morris study over all usable real trials (wall time, 2 cores)
MORRIS_RUNS = 1040  # 52 usable trials x 20 design points
MORRIS_TARGETS_S = {"pinocchio": 30.0, "mujoco": 180.0}
MORRIS_ALL_TARGET_S = 900.0
CHAIN_ENGINES = ("pinocchio", "mujoco", "pybullet", "exudyn", "dart")


def _spread(items: list, n: int) -> list:
    """``n`` items evenly spread over ``items`` (deterministic)."""
    if n >= len(items):
        return list(items)
    idx = np.unique(np.linspace(0, len(items) - 1, n).round().astype(int))
    return [items[i] for i in idx]


def bench_morris(backends: list[str] | None = None, data: str | None = None, trials: str | None = None,
                 n_trials: int = 2, paper_runs: int = 3, paper_steps: int = 2, runs: int = MORRIS_RUNS,
                 workers: int = 2) -> pd.DataFrame:
    """CPU time of the Method of Morris per engine on a subset, extrapolated to a whole study.

    Every job of the subset (``n_trials`` usable trials spread over the dataset,
    or ``trials``, x the 20 points of the Morris design) runs through the
    study's own job function (:func:`canebench.execute.pipeline.run_job`:
    chain, probe, fit) serially in this process, so the numbers are the
    engines' cost without pool overhead. Pinocchio always runs, first: every
    ratio is to Pinocchio measured here. The study estimate is the mean CPU
    per run x ``runs`` (1,040: 52 usable trials x 20 points), and its ideal
    wall time on ``workers`` cores is that over ``workers``.

    The paper's 40 kHz protocol: ``paper_runs`` MuJoCo jobs of the subset
    (spread over segment counts) run ``paper_steps`` setpoints under the paper
    protocol; its cost per setpoint is fixed (40,000 steps), so the full run
    costs that x the setpoints the fast run made (same stop rule). The ratio
    paper/fast over those jobs, applied to the MuJoCo fast estimate, gives the
    paper-protocol study time.
    """
    import time

    from ..execute.pipeline import field_stage, make_jobs, run_job
    from ..registry import discover
    from .paper import morris_configs

    reg = discover()
    wanted = list(backends or CHAIN_ENGINES)
    usable = [b for b in dict.fromkeys(["pinocchio", *wanted]) if b in reg and reg[b].available]
    skipped = [b for b in wanted if b not in usable]
    d = Path(data) if data else bundled_dataset()
    all_trials = load_dataset(d, trials)
    fields = field_stage(all_trials)
    ok_trials = [t for t in all_trials if fields[t.id].fit is not None and fields[t.id].fit.usable]
    proto = PROTOCOLS["fast"]
    steps = {t.id: fields[t.id].n_steps(proto) for t in ok_trials}
    # spread over the trials' lengths (setpoints): short stiff pushes and long soft ones
    subset = ok_trials if trials else _spread(sorted(ok_trials, key=lambda t: (steps[t.id], t.id)), n_trials)
    mean_steps = float(np.mean(list(steps.values())))
    _, configs = morris_configs()
    pairs = [(t, c) for t in subset for c in configs]
    print(f"Method of Morris benchmark: {len(subset)} usable trial(s) of {d} ({', '.join(t.id for t in subset)}) x "
          f"{len(configs)} design points = {len(pairs)} runs per engine, fast protocol, serial, one process; "
          f"{len(ok_trials)} usable trials here ({len(ok_trials) * len(configs)} runs), the issue's study: {runs}")
    for b in skipped:
        print(f"  skipping {b}: not available")
    rows, mj_jobs = [], []
    for b in usable:
        jobs = make_jobs([t for t, _ in pairs], [b], proto, [c for _, c in pairs], fields)
        setpoints = sum(j.n_steps for j in jobs)
        cpu, failed, n_samples = [], 0, []
        t0 = time.perf_counter()
        for j in jobs:
            r = run_job(j)
            cpu.append(r.row["cpu_s"])
            failed += r.row["status"] != "ok"
            n_samples.append(r.row.get("n_samples", 0))
            if b == "mujoco":
                mj_jobs.append((j, r.row["cpu_s"], r.row.get("n_samples", 0), r.row.get("n_links", 0)))
        wall = time.perf_counter() - t0
        mean = float(np.mean(cpu))
        # a run costs in proportion to its setpoints (fixed steps each): weight by the dataset's trial lengths
        study = float(np.sum(cpu)) / setpoints * mean_steps * runs
        rows.append({"backend": b, "runs": len(jobs), "failed": failed, "cpu_per_run_s": mean,
                     "cpu_max_s": float(np.max(cpu)), "wall_s": wall, "study_cpu_s": study,
                     f"study_wall_{workers}cores_s": study / workers})
        print(f"  {b:10s} {len(jobs)} runs, {failed} failed, {mean:.3f} s CPU per run (max {np.max(cpu):.2f})",
              flush=True)
    df = pd.DataFrame(rows).set_index("backend")
    df["vs_pinocchio"] = df.cpu_per_run_s / df.loc["pinocchio", "cpu_per_run_s"]
    wcol = f"study_wall_{workers}cores_s"
    df["target_s"] = [MORRIS_TARGETS_S.get(b, np.nan) for b in df.index]
    df["meets_target"] = [("yes" if w < t else "no") if np.isfinite(t) else "" for w, t in zip(df[wcol], df.target_s)]
    pd.set_option("display.width", 200)
    print(f"\nper engine: CPU per run here; a {runs}-run study's CPU (CPU per setpoint x the dataset's mean "
          f"{mean_steps:.1f} setpoints per trial x {runs}) and ideal wall time on {workers} cores (CPU / cores); "
          "ratio to Pinocchio in this process; the issue's target:")
    print(df.to_string(float_format=lambda v: f"{v:.3g}"))
    engines = [b for b in CHAIN_ENGINES if b in df.index]
    total = float(df.loc[engines, wcol].sum())
    print(f"all {len(engines)} chain engines ({', '.join(engines)}): {total:.0f} s = {total / 60:.1f} min on "
          f"{workers} cores (target: all five under {MORRIS_ALL_TARGET_S / 60:.0f} min"
          f"{'' if len(engines) == len(CHAIN_ENGINES) else '; not all five measured'})")
    if paper_runs > 0 and "mujoco" in reg and reg["mujoco"].available:
        df.attrs["paper"] = _paper_estimate(mj_jobs, pairs, fields, paper_runs, paper_steps,
                                            df.loc["mujoco", "study_cpu_s"] if "mujoco" in df.index else None,
                                            runs, workers, mean_steps)
    return df


def _paper_estimate(mj_jobs: list, pairs: list, fields: dict, paper_runs: int, paper_steps: int,
                    fast_study_cpu: float | None, runs: int, workers: int, mean_steps: float) -> dict:
    """MuJoCo under the paper protocol: a few runs' first setpoints, scaled to whole runs and to the study."""
    import time

    from ..execute.pipeline import make_jobs, run_job

    proto = PROTOCOLS["paper"]
    if not mj_jobs:  # MuJoCo not benchmarked: its fast runs for the sampled jobs, here
        for j in make_jobs([t for t, _ in pairs], ["mujoco"], PROTOCOLS["fast"], [c for _, c in pairs], fields):
            r = run_job(j)
            mj_jobs.append((j, r.row["cpu_s"], r.row.get("n_samples", 0), r.row.get("n_links", 0)))
    pick = _spread(sorted(mj_jobs, key=lambda r: (r[3], r[0].trial.id)), paper_runs)
    backend = get_backend("mujoco")
    fast_cpu = paper_cpu = 0.0
    rows = []
    for job, cpu_fast, n_fast, links in pick:
        chain = build_chain(job.trial.cane, job.trial.push_id, job.config)
        c0 = time.process_time()
        tr = run_probe(backend, chain, proto, paper_steps, repeat_finer=False)
        per_step = (time.process_time() - c0) / max(len(tr.force), 1)
        est = per_step * max(n_fast, 1)
        rows.append({"trial": job.trial.id, "links": links, "fast_cpu_s": cpu_fast, "setpoints": n_fast,
                     "paper_cpu_per_setpoint_s": per_step, "paper_run_est_s": est, "paper/fast": est / cpu_fast,
                     "status": tr.status})
        fast_cpu += cpu_fast
        paper_cpu += est
    t = pd.DataFrame(rows)
    ratio = paper_cpu / fast_cpu
    print(f"\nMuJoCo, paper protocol (40 kHz, harness PID): {len(t)} runs timed over their first {paper_steps} "
          "setpoint(s), scaled to the setpoints of the same fast run:")
    print(t.to_string(index=False, float_format=lambda v: f"{v:.3g}"))
    out = {"paper_over_fast": ratio, "runs": t.to_dict("records")}
    if fast_study_cpu is None:  # MuJoCo was not among the engines: its fast runs of the subset, timed above
        fast_study_cpu = sum(r[1] for r in mj_jobs) / sum(r[0].n_steps for r in mj_jobs) * mean_steps * runs
    if fast_study_cpu is not None:
        est = ratio * fast_study_cpu
        out.update(study_cpu_s=est, study_wall_s=est / workers)
        print(f"paper/fast CPU ratio {ratio:.0f}x: the {runs}-run Morris study on the paper protocol would take "
              f"{est / 3600:.1f} h of MuJoCo CPU ({est / workers / 3600:.1f} h on {workers} cores), against "
              f"{fast_study_cpu / workers / 60:.1f} min on the fast protocol (the issue estimated ~11 h)")
    return out


def bench_discover(data: str | None = None, backends: list[str] | None = None, workers: int = 2,
                   out: str | None = None) -> dict[str, float]:
    """The whole discovery workflow (baseline, selection, intervals, engine confirmation) timed by
    stage, as a ratio to a plain beam run of the same trials in the same process (the
    workflow's own baseline stage, measured first with its own store so nothing is reused).
    """
    import tempfile
    import time

    from ..discovery.workflow import discover
    from ..execute.executors import make_executor
    from ..execute.progress import Progress
    from ..execute.runner import run_trials
    from ..model.presets import PRESETS

    trials = load_dataset(data or bundled_dataset())
    backends = backends or ["beam", "pinocchio", "mujoco"]
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(out or tmp)
        ex = make_executor("local", workers, None)
        t0 = time.perf_counter()
        run_trials(trials, ["beam"], PROTOCOLS["fast"], PRESETS["beam-consistent"], root / "plain_beam",
                   executor=ex, progress=Progress())
        t_plain = time.perf_counter() - t0
        t0 = time.perf_counter()
        res = discover(trials, "beam", backends, root / "discover", ex, progress=Progress())
        t_all = time.perf_counter() - t0
    print(f"discovery workflow on {len(trials)} trials ({data or 'bundled synthetic set'}), confirmed on "
          f"{', '.join(backends)}, local executor with {workers} workers:")
    for k, v in res.timing.items():
        print(f"  {k:16s} {v:7.1f} s")
    print(f"  wall {t_all:.1f} s = {t_all / t_plain:.1f}x a plain beam run of the same trials ({t_plain:.1f} s); "
          f"target: under 180 s: {'met' if t_all < 180 else 'NOT met'}")
    print(f"  named: {', '.join(n['effect'] for n in res.named) or 'nothing'}; unexplained: {res.unexplained}")
    return {"wall_s": t_all, "plain_beam_s": t_plain, **res.timing}


def bench_contact(data: str | None = None, jump: int = 20) -> pd.DataFrame:
    """The IMU rule's change points with ``ruptures``' own rbf cost and with
    :class:`~canebench.measure.kernel_cost.CostRbfPrefix`, on every channel of every
    ``*.imu.csv`` in ``data`` (default: the bundled synthetic contact set), in this process.

    Prints both costs' seconds, their ratio, and how many channels' change points
    differ (the prefix cost is only a faster sum: a difference means a bug, or a near-tie
    between two candidate splits that rounding decided the other way).
    """
    import time

    import ruptures as rpt

    from .. import canes
    from ..data.imu import read_imu_csv
    from ..measure.contact import PEN_FACTOR, _changepoints, imu_residuals

    d = Path(data) if data else Path(canes.__file__).resolve().parent / "synthetic-contact"
    files = sorted((d / "trials").glob("*.imu.csv")) or sorted(d.glob("*.imu.csv"))
    if not files:
        raise FileNotFoundError(f"{d}: no *.imu.csv files (IMU logs beside the rig CSVs)")
    rows = []
    for f in files:
        resid = imu_residuals(read_imu_csv(f))
        for k in range(resid.shape[1]):
            x = resid[:, k]
            t0 = time.perf_counter()
            a = _changepoints(x, PEN_FACTOR, jump, cost=rpt.costs.CostRbf())
            t1 = time.perf_counter()
            b = _changepoints(x, PEN_FACTOR, jump)
            t2 = time.perf_counter()
            rows.append({"file": f.name, "channel": k, "n": len(x), "ruptures_s": t1 - t0, "prefix_s": t2 - t1,
                         "same": a == b})
    df = pd.DataFrame(rows)
    ta, tb = df.ruptures_s.sum(), df.prefix_s.sum()
    print(f"IMU change points, {len(files)} logs x 9 channels ({df.n.median():.0f} samples median), jump {jump}, "
          f"one process:")
    print(f"  ruptures' CostRbf {ta:.1f} s, CostRbfPrefix {tb:.1f} s: {ta / tb:.1f}x faster; "
          f"channels with different change points: {int((~df.same).sum())} of {len(df)}")
    return df
