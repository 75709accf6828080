"""Shared fixtures. Field data is read from ../shared/field-data (or
$CANEBENCH_FIELD_DATA); tests that need it skip with a message when absent."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent


def field_data_dir() -> Path | None:
    env = os.environ.get("CANEBENCH_FIELD_DATA")
    cand = Path(env) if env else REPO.parent / "shared" / "field-data"
    return cand if (cand / "push_points.csv").exists() else None


@pytest.fixture
def field_dir() -> Path:
    d = field_data_dir()
    if d is None:
        pytest.skip("field data not found: put it at ../shared/field-data or set CANEBENCH_FIELD_DATA")
    return d


@pytest.fixture(scope="session")
def bundled_trials():
    from canebench.data.dataset import bundled_dataset, load_dataset

    return load_dataset(bundled_dataset())
