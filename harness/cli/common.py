"""Options and steps shared by the commands (parse, load, select)."""

from __future__ import annotations

import argparse
import datetime as _dt
import os
import signal
import sys
from pathlib import Path
from typing import Any

from ..errors import InputError


def default_jobs() -> int:
    return max(1, os.cpu_count() or 1)


#: the execution options' defaults but ``--jobs`` (every core: :func:`default_jobs`), for the parser and
#: for a command that says which options it leaves aside (``study``)
EXECUTOR_DEFAULTS = {"executor": "local", "scheduler": None, "timeout": 600.0}


def add_executor_options(p: argparse.ArgumentParser, store: bool = True) -> None:
    """The execution options; ``store=False`` for a command that keeps no run store of its own
    (``discover``: no per-job time limit, nothing to start afresh, its own progress lines)."""
    g = p.add_argument_group("execution")
    g.add_argument("--executor", default=EXECUTOR_DEFAULTS["executor"],
                   help="local (process pool, default), dask, or serial")
    g.add_argument("--jobs", type=int, default=default_jobs(),
                   help="worker processes (local) or LocalCluster workers (dask); default: every core")
    g.add_argument("--scheduler", default=EXECUTOR_DEFAULTS["scheduler"],
                   help="dask scheduler address (tcp://HOST:PORT); default: start a LocalCluster")
    if not store:
        return
    g.add_argument("--timeout", type=float, default=EXECUTOR_DEFAULTS["timeout"],
                   help=f"per-job time limit in seconds (default {EXECUTOR_DEFAULTS['timeout']:g}; 0: none)")
    g.add_argument("--fresh", action="store_true", help="ignore the run folder's store and start over")
    g.add_argument("--quiet", action="store_true", help="no progress output")


def names(spec: str | None) -> list[str]:
    """The names of a comma-separated option (``--backends a, b,``: ``['a', 'b']``); none for ``None``."""
    return [n.strip() for n in (spec or "").split(",") if n.strip()]


def add_model_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("model")
    g.add_argument("--preset", default="default", help="named model configuration (canebench presets)")
    g.add_argument("--set", action="append", metavar="KEY=VALUE", help="model configuration override (repeatable)")
    g.add_argument("--model", metavar="FILE", help="model file (e.g. the discovery workflow's model.yaml): a preset "
                                                  "plus fitted effects; replaces --preset, --set applies on top")


def add_data_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--field", help="dataset directory (push_points.csv + trials/); default: bundled synthetic set")
    p.add_argument("--trials", help="comma-separated globs on trial or cane ids, e.g. 'b1c*,b2c3t1'")
    p.add_argument("--strict", action="store_true",
                   help="treat input warnings (implausible units, folded or tip-first polylines) as errors")


def input_warnings(strict: bool) -> None:
    """Show each input warning once as one plain line; under ``--strict`` make it an error."""
    import warnings

    from ..errors import InputWarning

    shown: set[str] = set()

    def show(message, category, filename, lineno, file=None, line=None):  # noqa: ANN001
        if issubclass(category, InputWarning):
            # a file is read by several stages (discover reads a rig CSV a dozen times): said once.
            # Not the "default" filter: it keeps one warning per code line, so one per kind, not per file
            if str(message) not in shown:
                shown.add(str(message))
                print(f"canebench: warning: {message}", file=sys.stderr)
        else:
            print(warnings.formatwarning(message, category, filename, lineno, line), file=sys.stderr, end="")

    warnings.showwarning = show
    warnings.simplefilter("error" if strict else "always", InputWarning)


def out_dir(value: str | None, prefix: str) -> Path:
    out = Path(value) if value else Path("canebench-runs") / _dt.datetime.now().strftime(f"{prefix}-%Y%m%d-%H%M%S")
    if out.exists() and not out.is_dir():
        raise InputError(str(out), "--out", "exists and is not a folder")
    try:
        out.mkdir(parents=True, exist_ok=True)
        probe = out / ".canebench-write-test"
        probe.write_text("")
        probe.unlink()
    except OSError as exc:
        raise InputError(str(out), "--out", f"cannot write there: {exc.strerror or exc}") from None
    return out


def model_config(a: argparse.Namespace) -> Any:
    from ..model.config import parse_assignments
    from ..model.presets import PRESETS
    from ..registry import UnknownName

    if getattr(a, "model", None):
        from ..model.modelfile import load_model_file

        base = load_model_file(a.model)
    else:
        try:
            base = PRESETS[a.preset]
        except UnknownName as exc:
            raise InputError("--preset", "preset", str(exc)) from None
    return base.with_overrides(parse_assignments(a.set))


def executor(a: argparse.Namespace) -> Any:
    from ..execute.executors import EXECUTORS, make_executor

    if a.executor not in EXECUTORS:
        raise InputError("--executor", "executor", f"unknown executor {a.executor!r}; known: {', '.join(EXECUTORS)}")
    if a.jobs < 1:
        raise InputError("--jobs", "jobs", "must be >= 1")
    return make_executor(a.executor, a.jobs, a.scheduler)


def trials(a: argparse.Namespace) -> tuple[Path, list]:
    from ..data.dataset import bundled_dataset, load_dataset
    from ..errors import InputWarning

    input_warnings(getattr(a, "strict", False))
    data_dir = Path(a.field) if a.field else bundled_dataset()
    try:
        return data_dir, load_dataset(data_dir, a.trials)
    except InputWarning as w:  # --strict
        raise InputError(w.source, w.field, f"{w.message} (an error under --strict)") from None


def assumptions(trials: list, config: Any) -> list[str]:
    """The assumptions a run rests on, as they are true for this configuration (all trials, sorted)."""
    from ..execute.pipeline import assumptions_for

    return sorted({s for t in trials for s in assumptions_for(t, config)})


def backends(spec: str) -> tuple[list[str], dict[str, str]]:
    from ..registry import select

    usable, skipped = select(names(spec))
    for n, why in skipped.items():
        print(f"skipping backend {n}: {why}", file=sys.stderr)
    return usable, skipped


def progress(a: argparse.Namespace) -> Any:
    from ..execute.progress import make_progress

    return make_progress(quiet=getattr(a, "quiet", False))


def sigterm_as_interrupt() -> None:
    """SIGTERM (a scheduler's or a user's kill) stops a run like Ctrl-C: outputs written, resumable."""

    def handler(signum: int, frame: object) -> None:
        raise KeyboardInterrupt

    try:
        signal.signal(signal.SIGTERM, handler)
    except ValueError:  # not the main thread (embedded use)
        pass


def say_interrupted(outcome: Any, out: Path) -> None:
    print(f"interrupted: {outcome.n_jobs - len(outcome.missing)} of {outcome.n_jobs} jobs done, "
          f"{len(outcome.missing)} not run; outputs written from what is done. "
          f"Resume: run the same command again with --out {out}", file=sys.stderr)
