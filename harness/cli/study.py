"""``canebench study NAME``: one of the paper's analyses, as a command (each is also a Python function)."""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from . import common

SIM_STUDIES = ("naive", "morris", "sweep")


def add_parser(sub: argparse._SubParsersAction) -> None:
    st = sub.add_parser("study", help="run one of the paper's studies into a run folder")
    st.add_argument("name", choices=["contact", "modulus", *SIM_STUDIES],
                    help="contact: IMU contact detection (the paper's rule) and a force-only detector; "
                         "modulus: three-point bending -> flexural modulus, t-tests, distributions; naive: the "
                         "paper's naive case on every engine; morris: Method of Morris (4 factors, 6 levels, 4 "
                         "trajectories); sweep: modulus x diameter factor, 5 x 5")
    st.add_argument("--data", help="modulus: three-point bending dataset (default: the bundled SYNTHETIC set)")
    common.add_data_options(st)
    st.add_argument("--backends", help="engines for naive/morris/sweep (default pinocchio)")
    st.add_argument("--protocol", help="probe protocol for naive/morris/sweep (default fast)")
    st.add_argument("--truncate-contacts", action="store_true",
                    help="naive/morris/sweep: score a trial with a detected contact only up to the contact (the "
                         "paper's partial trials; IMU rule where logged, else the force-only detector); naive "
                         "then reports the error with and without the rule")
    st.add_argument("--out", help="run folder (default canebench-runs/study-<name>-<time>); an existing one resumes")
    st.add_argument("--no-report", action="store_true")
    common.add_executor_options(st)
    st.set_defaults(fn=main)


def main(a: argparse.Namespace) -> int:
    from ..studies import STUDIES

    simulates = a.name in SIM_STUDIES
    if simulates:  # a mistyped engine stops before the run folder is made
        usable, skipped = common.backends(a.backends or "pinocchio")
    ignored = ignored_options(a)
    if ignored:
        why = {"contact": "it reads --field and simulates nothing", "modulus": "it reads --data and simulates nothing"
               }.get(a.name, "it reads no bending dataset")
        print(f"note: study {a.name} leaves {', '.join(ignored)} aside ({why})", file=sys.stderr)
    out = common.out_dir(a.out, f"study-{a.name}")
    t0 = time.perf_counter()
    code = 0
    if a.name == "contact":
        from canebench import canes

        data = Path(a.field) if a.field else Path(canes.__file__).resolve().parent / "synthetic-contact"
        res = STUDIES["contact"](data, out)
        meta = res.meta
        print(f"canebench study contact: {data} -> {out} (in process: no simulation)")
        print(json.dumps({k: meta[k] for k in meta if k in ("counts", "paper", "force_events", "force_event_trials",
                                                            "force_partial", "force_partial_by_cause")},
                         indent=1, default=str))
        part = res.trials[res.trials.status != "full"]
        if len(part):
            print("partial / excluded trials:")
            print(part[["trial", "method", "status", "cause", "contact_mm", "kept_samples", "n_rig", "k_field_full",
                        "k_field_partial"]].to_string(index=False, float_format=lambda v: f"{v:.3g}"))
        if res.sensitivity is not None:
            print("force-only counts by detector setting:")
            print(res.sensitivity.to_string(index=False, float_format=lambda v: f"{v:.3g}"))
        if (out / "contact_scores.json").exists():
            print("against the dataset's truth:", (out / "contact_scores.json").read_text())
    elif a.name == "modulus":
        from ..data.bending import bundled_bending_dataset

        data = Path(a.data) if a.data else bundled_bending_dataset()
        res = STUDIES["modulus"](data, out)
        print(f"canebench study modulus: {len(res.samples)} samples from {data}"
              f"{' (SYNTHETIC data)' if res.meta.get('synthetic') else ''} -> {out}")
        cols = [c for c in ("family", "group", "n", "mean_gpa", "sd_gpa", "min_gpa", "max_gpa") if c in res.groups]
        print(res.groups[cols].to_string(index=False, float_format=lambda v: f"{v:.3f}"))
        print("\nWelch t-tests:")
        print(res.ttests.to_string(index=False, float_format=lambda v: f"{v:.3g}"))
    else:
        from ..execute.provenance import provenance
        from ..probe.protocol import get_protocol

        data_dir, trials = common.trials(a)
        proto = get_protocol(a.protocol or "fast")
        ex = common.executor(a)
        meta = provenance(usable, proto, None, {"command": " ".join(sys.argv), "dataset": str(data_dir.resolve()),
                                                "skipped_backends": skipped,
                                                "assumptions": common.assumptions(trials, None)})
        print(f"canebench study {a.name}: {len(trials)} trials from {data_dir}, backends {','.join(usable)} -> {out}")
        common.sigterm_as_interrupt()
        res = STUDIES[a.name](trials, usable, out, ex, proto, common.progress(a), meta,
                              timeout_s=a.timeout or None, fresh=a.fresh, truncate_contacts=a.truncate_contacts)
        print(f"done in {time.perf_counter() - t0:.1f} s: {res.outcome.summary()}")
        _print(a.name, res)
        if res.outcome.interrupted:
            common.say_interrupted(res.outcome, out)
        code = res.outcome.exit_code
    if not a.no_report:
        from canebench.reports.build import build_report

        print(f"report: {build_report(out)}")
    return code


# options a study does not read; saying so beats a silent default (study contact once ran with a given
# --backends unnoticed)
_UNREAD = {"contact": ("--data", "--trials", "--strict", "--backends", "--protocol", "--truncate-contacts",
                       "--executor", "--jobs", "--scheduler", "--timeout", "--fresh"),
           "modulus": ("--field", "--trials", "--strict", "--backends", "--protocol", "--truncate-contacts",
                       "--executor", "--jobs", "--scheduler", "--timeout", "--fresh"),
           **{name: ("--data",) for name in SIM_STUDIES}}


def ignored_options(a: argparse.Namespace) -> list[str]:
    """The options given on the command line that study ``a.name`` does not read, in ``_UNREAD``'s order."""
    defaults = {**{f"--{k}": v for k, v in common.EXECUTOR_DEFAULTS.items()}, "--jobs": common.default_jobs()}
    out = []
    for opt in _UNREAD[a.name]:
        v = getattr(a, opt[2:].replace("-", "_"))
        if v is not None and v is not False and v != defaults.get(opt):
            out.append(opt)
    return out


def _print(name: str, res) -> None:  # noqa: ANN001
    f = lambda v: f"{v:.3g}"  # noqa: E731
    if name == "naive":
        ok = res.table[res.table.status == "ok"]
        for b, g in ok.groupby("backend"):
            print(f"  {b:10s} median |ln(k_sim/k_field)| {g.log_ratio.abs().median():.3f}, range "
                  f"{g.log_ratio.min():.2f}..{g.log_ratio.max():.2f} over {len(g)} trials")
        print(res.variance.to_string(index=False, float_format=f))
        print(res.by_rank.to_string(index=False, float_format=f))
        if res.truncation is not None:
            print("truncation rule (partial trials scored up to the contact), naive-case error with and without:")
            print(res.truncation.to_string(index=False, float_format=f))
    elif name == "morris":
        print(res.ranking.to_string(index=False, float_format=f))
        if res.engines is not None and len(res.engines):
            from ..studies.paper import morris_engine_sentence

            print(res.engines.drop(columns=["overall_order"]).to_string(index=False, float_format=f))
            print(morris_engine_sentence(res.engines))
    elif name == "sweep":
        for b, v in res.summary.items():
            print(f"  {b}: {v}")
