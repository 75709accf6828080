"""``canebench study NAME``: one of the paper's analyses, as a command (and a function)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def add_parser(sub: argparse._SubParsersAction) -> None:
    st = sub.add_parser("study", help="run one of the paper's studies into a run folder (see 'canebench study -h')")
    st.add_argument("name", choices=["modulus"],
                    help="modulus: three-point bending -> flexural modulus by season, variety and age, "
                         "Welch t-tests, the paper's two figures, named modulus distributions")
    st.add_argument("--data", help="three-point bending dataset (samples.csv + tests/); default: the bundled "
                                   "SYNTHETIC sample set")
    st.add_argument("--out", help="run folder (default canebench-runs/study-<name>-<time>)")
    st.add_argument("--no-report", action="store_true")
    st.set_defaults(fn=main)


def main(a: argparse.Namespace) -> int:
    from ..studies import STUDIES
    from . import common

    out = common.out_dir(a.out, f"study-{a.name}")
    if a.name == "modulus":
        from ..data.bending import bundled_bending_dataset

        data = Path(a.data) if a.data else bundled_bending_dataset()
        res = STUDIES["modulus"](data, out)
        meta = res.meta
        print(f"canebench study modulus: {len(res.samples)} samples from {data}"
              f"{' (SYNTHETIC data)' if meta.get('synthetic') else ''} -> {out}")
        cols = [c for c in ("family", "group", "n", "mean_gpa", "sd_gpa", "min_gpa", "max_gpa") if c in res.groups]
        print(res.groups[cols].to_string(index=False, float_format=lambda v: f"{v:.3f}"))
        print("\nWelch t-tests:")
        print(res.ttests.to_string(index=False, float_format=lambda v: f"{v:.3g}"))
    if not a.no_report:
        from canebench.reports.build import build_report

        print(f"report: {build_report(out)}", file=sys.stdout)
    return 0
