"""What produced a result: versions, engines, protocol, configuration, commit."""

from __future__ import annotations

import datetime as _dt
import platform
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from .. import __version__
from ..model.config import ModelConfig
from ..probe.protocol import Protocol
from ..registry import discover, get_backend


def git_commit() -> str | None:
    try:
        return subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True,
                              cwd=Path(__file__).parent, timeout=5).stdout.strip() or None
    except Exception:
        return None


def git_dirty(where: str | Path | None = None) -> bool | None:
    """Whether the tracked files of canebench's checkout (or of the one holding ``where``) differ from
    the commit :func:`git_commit` names: a result made by uncommitted code. None outside a checkout."""
    try:
        r = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], capture_output=True, text=True,
                           cwd=Path(where) if where is not None else Path(__file__).parent, timeout=10)
        return bool(r.stdout.strip()) if r.returncode == 0 else None
    except Exception:
        return None


def provenance(backends: list[str], proto: Protocol, config: ModelConfig | None,
               extra: dict[str, Any] | None = None) -> dict[str, Any]:
    """The provenance block of ``run.json`` (and of every study's metadata)."""
    reg = discover()
    return {
        "canebench": __version__,
        "git_commit": git_commit(),
        "git_dirty": git_dirty(),
        "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "python": sys.version.split()[0],
        "platform": platform.platform(),
        "numpy": np.__version__,
        "pandas": pd.__version__,
        "engines": {b: reg[b].version for b in backends if b in reg},
        "backend_settings": {b: get_backend(b).settings(proto) for b in backends},
        "protocol": proto.to_dict(),
        "model_config": config.to_dict() if config is not None else None,
        "seed": None,  # the probe is deterministic; dataset seeds live in their provenance
        **(extra or {}),
    }
