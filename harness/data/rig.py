"""The field rig's CSV format: reading and validation.

Rig CSV columns (see ../shared/field-data/README.md): ``Iteration``,
``Time Stamp`` (16-bit ms counter that wraps), ``Load Cell Reading (gf)``
(compressive positive, with a tare offset), ``Displacement (mm)`` (absolute
probe position, 0.5 mm per sample), ``Height (mm)``.

Every column must be present and numeric; a NaN or a displacement that
goes back is an error naming the file, row and column. A sample that
repeats the previous position (logged twice while the stepper did not step)
is merged with it, their readings averaged, with a warning. Time stamps are
unwrapped (add 65536 at each negative jump) only to report the trial's
duration; physics uses displacement, which the stepper sets exactly.
Displacement is made relative to the first sample: the rig logs an absolute
carriage position whose origin means nothing for the cane.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import InputError, cell_text, warn_input

COLUMNS = {
    "iteration": "Iteration",
    "time": "Time Stamp",
    "force": "Load Cell Reading (gf)",
    "disp": "Displacement (mm)",
    "height": "Height (mm)",
}


@dataclass
class RigTrial:
    path: str
    displacement_mm: np.ndarray  # relative to first sample
    force_gf: np.ndarray  # raw reading
    time_s: np.ndarray  # unwrapped, from the first row logged (a merged position: its rows' mean time)
    height_mm: float

    def up_to(self, travel_mm: float) -> "RigTrial":
        """The record up to ``travel_mm`` of travel from its first sample (that sample included)."""
        keep = self.displacement_mm <= travel_mm + 1e-9
        return replace(self, displacement_mm=self.displacement_mm[keep], force_gf=self.force_gf[keep],
                       time_s=self.time_s[keep])


def read_rig_csv(path: str | Path) -> RigTrial:
    """Read and validate one rig CSV."""
    path = Path(path)
    src = str(path)
    try:
        df = pd.read_csv(path)
    except FileNotFoundError:
        raise InputError(src, "<file>", "file not found") from None
    except (IsADirectoryError, PermissionError) as exc:
        raise InputError(src, "<file>", f"cannot read: {exc.strerror}") from None
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise InputError(src, "<file>", f"malformed CSV: {exc}") from None
    df.columns = [str(c).strip() for c in df.columns]
    for key, col in COLUMNS.items():
        if col not in df.columns:
            raise InputError(src, col, f"missing column; found {list(df.columns)}")
    if len(df) < 2:
        raise InputError(src, "<rows>", "fewer than 2 samples")
    out = {}
    for key in ("time", "force", "disp", "height"):
        col = COLUMNS[key]
        vals = pd.to_numeric(df[col], errors="coerce").to_numpy(float)
        bad = ~np.isfinite(vals)
        if bad.any():
            i = int(np.argmax(bad))
            raise InputError(src, col, f"row {i + 2}: not a finite number ({cell_text(df[col].iloc[i])})")
        out[key] = vals
    disp = out["disp"] - out["disp"][0]
    d = np.diff(disp)
    if np.any(d < 0):
        i = int(np.argmax(d < 0)) + 1
        raise InputError(src, COLUMNS["disp"], f"row {i + 2}: displacement does not increase (it goes back "
                                               f"from {out['disp'][i - 1]:.10g} to {out['disp'][i]:.10g})")
    t = out["time"].copy()
    jumps = np.diff(t)
    t[1:] += 65536.0 * np.cumsum(jumps < -32768)  # 16-bit counter wrapped
    t0 = t[0]  # the clock's zero is the first row logged (the IMU's is too), merged or not
    force = out["force"]
    if np.any(d == 0):
        # a sample logged twice at one probe position (the logger ran while the stepper did not
        # step): one position, one reading, their mean; the fit and the elbow searches take one
        # sample per position
        rows = np.flatnonzero(d == 0) + 1
        group = np.concatenate([[0], np.cumsum(d > 0)])
        n = np.bincount(group)
        force, t = np.bincount(group, force) / n, np.bincount(group, t) / n
        disp = disp[np.concatenate([[True], d > 0])]
        warn_input(src, COLUMNS["disp"], f"{len(rows)} sample(s) repeat the previous position (row(s) "
                                         f"{', '.join(str(r + 2) for r in rows[:5])}{', ...' if len(rows) > 5 else ''}"
                                         "); each position's readings are averaged")
    if len(disp) < 2:
        raise InputError(src, COLUMNS["disp"], "the probe never moves")
    step = float(np.median(np.diff(disp)))
    if step < 0.01:
        warn_input(src, COLUMNS["disp"], f"median step {step:.3g} per sample: the rig steps 0.5 mm, so this "
                                         "looks like metres, not mm")
    elif step > 2.5:  # five rig steps a sample: a displacement in another unit (or scaled) moves k as much
        warn_input(src, COLUMNS["disp"], f"median step {step:.3g} mm per sample: the rig steps 0.5 mm, so the "
                                         "positions look scaled (not mm?); the stiffness scales with them")
    return RigTrial(src, disp, force, (t - t0) / 1000.0, float(np.median(out["height"])))
