"""``canebench report``: rebuild a run folder's figures and HTML from its files (no re-simulation)."""

from __future__ import annotations

import argparse
from pathlib import Path


def add_parser(sub: argparse._SubParsersAction) -> None:
    rp = sub.add_parser("report", help="rebuild the report of a run folder from its CSVs")
    rp.add_argument("run_dir")
    rp.set_defaults(fn=main)


def main(a: argparse.Namespace) -> int:
    from canebench.reports.build import build_report, read_meta

    from ..errors import InputError

    if not Path(a.run_dir).is_dir():
        raise InputError(a.run_dir, "run_dir", "not a folder")
    page = build_report(Path(a.run_dir))
    meta = read_meta(Path(a.run_dir))
    if meta.get("state") not in (None, "complete"):
        print(f"incomplete run ({meta['state']}): {meta.get('jobs_done', '?')} of {meta.get('jobs_total', '?')} jobs "
              f"have results, {meta.get('jobs_missing', '?')} missing. {meta.get('resume', '')}")
    print(page)
    return 0
