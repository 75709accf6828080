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
    from ..execute.provenance import provenance
    from ..model.config import ModelConfig
    from ..probe.protocol import get_protocol
    from ..registry import discover
    from ..studies.agreement import REFERENCE, run_agreement

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
    out = common.out_dir(a.out, "agree")
    _, trials = common.trials(a)
    ex = common.executor(a)
    print(f"canebench agree: {len(trials)} trials x {len(usable)} backends ({','.join(usable)}), protocol {proto.name}")
    t0 = time.perf_counter()
    meta = provenance(usable, proto, ModelConfig(), {"command": " ".join(sys.argv), "skipped_backends": skipped,
                                                      "synthetic": True})
    common.sigterm_as_interrupt()
    r = run_agreement(trials, usable, proto, out, ex, a.baseline, a.update_baseline, timeout_s=a.timeout or None,
                      fresh=a.fresh, progress=common.progress(a), meta=meta, label="agree")
    print(f"done in {time.perf_counter() - t0:.1f} s: {r.outcome.summary()}")
    if r.outcome.interrupted:
        common.say_interrupted(r.outcome, out)
        return r.outcome.exit_code
    print("\nstiffness relative to each backend's reference (pinocchio for chains, beam for continuum "
          "engines; max |k/k_ref - 1| per backend):")
    for b, g in r.table.groupby("backend"):
        ok = g[g.status.isin(["ok", "unscored"])]
        ref = g.reference.iloc[0] if "reference" in g and len(g) else "pinocchio"
        print(f"  {b:12s} vs {ref:10s} max {ok.rel_to_ref.abs().max():.2e}  median {ok.rel_to_ref.abs().median():.2e}  "
              f"failed {int((~g.status.isin(['ok', 'unscored'])).sum())}/{len(g)}  wall {g.wall_s.sum():.1f} s")
    print("\npairwise |ln(k_a/k_b)|:")
    print(r.pairs.to_string(index=False, float_format=lambda v: f"{v:.2e}"))
    if a.update_baseline:
        print(f"baseline written: {r.baseline_path}")
        return 0
    if not r.baseline_found:
        print(f"no baseline at {r.baseline_path}: checking against {REFERENCE} only")
    from canebench.reports.build import build_report

    build_report(out)
    if r.passed:
        print(f"\nagreement gate: PASS ({len(r.table)} trial x backend results)")
        return 0
    print(f"\nagreement gate: FAIL, {len(r.gate.violations)} violation(s):")
    print(r.gate.violations.to_string(index=False, float_format=lambda v: f"{v:.3e}"))
    return 1
