"""IMU accelerometer logs of a probing trial: format, reading and validation.

One CSV per trial, beside its rig CSV: ``trials/<rig csv stem>.imu.csv``
(spec: ``canes/IMU_FORMAT.md``). Columns, accelerations in m/s^2:

``time_s, pushed_x, pushed_y, pushed_z, left_x, left_y, left_z, right_x, right_y, right_z``

``pushed`` is the accelerometer on the pushed cane, ``left``/``right`` those on
two neighbouring canes of the same bush (the paper's nine channels).
``time_s`` is seconds since the rig's first sample (the rig logs every 0.5 s,
so rig sample ``i`` is at ``0.5 i`` s after unwrapping its time stamps),
strictly increasing, sampled at 40 Hz (each step within 10 % of 25 ms).
Every error names the file, the column and the row.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import InputError, cell_text

SENSORS = ("pushed", "left", "right")
CHANNELS = tuple(f"{s}_{a}" for s in SENSORS for a in "xyz")
COLUMNS = ("time_s", *CHANNELS)
RATE_HZ = 40.0
RATE_TOLERANCE = 0.10  # relative tolerance on each time step
MIN_SAMPLES = 40  # one second
MAX_ABS_ACCEL = 200.0  # m/s^2; beyond this the column is likely in mm/s^2 or raw counts


def imu_path(rig_csv: str | Path) -> Path:
    """Where the IMU log of a rig CSV lives: ``<stem>.imu.csv`` beside it."""
    rig_csv = Path(rig_csv)
    return rig_csv.with_name(rig_csv.stem + ".imu.csv")


def read_imu_csv(path: str | Path, rate_hz: float = RATE_HZ) -> pd.DataFrame:
    """Read and validate one IMU CSV.

    Parameters
    ----------
    path : str or Path
        The ``.imu.csv`` file.
    rate_hz : float
        Expected sampling rate (40 Hz in the paper).

    Returns
    -------
    pandas.DataFrame
        Columns :data:`COLUMNS` as floats, in that order.

    Raises
    ------
    InputError
        Missing file or column, non-numeric or non-finite value, time not
        increasing, wrong sampling rate, implausible magnitude, too few rows.
    """
    src = str(path)
    try:
        df = pd.read_csv(path, comment="#")
    except FileNotFoundError:
        raise InputError(src, "<file>", "file not found") from None
    except (IsADirectoryError, PermissionError) as exc:
        raise InputError(src, "<file>", f"cannot read: {exc.strerror}") from None
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise InputError(src, "<file>", f"malformed CSV: {exc}") from None
    df.columns = [str(c).strip() for c in df.columns]
    for col in COLUMNS:
        if col not in df.columns:
            raise InputError(src, col, f"missing column; expected {list(COLUMNS)}, found {list(df.columns)}")
    if len(df) < MIN_SAMPLES:
        raise InputError(src, "<rows>", f"{len(df)} samples; need at least {MIN_SAMPLES} (1 s at 40 Hz)")
    out = {}
    for col in COLUMNS:
        vals = pd.to_numeric(df[col], errors="coerce").to_numpy(float)
        bad = ~np.isfinite(vals)
        if bad.any():
            i = int(np.argmax(bad))
            raise InputError(src, col, f"row {i + 2}: not a finite number ({cell_text(df[col].iloc[i])})")
        if col != "time_s" and np.abs(vals).max() > MAX_ABS_ACCEL:
            i = int(np.argmax(np.abs(vals)))
            raise InputError(src, col, f"row {i + 2}: |{vals[i]:g}| > {MAX_ABS_ACCEL:g} m/s^2; "
                                       "accelerations must be in m/s^2")
        out[col] = vals
    dt = np.diff(out["time_s"])
    if np.any(dt <= 0):
        i = int(np.argmax(dt <= 0)) + 1
        raise InputError(src, "time_s", f"row {i + 2}: time does not increase")
    step = 1.0 / rate_hz
    off = np.abs(dt - step) > RATE_TOLERANCE * step
    if off.any():
        i = int(np.argmax(off)) + 1
        raise InputError(src, "time_s", f"row {i + 2}: step {dt[i - 1] * 1e3:.1f} ms; expected "
                                        f"{step * 1e3:g} ms ({rate_hz:g} Hz)")
    return pd.DataFrame(out, columns=list(COLUMNS))


def write_imu_csv(path: str | Path, time_s: np.ndarray, accel: np.ndarray, header: str = "") -> Path:
    """Write an IMU log (``accel``: n x 9, channel order :data:`CHANNELS`); ``header`` lines get ``# ``."""
    path = Path(path)
    lines = [f"# {h}" for h in header.splitlines() if h]
    lines.append(",".join(COLUMNS))
    for t, row in zip(time_s, accel):
        lines.append(f"{t:.3f}," + ",".join(f"{v:.3f}" for v in row))
    path.write_text("\n".join(lines) + "\n")
    return path
