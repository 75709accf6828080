"""``canebench generate``: regenerate the bundled synthetic dataset (seeded)."""

from __future__ import annotations

import argparse
from pathlib import Path


def add_parser(sub: argparse._SubParsersAction) -> None:
    g = sub.add_parser("generate", help="regenerate the bundled synthetic dataset (seeded)")
    g.add_argument("--out", help="dataset directory (default: the package's canes/synthetic)")
    g.add_argument("--seed", type=int, default=20240515)
    g.set_defaults(fn=main)


def main(a: argparse.Namespace) -> int:
    from canebench.canes.generate import generate

    generate(Path(a.out) if a.out else None, seed=a.seed)
    return 0
