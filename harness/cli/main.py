"""``canebench`` command line. One thin module per command: parse, call one function, print."""

from __future__ import annotations

import argparse
import sys

from ..errors import CanebenchError, InputWarning
from . import agree, backends, bench, converge, generate, report, run, study
from . import discover, export

COMMANDS = (run, report, agree, converge, study, backends, generate, bench, export, discover)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="canebench", description="Benchmark harness for deformable cane models.")
    sub = p.add_subparsers(dest="cmd", required=True)
    for mod in COMMANDS:
        mod.add_parser(sub)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args.fn(args) or 0)
    except CanebenchError as exc:
        print(f"canebench: error: {exc}", file=sys.stderr)
        return 2
    except InputWarning as exc:  # raised as an error under --strict
        print(f"canebench: error: {exc} (--strict)", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("canebench: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
