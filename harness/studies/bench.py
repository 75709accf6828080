"""Benchmarks measured in one process: ratios, never absolute thresholds.

``bench_protocols`` probes a few bundled trials with every requested backend
under the paper protocol (40 kHz) and the fast one, and prints per trial:
the stiffness and its difference from the Pinocchio static answer, the
fast/paper stiffness difference, each engine's wall time as a ratio to
MuJoCo's in the same run and protocol, and each engine's paper/fast speed-up.
"""

from __future__ import annotations

import math

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
        k_ref = run_probe(ref, chain, PROTOCOLS["fast"], n).fit().slope
        for pname in ("fast", "paper"):
            for b in backends:
                tr = run_probe(get_backend(b), chain, PROTOCOLS[pname], n)
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
        res = {b: run_probe(get_backend(b), chain, proto, 90) for b in ("beam", "pinocchio")}
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
