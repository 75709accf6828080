"""``canebench`` command line: run, report, backends, bench, generate."""

from __future__ import annotations

import argparse
import datetime as _dt
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from .config import ModelConfig, parse_assignments
from .errors import CanebenchError

DEFAULT_BACKENDS = "mujoco,pinocchio"


def _progress(done: int, total: int, outcome) -> None:
    parts = []
    for r in outcome.rows:
        k = r.get("k_sim")
        kk = f"{k:.4g}" if isinstance(k, float) and k == k else "-"
        parts.append(f"{r['backend']}={kk}" + ("" if r["status"] == "ok" else f"[{r['status']}]"))
    trial = outcome.rows[0]["trial"] if outcome.rows else "?"
    print(f"[{done:3d}/{total}] {trial:10s} {' '.join(parts)}", flush=True)


def cmd_run(a: argparse.Namespace) -> int:
    from .dataset import bundled_dataset, load_dataset
    from .protocol import get_protocol
    from .registry import select
    from .run import provenance, run_trials, write_run

    data_dir = Path(a.field) if a.field else bundled_dataset()
    trials = load_dataset(data_dir, a.trials)
    if a.limit:
        trials = trials[: a.limit]
    names = [n.strip() for n in a.backends.split(",") if n.strip()]
    usable, skipped = select(names)
    for n, why in skipped.items():
        print(f"skipping backend {n}: {why}", file=sys.stderr)
    if not usable:
        print("no usable backend", file=sys.stderr)
        return 2
    proto = get_protocol(a.protocol)
    config = ModelConfig().with_overrides(parse_assignments(a.set))
    out = Path(a.out) if a.out else Path("canebench-runs") / _dt.datetime.now().strftime("run-%Y%m%d-%H%M%S")
    synthetic = all(t.cane.provenance.get("synthetic", False) for t in trials)
    assumptions = sorted({s for t in trials for s in t.cane.provenance.get("assumptions", [])})
    print(f"canebench run: {len(trials)} trials from {data_dir}"
          f"{' (SYNTHETIC data)' if synthetic else ''}, backends {','.join(usable)}, protocol {proto.name}, "
          f"{a.jobs} worker(s) -> {out}")
    for s in assumptions:
        print(f"  assumption: {s}")
    t0 = time.perf_counter()
    res, traces, fields = run_trials(trials, usable, proto, config, out, jobs=a.jobs, max_steps=a.max_steps,
                                     progress=_progress)
    meta = provenance(usable, proto, config, {
        "command": " ".join(sys.argv),
        "dataset": str(data_dir.resolve()),
        "dataset_provenance": trials[0].cane.provenance if trials else {},
        "synthetic": synthetic,
        "assumptions": assumptions,
        "skipped_backends": skipped,
        "n_trials": len(trials),
        "wall_s": time.perf_counter() - t0,
    })
    write_run(out, res, traces, fields, meta)
    ok = res[res.status == "ok"]
    print(f"done in {meta['wall_s']:.1f} s: {len(ok)} scored rows, "
          f"{int((res.status == 'failed').sum())} failed, {int((res.status == 'unscored').sum())} unscored")
    for b, g in ok.groupby("backend"):
        print(f"  {b:10s} median |ln(k_sim/k_field)| = {g.log_ratio.abs().median():.3f} over {len(g)} trials")
    if not a.no_report:
        from canebench.reports.build import build_report

        page = build_report(out)
        print(f"report: {page}")
    print(f"results: {out / 'results.csv'}")
    return 0


def cmd_agree(a: argparse.Namespace) -> int:
    import pandas as pd

    from .agreement import REFERENCE, agreement_table, baseline_path, check, pairwise
    from .dataset import bundled_dataset, load_dataset
    from .protocol import get_protocol
    from .registry import discover, select
    from .run import provenance, run_trials, write_run

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        reg = discover()
    # by default every engine that simulates the chain; the continuum beam is
    # a different model (see `canebench converge`), not an engine to agree with
    names = ([n.strip() for n in a.backends.split(",")] if a.backends
             else sorted(n for n, i in reg.items() if "continuum" not in i.tags))
    if REFERENCE not in names:
        names.append(REFERENCE)
    usable, skipped = select(names)
    for n, why in skipped.items():
        print(f"skipping backend {n}: {why}", file=sys.stderr)
    proto = get_protocol(a.protocol)
    trials = load_dataset(Path(a.field) if a.field else bundled_dataset(), a.trials)
    out = Path(a.out) if a.out else Path("canebench-runs") / _dt.datetime.now().strftime("agree-%Y%m%d-%H%M%S")
    print(f"canebench agree: {len(trials)} trials x {len(usable)} backends ({','.join(usable)}), protocol {proto.name}")
    t0 = time.perf_counter()
    res, traces, fields = run_trials(trials, usable, proto, ModelConfig(), out, jobs=a.jobs, progress=_progress)
    meta = provenance(usable, proto, ModelConfig(), {"command": " ".join(sys.argv), "skipped_backends": skipped,
                                                      "synthetic": True, "wall_s": time.perf_counter() - t0})
    write_run(out, res, traces, fields, meta)
    table = agreement_table(res)
    table.to_csv(out / "agreement.csv", index=False)
    pairs = pairwise(res)
    pairs.to_csv(out / "pairwise.csv", index=False)
    print("\nstiffness relative to pinocchio (max |k/k_ref - 1| per backend):")
    for b, g in table.groupby("backend"):
        ok = g[g.status.isin(["ok", "unscored"])]
        print(f"  {b:10s} max {ok.rel_to_ref.abs().max():.2e}  median {ok.rel_to_ref.abs().median():.2e}  "
              f"failed {int((~g.status.isin(['ok', 'unscored'])).sum())}/{len(g)}  wall {g.wall_s.sum():.1f} s")
    print("\npairwise |ln(k_a/k_b)|:")
    print(pairs.to_string(index=False, float_format=lambda v: f"{v:.2e}"))
    bpath = Path(a.baseline) if a.baseline else baseline_path(proto.name)
    if a.update_baseline:
        bpath.parent.mkdir(parents=True, exist_ok=True)
        table[["trial", "backend", "protocol", "k_sim", "status", "reason"]].to_csv(bpath, index=False)
        print(f"baseline written: {bpath}")
        return 0
    baseline = pd.read_csv(bpath) if bpath.exists() else None
    if baseline is None:
        print(f"no baseline at {bpath}: checking against {REFERENCE} only")
    gate = check(table, baseline)
    gate.violations.to_csv(out / "violations.csv", index=False)
    from canebench.reports.build import build_report

    build_report(out)
    if gate.ok:
        print(f"\nagreement gate: PASS ({len(table)} trial x backend results)")
        return 0
    print(f"\nagreement gate: FAIL, {len(gate.violations)} violation(s):")
    print(gate.violations.to_string(index=False, float_format=lambda v: f"{v:.3e}"))
    return 1


def cmd_converge(a: argparse.Namespace) -> int:
    from canebench.reports.build import build_report
    from canebench.reports.convergence import chain_plot, rod_plot, summary

    from .dataset import bundled_dataset, load_dataset
    from .rodstudy import chain_convergence, rod_convergence, straight_cantilever

    out = Path(a.out) if a.out else Path("canebench-runs") / _dt.datetime.now().strftime("converge-%Y%m%d-%H%M%S")
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    rod = rod_convergence()
    rod.to_csv(out / "rod_convergence.csv", index=False)
    order = np.polyfit(np.log(rod.elements[:-2]), np.log(rod.rel_error[:-2]), 1)[0]
    print(f"beam: tip-deflection error vs RK4 elements, observed order {-order:.2f}")
    print(rod.to_string(index=False, float_format=lambda v: f"{v:.3e}"))
    cases = [("uniform-cantilever", straight_cantilever(False), "tip"), ("tapered-cantilever", straight_cantilever(True), "tip")]
    cases += [(t.id, t.cane, t.push_id) for t in load_dataset(bundled_dataset(), a.trials)]
    segs = tuple(int(s) for s in a.segments.split(","))
    df = chain_convergence(cases, segments=segs, progress=lambda i, n, tid: print(f"[{i:3d}/{n}] {tid}", flush=True))
    df.to_csv(out / "convergence.csv", index=False)
    chain_plot(df, out / "chain_convergence.png")
    rod_plot(rod, out / "rod_convergence.png")
    summ = summary(df)
    summ.to_csv(out / "convergence_summary.csv", index=False)
    print("\nchain stiffness / beam stiffness - 1 over the bundled canes (small deflection, gravity off):")
    print(summ.to_string(index=False, float_format=lambda v: f"{v:.4f}"))
    from canebench.reports.convergence import exceedances

    exc = exceedances(df)
    print("\ndual-length chains more than 1 % from the beam at 20 segments (torsion: the chain has no twist joint):")
    print(exc.to_string(index=False, float_format=lambda v: f"{v:.4f}") if len(exc) else "  none")
    for f in ("paper", "end_angle", "dual_length"):
        g = df[(df.trial == "uniform-cantilever") & (df.formula == f) & (df.discretization == "uniform")]
        last = g[g.segments == g.segments.max()].iloc[0]
        print(f"uniform cantilever, {f}, {int(last.segments)} segments: k_chain/k_beam = {last.ratio:.4f}")
    if (out / "results.csv").exists():
        page = build_report(out)
    else:
        from canebench.reports.build import _convergence_section

        page = out / "convergence.html"
        page.write_text("<!doctype html><html><head><meta charset='utf-8'><title>canebench convergence</title>"
                        "</head><body style='font-family:sans-serif;max-width:1200px;margin:auto'>"
                        f"{_convergence_section(out)}</body></html>")
    print(f"done in {time.perf_counter() - t0:.1f} s -> {page}")
    return 0


def cmd_report(a: argparse.Namespace) -> int:
    from canebench.reports.build import build_report

    print(build_report(Path(a.run_dir)))
    return 0


def cmd_backends(a: argparse.Namespace) -> int:
    from .protocol import PROTOCOLS
    from .registry import ENTRY_POINT_GROUP, discover

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        reg = discover()
    print(f"entry-point group: {ENTRY_POINT_GROUP}")
    for name, info in sorted(reg.items()):
        state = f"available, {info.kind}, version {info.version}" if info.available else f"UNAVAILABLE: {info.reason}"
        print(f"{name:12s} {state}  [{info.target}]  tags={','.join(info.tags)}")
        if info.available:
            b = info.cls()
            for p in PROTOCOLS.values():
                st = b.settings(p)
                if a.verbose:
                    print(f"    {p.name}: {st}")
                else:
                    print(f"    {p.name}: integrator={st.get('integrator')}; dt={st.get('dt')}; springs={st.get('springs')}")
    return 0


def cmd_generate(a: argparse.Namespace) -> int:
    from canebench.canes.generate import generate

    generate(Path(a.out) if a.out else None, seed=a.seed)
    return 0


def cmd_bench(a: argparse.Namespace) -> int:
    from .bench import bench_beam, bench_protocols

    if a.beam:
        bench_beam(trials=a.trials or "b1c1t1,b3c1t2,b5c3t1,b6c2t3")
        return 0
    bench_protocols(trials=a.trials or "b1c1t1,b1c2t1,b3c1t2", backends=a.backends.split(","), steps=a.steps)
    return 0


def build_parser() -> argparse.ArgumentParser:
    from .run import default_jobs

    p = argparse.ArgumentParser(prog="canebench", description=__doc__)
    sub = p.add_subparsers(dest="cmd", required=True)

    r = sub.add_parser("run", help="probe trials on backends and score them against field stiffness")
    r.add_argument("--field", help="dataset directory (push_points.csv + trials/); default: bundled synthetic set")
    r.add_argument("--backends", default=DEFAULT_BACKENDS, help="comma-separated backend names")
    r.add_argument("--protocol", default="fast", help="probe protocol: fast (default) or paper")
    r.add_argument("--out", help="run folder (default canebench-runs/run-<time>)")
    r.add_argument("--trials", help="comma-separated globs on trial or cane ids, e.g. 'b1c*,b2c3t1'")
    r.add_argument("--limit", type=int, help="only the first N selected trials")
    r.add_argument("--max-steps", type=int, help="cap on protocol steps per trial")
    r.add_argument("--set", action="append", metavar="KEY=VALUE", help="model configuration override (repeatable)")
    r.add_argument("--jobs", type=int, default=default_jobs(), help="worker processes")
    r.add_argument("--no-report", action="store_true")
    r.set_defaults(fn=cmd_run)

    rp = sub.add_parser("report", help="rebuild the report of a run folder from its CSVs")
    rp.add_argument("run_dir")
    rp.set_defaults(fn=cmd_report)

    ag = sub.add_parser("agree", help="probe bundled trials on every backend; agreement matrix and regression gate")
    ag.add_argument("--backends", help="comma-separated (default: every registered backend)")
    ag.add_argument("--protocol", default="fast")
    ag.add_argument("--trials", help="trial globs (default: all 54)")
    ag.add_argument("--field", help="dataset directory (default: bundled synthetic set)")
    ag.add_argument("--out", help="output folder")
    ag.add_argument("--baseline", help="baseline CSV (default: reports/baselines/agreement_<protocol>.csv)")
    ag.add_argument("--update-baseline", action="store_true", help="write the baseline instead of checking")
    ag.add_argument("--jobs", type=int, default=default_jobs())
    ag.set_defaults(fn=cmd_agree)

    cv = sub.add_parser("converge", help="beam convergence and chain/beam stiffness vs segments, per formula")
    cv.add_argument("--trials", help="trial globs on the bundled dataset (default: all)")
    cv.add_argument("--segments", default="3,4,5,6,8,10,12,15,20,25,30,40")
    cv.add_argument("--out", help="output folder (a run folder: its report then shows the study)")
    cv.set_defaults(fn=cmd_converge)

    b = sub.add_parser("backends", help="list registered backends, versions, availability")
    b.add_argument("-v", "--verbose", action="store_true", help="show each backend's full configuration per protocol")
    b.set_defaults(fn=cmd_backends)

    g = sub.add_parser("generate", help="regenerate the bundled synthetic dataset (seeded)")
    g.add_argument("--out", help="dataset directory (default: the package's canes/synthetic)")
    g.add_argument("--seed", type=int, default=20240515)
    g.set_defaults(fn=cmd_generate)

    be = sub.add_parser("bench", help="benchmark: paper vs fast protocol (stiffness difference, speed-up)")
    be.add_argument("--trials", help="trial globs on the bundled dataset")
    be.add_argument("--beam", action="store_true", help="time the beam backend's full 90-step sweep instead")
    be.add_argument("--backends", default="mujoco", help="comma-separated; MuJoCo is always included as the baseline")
    be.add_argument("--steps", type=int, default=None, help="protocol steps per trial (default: full trial)")
    be.set_defaults(fn=cmd_bench)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args.fn(args) or 0)
    except CanebenchError as exc:
        print(f"canebench: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
