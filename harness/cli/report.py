"""``canebench report``: rebuild a run folder's figures and HTML from its files (no re-simulation)."""

from __future__ import annotations

import argparse
from pathlib import Path


def add_parser(sub: argparse._SubParsersAction) -> None:
    rp = sub.add_parser("report", help="rebuild the report of a run folder from its CSVs")
    rp.add_argument("run_dir")
    rp.set_defaults(fn=main)


def main(a: argparse.Namespace) -> int:
    from canebench.reports.build import build_report

    from ..errors import InputError

    if not Path(a.run_dir).is_dir():
        raise InputError(a.run_dir, "run_dir", "not a folder")
    print(build_report(Path(a.run_dir)))
    return 0
