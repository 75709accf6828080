"""Datasets: cane descriptions paired with rig trials.

A dataset directory holds ``push_points.csv`` (bush, cane, trial, height_mm,
diameter_mm, file) and the rig CSVs it names - the field campaign's layout.
If it also has ``canes/*.yaml`` descriptions (the bundled synthetic set),
those give the geometry. Otherwise (the real field data, which published no
geometry) each cane is ASSUMED straight and vertical from the ground to its
highest push point, with the caliper diameters at the push heights; that
assumption is carried into every output.
"""

from __future__ import annotations

import fnmatch
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from .cane import CaneDescription, cane_from_dict, load_cane
from ..errors import InputError, cell_text, warn_input

STRAIGHT_ASSUMPTION = ("geometry assumed: straight vertical cane from the ground to the highest push point "
                       "(the field data has no polylines)")


def bundled_dataset() -> Path:
    """Path of the bundled synthetic dataset (installed package data)."""
    from canebench import canes

    return Path(canes.__file__).resolve().parent / "synthetic"


@dataclass(frozen=True)
class Trial:
    id: str  # e.g. b1c2t3
    cane: CaneDescription
    push_id: str
    csv: Path | None
    bush: int
    cane_no: int
    trial_no: int
    height_mm: float
    diameter_mm: float


def read_push_points(path: Path) -> pd.DataFrame:
    src = str(path)
    try:
        df = pd.read_csv(path)
    except FileNotFoundError:
        raise InputError(src, "<file>", "not found (a dataset needs push_points.csv)") from None
    except (IsADirectoryError, PermissionError) as exc:
        raise InputError(src, "<file>", f"cannot read: {exc.strerror}") from None
    except (pd.errors.ParserError, pd.errors.EmptyDataError) as exc:
        raise InputError(src, "<file>", f"malformed CSV: {exc}") from None
    except UnicodeDecodeError:
        raise InputError(src, "<file>", "not a text file (cannot decode as UTF-8); expected CSV") from None
    for col in ("bush", "cane", "trial", "height_mm", "diameter_mm", "file"):
        if col not in df.columns:
            raise InputError(src, col, "missing column")
    for col in ("bush", "cane", "trial", "height_mm", "diameter_mm"):
        vals = pd.to_numeric(df[col], errors="coerce")
        bad = ~np.isfinite(vals.to_numpy(float))
        if bad.any():
            i = int(bad.argmax())
            raise InputError(src, col, f"row {i + 2}: not a finite number ({cell_text(df[col].iloc[i])})")
        if col in ("height_mm", "diameter_mm") and (vals <= 0).any():
            i = int((vals <= 0).to_numpy().argmax())
            raise InputError(src, col, f"row {i + 2}: must be > 0, got {vals.iloc[i]}")
        if col in ("bush", "cane", "trial") and np.any(vals.to_numpy(float) != np.round(vals.to_numpy(float))):
            i = int((vals.to_numpy(float) != np.round(vals.to_numpy(float))).argmax())
            raise InputError(src, col, f"row {i + 2}: must be a whole number, got {vals.iloc[i]!r}")
        df[col] = vals
    dup = df.duplicated(["bush", "cane", "trial"])
    if dup.any():
        i = int(dup.to_numpy().argmax())
        raise InputError(src, "trial", f"row {i + 2}: bush {df.bush.iloc[i]:g} cane {df.cane.iloc[i]:g} trial "
                                       f"{df.trial.iloc[i]:g} appears twice")
    for col, (lo, hi), unit in (("height_mm", (20.0, 4000.0), "metres"), ("diameter_mm", (0.5, 50.0), "metres")):
        v = df[col].to_numpy(float)
        odd = (v < lo) | (v > hi)
        if odd.any():
            i = int(odd.argmax())
            hint = f"; looks like {unit}, not mm" if v[i] < lo else ""
            warn_input(src, col, f"row {i + 2}: {v[i]:g} mm is implausible ({lo:g}-{hi:g} mm){hint}")
    return df


def straight_cane(bush: int, cane: int, rows: pd.DataFrame, source: str) -> CaneDescription:
    """A straight vertical cane from the ground through the push points."""
    top = float(rows["height_mm"].max()) / 1000.0
    data = {
        "id": f"b{bush}c{cane}",
        "polyline": {"raw": False, "points": [[0.0, 0.0, 0.0], [0.0, 0.0, top]]},
        "calipers": [{"height": float(r.height_mm) / 1000.0, "diameter": float(r.diameter_mm) / 1000.0}
                     for r in rows.itertuples()],
        "push_points": [{"id": str(int(r.trial)), "height": float(r.height_mm) / 1000.0, "direction": [1, 0, 0]}
                        for r in rows.itertuples()],
        "provenance": {"source": source, "synthetic": False, "assumptions": [STRAIGHT_ASSUMPTION]},
    }
    return cane_from_dict(data, source)


def push_point_for(desc: CaneDescription, trial: int, tid: str, pp_src: str) -> str:
    """The id of the push point that trial number ``trial`` of push_points.csv probes: the id equal to
    the number ("1"), else the one id whose number it ends in ("t1", "T01", "push-1"): the format
    documents pair them by number, and a blind test bed's "t1" ids were refused (session 66)."""
    ids = [p.id for p in desc.push_points]
    if str(trial) in ids:
        return str(trial)
    ends = [i for i in ids if (m := re.search(r"(\d+)$", i)) and int(m.group(1)) == trial]
    if len(ends) == 1:
        return ends[0]
    why = f"ids {', '.join(ends)} all end in {trial}" if ends else f"its ids are {', '.join(ids)}"
    raise InputError(desc.source, "push_points", f"no push point for trial {tid} of {pp_src} (trial {trial}): "
                                                 f"{why}; give the push point the id '{trial}'")


def load_dataset(directory: str | Path, select: str | None = None) -> list[Trial]:
    """All trials of a dataset directory, optionally filtered by glob(s).

    ``select`` is a comma-separated list of glob patterns on trial ids
    (``b1c*``, ``b2c3t1``) or cane ids.
    """
    d = Path(directory)
    if not d.is_dir():
        raise InputError(str(d), "--field", "dataset directory not found")
    pp = read_push_points(d / "push_points.csv")
    yaml_dir = d / "canes"
    descriptions: dict[str, CaneDescription] = {}
    has_yaml = yaml_dir.is_dir()
    if has_yaml:
        for y in sorted([*yaml_dir.glob("*.yaml"), *yaml_dir.glob("*.yml")]):
            c = load_cane(y)
            if c.id in descriptions:
                raise InputError(str(y), "id", f"cane id {c.id!r} is also used by {descriptions[c.id].source}: "
                                               "every description needs its own id")
            descriptions[c.id] = c
    pp_src = str(d / "push_points.csv")
    if pp.empty:  # a header alone: every command would have nothing to do, and some would fail obscurely
        raise InputError(pp_src, "rows", "no trials: the file has a header but no rows")
    wanted = {f"b{int(b)}c{int(c)}" for b, c in zip(pp.bush, pp.cane)}
    if has_yaml:
        # a description nobody probes, or a probed cane without one, is a mismatch:
        # silently falling back to a straight cane would change the physics
        stray = sorted(set(descriptions) - wanted)
        if stray:
            c = descriptions[stray[0]]
            raise InputError(c.source, "id", f"cane id {c.id!r} matches no bush/cane row of {pp_src} "
                                             f"(rows name: {', '.join(sorted(wanted))})")
        missing = sorted(wanted - set(descriptions))
        if missing:
            raise InputError(pp_src, "cane", f"no description in {yaml_dir} for cane(s) {', '.join(missing)} "
                                             "(ids must match b<bush>c<cane>)")
    trials = []
    for (bush, cane), rows in pp.groupby(["bush", "cane"], sort=True):
        cid = f"b{int(bush)}c{int(cane)}"
        desc = descriptions.get(cid) or straight_cane(int(bush), int(cane), rows, pp_src)
        for r in rows.itertuples():
            tid = f"{cid}t{int(r.trial)}"
            pid = push_point_for(desc, int(r.trial), tid, pp_src)
            trials.append(Trial(tid, desc, pid, (d / str(r.file)).resolve(), int(bush), int(cane),
                                int(r.trial), float(r.height_mm), float(r.diameter_mm)))
    if select:
        pats = [p.strip() for p in select.split(",") if p.strip()]
        trials = [t for t in trials if any(fnmatch.fnmatch(t.id, p) or fnmatch.fnmatch(t.cane.id, p) for p in pats)]
        if not trials:
            raise InputError(str(d), "--trials", f"no trial matches {select!r}")
    return trials
