"""Three-point bending samples (flexural modulus testing): format, reading, validation.

A data folder holds one sample table and one force-displacement CSV per test::

    samples.csv
    tests/<sample_id>_test<k>.csv      (k = 1, 2, 3, ...)

``samples.csv`` has one row per sample, in these columns (any order; extra
columns are kept and ignored):

=============== ==============================================================
``sample_id``   unique, non-empty; letters, digits, ``-``, ``_``, ``.``
``season``      e.g. ``dormant``, ``fruiting`` (stored lower-case)
``variety``     e.g. ``Duke`` (kept as written)
``age``         free label, e.g. ``new``, ``1-year``, ``2-year+``
``span_mm``     support distance L (mm), > 0 (paper's default 203.2 = 8 in)
``caliper_1_mm`` .. ``caliper_6_mm``
                six diameters (mm), > 0: min and max at support A (1, 2), at
                the loading point (3, 4) and at support B (5, 6); the radius
                is half their mean (as in the paper)
``notes``       optional free text (the bundled set says ``SYNTHETIC`` here)
=============== ==============================================================

Each test CSV has the columns ``displacement_mm`` (crosshead travel from
first contact, non-decreasing) and ``force_n`` (N, positive in compression),
one row per reading. Every sample needs at least one test (the paper ran
three) and every test file must name a sample of ``samples.csv``.

In every CSV, lines starting with ``#`` are comments; error messages give
line numbers of the file as written (header = line 1 when no comments).
Errors (:class:`canebench.errors.InputError`) name the file, the column and
the line: missing columns, empty or non-finite values, non-positive spans
or diameters, duplicate ids, decreasing displacement, orphan or missing
tests. Plausible-but-odd values (a span under 20 mm, diameters outside
0.5-50 mm: metres or inches?) are :func:`canebench.errors.warn_input`
warnings.
"""

from __future__ import annotations

import io
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import InputError, cell_text, warn_input

CALIPERS = tuple(f"caliper_{i}_mm" for i in range(1, 7))
SAMPLE_COLUMNS = ("sample_id", "season", "variety", "age", "span_mm") + CALIPERS
TEST_COLUMNS = ("displacement_mm", "force_n")
TEST_NAME = re.compile(r"^(?P<sample>.+)_test(?P<k>\d+)\.csv$")
SAMPLE_ID = re.compile(r"^[A-Za-z0-9._-]+$")


@dataclass
class BendingTest:
    """One force-displacement curve (SI units)."""

    sample_id: str
    test: int
    path: str
    displacement_m: np.ndarray
    force_n: np.ndarray


@dataclass
class BendingSample:
    """One cane sample: metadata, geometry (SI) and its tests."""

    sample_id: str
    season: str
    variety: str
    age: str
    span_m: float
    calipers_m: np.ndarray
    notes: str = ""
    source: str = ""
    tests: list[BendingTest] = field(default_factory=list)

    @property
    def radius_m(self) -> float:
        """Half the mean of the six caliper diameters (m)."""
        return float(np.mean(self.calipers_m)) / 2.0


def bundled_bending_dataset() -> Path:
    """Path of the bundled SYNTHETIC three-point-bending set (installed package data)."""
    from canebench import canes

    return Path(canes.__file__).resolve().parent / "modulus-synthetic"


def _read_csv(path: Path) -> tuple[pd.DataFrame, np.ndarray]:
    """A CSV without its ``#`` comment lines, and the file line number of each data row."""
    src = str(path)
    try:
        lines = path.read_text().splitlines()
    except FileNotFoundError:
        raise InputError(src, "<file>", "file not found") from None
    except UnicodeDecodeError:
        raise InputError(src, "<file>", "not a text file") from None
    keep = [i for i, ln in enumerate(lines) if ln.strip() and not ln.lstrip().startswith("#")]
    if not keep:
        raise InputError(src, "<file>", "no header line")
    try:
        df = pd.read_csv(io.StringIO("\n".join(lines[i] for i in keep)), dtype=str, keep_default_na=False)
    except (pd.errors.ParserError, pd.errors.EmptyDataError) as exc:
        raise InputError(src, "<file>", f"malformed CSV: {exc}") from None
    df.columns = [str(c).strip() for c in df.columns]
    return df, np.asarray(keep[1:], int) + 1


def _require(df: pd.DataFrame, cols: tuple[str, ...], src: str) -> None:
    for c in cols:
        if c not in df.columns:
            raise InputError(src, c, f"missing column; found {list(df.columns)}")


def _numbers(df: pd.DataFrame, col: str, line: np.ndarray, src: str, positive: bool = False) -> np.ndarray:
    vals = pd.to_numeric(df[col].str.strip(), errors="coerce").to_numpy(float)
    bad = ~np.isfinite(vals)
    if bad.any():
        i = int(np.argmax(bad))
        raise InputError(src, col, f"line {line[i]}: not a finite number ({cell_text(df[col].iloc[i])})")
    if positive and (vals <= 0).any():
        i = int(np.argmax(vals <= 0))
        raise InputError(src, col, f"line {line[i]}: must be > 0 (got {vals[i]:g})")
    return vals


def read_test_csv(path: str | Path, sample_id: str = "", test: int = 0) -> BendingTest:
    """Read and validate one test's force-displacement CSV (mm, N) into SI."""
    path = Path(path)
    src = str(path)
    df, line = _read_csv(path)
    _require(df, TEST_COLUMNS, src)
    if len(df) < 3:
        raise InputError(src, "<rows>", f"{len(df)} readings; need at least 3")
    disp = _numbers(df, "displacement_mm", line, src)
    force = _numbers(df, "force_n", line, src)
    dec = np.diff(disp) < 0
    if dec.any():
        i = int(np.argmax(dec)) + 1
        raise InputError(src, "displacement_mm", f"line {line[i]}: displacement decreases "
                                                 f"({disp[i - 1]:g} -> {disp[i]:g})")
    if disp[-1] - disp[0] <= 0:
        raise InputError(src, "displacement_mm", "displacement never increases")
    if disp[-1] > 200:
        warn_input(src, "displacement_mm", f"travel {disp[-1]:g} mm: micrometres, not mm?")
    return BendingTest(sample_id, test, src, disp * 1e-3, force)


def read_samples_csv(path: str | Path) -> list[BendingSample]:
    """Read and validate ``samples.csv`` (without tests)."""
    path = Path(path)
    src = str(path)
    df, line = _read_csv(path)
    _require(df, SAMPLE_COLUMNS, src)
    if df.empty:
        raise InputError(src, "<rows>", "no samples")
    for col in ("sample_id", "season", "variety", "age"):
        vals = df[col].str.strip()
        if (vals == "").any():
            i = int(np.argmax((vals == "").to_numpy()))
            raise InputError(src, col, f"line {line[i]}: empty")
        df[col] = vals
    for i, sid in enumerate(df["sample_id"]):
        if not SAMPLE_ID.match(sid):
            raise InputError(src, "sample_id", f"line {line[i]}: {sid!r} may only hold letters, digits, '-', '_', '.'")
    dup = df["sample_id"].duplicated()
    if dup.any():
        i = int(np.argmax(dup.to_numpy()))
        raise InputError(src, "sample_id", f"line {line[i]}: {df['sample_id'].iloc[i]!r} also used above")
    span = _numbers(df, "span_mm", line, src, positive=True)
    cal = np.column_stack([_numbers(df, c, line, src, positive=True) for c in CALIPERS])
    out = []
    for i, r in enumerate(df.itertuples(index=False)):
        if span[i] < 20:
            warn_input(src, "span_mm", f"line {line[i]}: span {span[i]:g} mm is implausibly short: metres?")
        if cal[i].min() < 0.5 or cal[i].max() > 50:
            warn_input(src, "caliper_*_mm", f"line {line[i]}: diameters {cal[i].min():g}-{cal[i].max():g} mm "
                                            "outside 0.5-50 mm: metres or inches?")
        if cal[i].max() >= span[i]:
            raise InputError(src, "span_mm", f"line {line[i]}: span {span[i]:g} mm not longer than the "
                                             f"sample's diameter {cal[i].max():g} mm")
        out.append(BendingSample(r.sample_id, r.season.lower(), r.variety, r.age, span[i] * 1e-3, cal[i] * 1e-3,
                                 str(getattr(r, "notes", "") or ""), f"{src}:{line[i]}"))
    return out


def read_bending_dataset(data_dir: str | Path) -> list[BendingSample]:
    """Every sample of a three-point-bending folder with its tests, validated.

    Parameters
    ----------
    data_dir : str or Path
        Folder with ``samples.csv`` and ``tests/<sample_id>_test<k>.csv``.

    Returns
    -------
    list of BendingSample
        In ``samples.csv`` order, tests sorted by number.
    """
    data_dir = Path(data_dir)
    samples = read_samples_csv(data_dir / "samples.csv")
    by_id = {s.sample_id: s for s in samples}
    tdir = data_dir / "tests"
    if not tdir.is_dir():
        raise InputError(str(tdir), "<folder>", "missing: one CSV per test, tests/<sample_id>_test<k>.csv")
    for p in sorted(tdir.glob("*.csv")):
        m = TEST_NAME.match(p.name)
        if not m:
            raise InputError(str(p), "<file name>", "expected <sample_id>_test<k>.csv")
        if m["sample"] not in by_id:
            raise InputError(str(p), "<file name>", f"sample {m['sample']!r} is not in samples.csv")
        by_id[m["sample"]].tests.append(read_test_csv(p, m["sample"], int(m["k"])))
    for s in samples:
        if not s.tests:
            raise InputError(s.source, "sample_id", f"sample {s.sample_id!r} has no test file "
                                                    f"({tdir}/{s.sample_id}_test1.csv, ...)")
        s.tests.sort(key=lambda t: t.test)
    return samples
