"""``canebench agree``: every bundled trial on every engine; agreement matrix and regression gate."""

from __future__ import annotations

import argparse
import sys
import time
import warnings

from . import common


def add_parser(sub: argparse._SubParsersAction) -> None:
    ag = sub.add_parser("agree", help="probe bundled trials on every backend; agreement matrix and regression gate")
    ag.add_argument("--backends", help="comma-separated (default: every registered chain backend)")
    ag.add_argument("--protocol", default="fast")
    common.add_data_options(ag)
    ag.add_argument("--out", help="output folder (an existing one resumes)")
    ag.add_argument("--baseline", help="baseline CSV (default: reports/baselines/agreement_<protocol>.csv)")
    ag.add_argument("--update-baseline", action="store_true", help="write the baseline instead of checking")
    common.add_executor_options(ag)
    ag.set_defaults(fn=main)


def main(a: argparse.Namespace) -> int:
    from pathlib import Path

    import pandas as pd

    from ..execute.pipeline import field_stage, make_jobs
    from ..execute.provenance import provenance
    from ..execute.runner import run_jobs
    from ..model.config import ModelConfig
    from ..probe.protocol import get_protocol
    from ..registry import discover
    from ..studies.agreement import REFERENCE, agreement_table, baseline_path, check, pairwise

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        reg = discover()
    # by default every engine that simulates the chain; the continuum beam is
    # a different model (see `canebench converge`), not an engine to agree with
    names = a.backends or ",".join(sorted(n for n, i in reg.items() if "continuum" not in i.tags))
    if REFERENCE not in names.split(","):
        names += f",{REFERENCE}"
    usable, skipped = common.backends(names)
    proto = get_protocol(a.protocol)
    _, trials = common.trials(a)
    out = common.out_dir(a.out, "agree")
    ex = common.executor(a)
    print(f"canebench agree: {len(trials)} trials x {len(usable)} backends ({','.join(usable)}), protocol {proto.name}")
    t0 = time.perf_counter()
    fields = field_stage(trials)
    jobs = make_jobs(trials, usable, proto, ModelConfig(), fields)
    meta = provenance(usable, proto, ModelConfig(), {"command": " ".join(sys.argv), "skipped_backends": skipped,
                                                      "synthetic": True})
    common.sigterm_as_interrupt()
    outcome = run_jobs(jobs, out, ex, fields=fields, timeout_s=a.timeout or None, fresh=a.fresh,
                       progress=common.progress(a), meta=meta, label="agree")
    print(f"done in {time.perf_counter() - t0:.1f} s: {outcome.summary()}")
    if outcome.interrupted:
        common.say_interrupted(outcome, out)
        return outcome.exit_code
    res = outcome.results
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
