"""Cane description: the backend-agnostic input format (spec in canes/README.md).

A description is plain data. It is validated on load so that every error
names the file and the field; nothing downstream re-checks user input.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from ..errors import InputError, warn_input
from .strict_yaml import load_yaml

DEFAULT_DENSITY = 580.0  # kg/m^3, paper (Zhang et al.)
DEFAULT_DAMPING = 0.15  # N m s/rad, paper (Pivato et al.)
DORMANT_MEAN_MODULUS = 4.57e9  # Pa, paper's dormant-season mean (naive case)

# Every key the format knows, per level: anything else is a typo that would
# otherwise be dropped silently (a misspelt modulus takes the default).
KEYS = {
    "<root>": ("id", "polyline", "calipers", "push_points", "material", "provenance"),
    "polyline": ("raw", "points"),
    "calipers": ("s", "height", "diameter"),
    "push_points": ("id", "s", "height", "direction", "trial"),
    "material": ("flexural_modulus", "density", "joint_damping"),
}
# Hard bounds: beyond them a value is not a cane in SI units at all.
MAX_COORD_M = 1.0e4
MAX_DIAMETER_M = 1.0
# Plausible ranges: outside them a warning names the likely unit mistake.
PLAUSIBLE_LENGTH_M = (0.05, 6.0)
PLAUSIBLE_DIAMETER_M = (0.5e-3, 0.05)
PLAUSIBLE_MODULUS_PA = (0.1e9, 40e9)
PLAUSIBLE_DENSITY = (100.0, 1500.0)


@dataclass(frozen=True)
class Location:
    """A place on the cane: arc length ``s`` from the base or a ``height`` (m)."""

    s: float | None = None
    height: float | None = None


@dataclass(frozen=True)
class Caliper:
    """A caliper diameter (m) measured at a location."""

    where: Location
    diameter: float


@dataclass(frozen=True)
class PushPoint:
    """Where and in which horizontal direction the probe pushes.

    ``direction`` is the probe's azimuth as a horizontal vector; the harness
    pitches it to be perpendicular to the cane there (as the field crew did)
    and then applies the configured probe angle.
    """

    id: str
    where: Location
    direction: tuple[float, float, float] = (1.0, 0.0, 0.0)
    trial: str | None = None  # path of the rig CSV, relative to the YAML file


@dataclass(frozen=True)
class Material:
    flexural_modulus: float = DORMANT_MEAN_MODULUS
    density: float = DEFAULT_DENSITY
    joint_damping: float = DEFAULT_DAMPING


@dataclass(frozen=True)
class CaneDescription:
    """A blueberry cane: centreline, calipers, push points, material, provenance.

    All quantities SI (m, Pa, kg/m^3, N m s/rad). ``polyline`` is base first,
    z up; ``raw_polyline`` says whether Chaikin smoothing is still to be applied.
    """

    id: str
    polyline: np.ndarray
    raw_polyline: bool
    calipers: tuple[Caliper, ...]
    push_points: tuple[PushPoint, ...]
    material: Material = field(default_factory=Material)
    provenance: dict[str, Any] = field(default_factory=dict)
    source: str = "<memory>"

    def push_point(self, pid: str) -> PushPoint:
        for p in self.push_points:
            if p.id == str(pid):
                return p
        raise InputError(self.source, "push_points", f"no push point with id {pid!r}")

    def trial_path(self, pid: str) -> Path | None:
        p = self.push_point(pid)
        if p.trial is None:
            return None
        return (Path(self.source).parent / p.trial).resolve()


# ---------------------------------------------------------------- validation


def _num(value: Any, src: str, fld: str, *, positive: bool = False, nonneg: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        raise InputError(src, fld, f"expected a number, got {value!r}")
    try:
        x = float(value)
    except ValueError:
        raise InputError(src, fld, f"expected a number, got {value!r}") from None
    except OverflowError:
        raise InputError(src, fld, f"number out of range ({str(value)[:20]}...)") from None
    if not math.isfinite(x):
        raise InputError(src, fld, f"must be finite, got {value!r}")
    if positive and x <= 0:
        raise InputError(src, fld, f"must be > 0, got {x!r}")
    if nonneg and x < 0:
        raise InputError(src, fld, f"must be >= 0, got {x!r}")
    return x


def _check_keys(d: dict, allowed: tuple[str, ...], src: str, where: str) -> None:
    import difflib

    for k in d:
        if k not in allowed:
            close = difflib.get_close_matches(str(k), allowed, n=1, cutoff=0.6)
            hint = f"; did you mean '{close[0]}'?" if close else f"; known: {', '.join(allowed)}"
            fld = str(k) if where == "<root>" else f"{where}.{k}"
            raise InputError(src, fld, f"unknown key{hint}")


def _location(d: dict, src: str, fld: str) -> Location:
    has_s, has_h = "s" in d, "height" in d
    if has_s == has_h:
        raise InputError(src, fld, "give exactly one of 's' (arc length, m) or 'height' (m)")
    if has_s:
        return Location(s=_num(d["s"], src, f"{fld}.s", nonneg=True))
    return Location(height=_num(d["height"], src, f"{fld}.height", nonneg=True))


def cane_from_dict(data: Any, source: str = "<memory>") -> CaneDescription:
    """Validate a parsed mapping and build a :class:`CaneDescription`."""
    src = str(source)
    if not isinstance(data, dict):
        raise InputError(src, "<root>", "expected a mapping at the top level")
    _check_keys(data, KEYS["<root>"], src, "<root>")
    for key in ("id", "polyline", "calipers", "push_points"):
        if key not in data:
            raise InputError(src, key, "missing required field")
    cid = str(data["id"]).strip()
    if not cid:
        raise InputError(src, "id", "must be a non-empty string")

    poly = data["polyline"]
    if isinstance(poly, dict):
        _check_keys(poly, KEYS["polyline"], src, "polyline")
        raw_flag = poly.get("raw", True)
        if not isinstance(raw_flag, bool):
            raise InputError(src, "polyline.raw", f"expected true or false, got {raw_flag!r}")
        raw = raw_flag
        pts = poly.get("points")
    else:
        raw, pts = True, poly
    if not isinstance(pts, list) or len(pts) < 2:
        raise InputError(src, "polyline.points", "need a list of at least 2 [x, y, z] points")
    arr = np.empty((len(pts), 3))
    for i, p in enumerate(pts):
        if not isinstance(p, (list, tuple)) or len(p) != 3:
            raise InputError(src, f"polyline.points[{i}]", f"expected [x, y, z], got {p!r}")
        for j in range(3):
            arr[i, j] = _num(p[j], src, f"polyline.points[{i}][{j}]")
            if abs(arr[i, j]) > MAX_COORD_M:
                raise InputError(src, f"polyline.points[{i}][{j}]",
                                 f"{arr[i, j]:.6g} m is out of range (|x| <= {MAX_COORD_M:g} m): coordinates are in metres")
    seg = np.linalg.norm(np.diff(arr, axis=0), axis=1)
    if np.any(seg <= 1e-9):
        i = int(np.argmax(seg <= 1e-9))
        raise InputError(src, f"polyline.points[{i + 1}]", "coincides with the previous point (degenerate polyline)")
    if seg.sum() < 1e-3:
        raise InputError(src, "polyline.points", "total length below 1 mm (degenerate polyline)")

    cals = data["calipers"]
    if not isinstance(cals, list) or not cals:
        raise InputError(src, "calipers", "need at least one {s|height, diameter} entry")
    calipers = []
    for i, c in enumerate(cals):
        f = f"calipers[{i}]"
        if not isinstance(c, dict) or "diameter" not in c:
            raise InputError(src, f, "expected a mapping with 'diameter' and 's' or 'height'")
        _check_keys(c, KEYS["calipers"], src, f)
        dia = _num(c["diameter"], src, f"{f}.diameter", positive=True)
        if dia > MAX_DIAMETER_M:
            raise InputError(src, f"{f}.diameter", f"{dia:g} m is out of range (<= {MAX_DIAMETER_M:g} m): "
                                                    "diameters are in metres (this looks like millimetres)")
        calipers.append(Caliper(_location(c, src, f), dia))

    pps = data["push_points"]
    if not isinstance(pps, list) or not pps:
        raise InputError(src, "push_points", "need at least one push point")
    push_points, seen = [], set()
    for i, p in enumerate(pps):
        f = f"push_points[{i}]"
        if not isinstance(p, dict) or "id" not in p:
            raise InputError(src, f, "expected a mapping with 'id' and 's' or 'height'")
        _check_keys(p, KEYS["push_points"], src, f)
        pid = str(p["id"])
        if pid in seen:
            raise InputError(src, f"{f}.id", f"duplicate push point id {pid!r}")
        seen.add(pid)
        direction = p.get("direction", [1.0, 0.0, 0.0])
        if not isinstance(direction, (list, tuple)) or len(direction) != 3:
            raise InputError(src, f"{f}.direction", "expected [x, y, z]")
        dvec = np.array([_num(v, src, f"{f}.direction") for v in direction])
        dvec[2] = 0.0  # azimuth only: the pitch is set perpendicular to the cane
        if np.linalg.norm(dvec) < 1e-9:
            raise InputError(src, f"{f}.direction", "needs a non-zero horizontal component")
        dvec /= np.linalg.norm(dvec)
        trial = p.get("trial")
        push_points.append(PushPoint(pid, _location(p, src, f), tuple(float(v) for v in dvec),
                                     None if trial is None else str(trial)))

    mat = data.get("material", {}) or {}
    if not isinstance(mat, dict):
        raise InputError(src, "material", "expected a mapping")
    _check_keys(mat, KEYS["material"], src, "material")
    material = Material(
        flexural_modulus=_num(mat.get("flexural_modulus", DORMANT_MEAN_MODULUS), src, "material.flexural_modulus", positive=True),
        density=_num(mat.get("density", DEFAULT_DENSITY), src, "material.density", positive=True),
        joint_damping=_num(mat.get("joint_damping", DEFAULT_DAMPING), src, "material.joint_damping", nonneg=True),
    )
    prov = data.get("provenance", {}) or {}
    if not isinstance(prov, dict):
        raise InputError(src, "provenance", "expected a mapping")
    if "assumptions" in prov:
        # each a sentence every result from this cane carries; one sentence alone is a list of one
        a = prov["assumptions"]
        a = [] if a is None else [a] if isinstance(a, str) else a
        if not (isinstance(a, list) and all(isinstance(x, str) for x in a)):
            raise InputError(src, "provenance.assumptions", f"expected a list of sentences (text), got {a!r}")
        prov = {**prov, "assumptions": a}
    cane = CaneDescription(cid, arr, raw, tuple(calipers), tuple(push_points), material, dict(prov), src)
    _check_extent(cane)
    _check_plausible(cane)
    return cane


def _extent_error(cane: CaneDescription, fld: str, where: Location, length: float, zmin: float, zmax: float) -> None:
    tol = 1e-3  # a caliper at the very tip, up to 1 mm past the digitized end, is a rounding matter
    if where.s is not None and where.s > length + tol:
        raise InputError(cane.source, f"{fld}.s", f"{where.s:.4g} m is beyond the cane's length {length:.4g} m")
    if where.height is not None and not (zmin - tol <= where.height <= zmax + tol):
        raise InputError(cane.source, f"{fld}.height", f"{where.height:.4g} m is outside the cane's heights "
                                                       f"{zmin:.4g}..{zmax:.4g} m")


def check_modulus(E: float, src: str, fld: str) -> None:
    """Warn when a modulus in Pa looks like GPa or MPa (shared by cane files and ``--set``)."""
    lo, hi = PLAUSIBLE_MODULUS_PA
    if not (lo <= E <= hi):
        unit = "; looks like GPa, not Pa" if E < 1e3 else ("; looks like MPa, not Pa" if E < 1e6 else "")
        warn_input(src, fld, f"{E:.4g} Pa is implausible for green wood ({lo:g}-{hi:g} Pa){unit}")


def _check_extent(cane: CaneDescription) -> None:
    """Push points and calipers must lie on the cane: an error at load, not at chain build.

    Checked on the centreline the chain is cut from (a raw polyline smoothed with
    the default Chaikin settings, which shortens it and lowers arches a little).
    """
    from ..model.geometry import Curve, chaikin

    curve = Curve.from_points(chaikin(cane.polyline) if cane.raw_polyline else cane.polyline)
    length = curve.length
    zmin, zmax = float(curve.points[:, 2].min()), float(curve.points[:, 2].max())
    for i, c in enumerate(cane.calipers):
        _extent_error(cane, f"calipers[{i}]", c.where, length, zmin, zmax)
    _warn_ambiguous_heights(cane, curve)
    for i, p in enumerate(cane.push_points):
        _extent_error(cane, f"push_points[{i}]", p.where, length, zmin, zmax)
        # a push at the clamp deflects nothing: every engine would fail on it, each in its own words
        # (by height: where the first crossing lies, which the chain takes; not the lowest point, which a
        # drooping tip may be)
        w = p.where
        s_push = w.s if w.s is not None else curve.s_at_height(w.height)
        if s_push is not None and s_push < 1e-3:
            fld, v = ("s", w.s) if w.s is not None else ("height", w.height)
            raise InputError(cane.source, f"push_points[{i}].{fld}", f"{v:.4g} m is at the clamped base (within "
                                                                     "1 mm): a push there deflects nothing")


def _warn_ambiguous_heights(cane: CaneDescription, curve: Any) -> None:
    """Warn where a height names more than one place: an arched cane reaches it on the way up and on
    the way down, and the first crossing is taken (an input review found the far limb's push 3 times
    softer, taken silently). Crossings within 5 cm of arc (a digitized wiggle) count as one place."""
    s, z = curve.s, curve.points[:, 2]
    places = [*((f"calipers[{i}]", c.where) for i, c in enumerate(cane.calipers)),
              *((f"push_points[{i}]", p.where) for i, p in enumerate(cane.push_points))]
    for fld, w in places:
        if w.height is None:
            continue
        d = z - w.height
        k = np.nonzero(d[:-1] * d[1:] < 0)[0]
        at = s[k] + d[k] / (d[k] - d[k + 1]) * (s[k + 1] - s[k])
        if len(at) > 1 and at.max() - at.min() > 0.05:
            warn_input(cane.source, f"{fld}.height", f"{w.height:.4g} m is reached at s = "
                       + ", ".join(f"{v:.3f}" for v in at[:4]) + f" m along the cane; the first ({at[0]:.3f} m) is "
                       "taken: give s (arc length) to choose")


def _check_plausible(cane: CaneDescription) -> None:
    """Warn (an error under --strict) about magnitudes that look like the wrong unit, and odd shapes."""
    src, pts = cane.source, cane.polyline
    seg = np.diff(pts, axis=0)
    length = float(np.linalg.norm(seg, axis=1).sum())
    lo, hi = PLAUSIBLE_LENGTH_M
    if length > hi:
        warn_input(src, "polyline.points", f"cane length {length:.4g} m is implausible for a blueberry cane "
                                           f"({lo:g}-{hi:g} m){'; looks like millimetres' if length > 50 else ''}")
    elif length < lo:
        warn_input(src, "polyline.points", f"cane length {length:.4g} m is implausibly short ({lo:g}-{hi:g} m)")
    lo, hi = PLAUSIBLE_DIAMETER_M
    for i, c in enumerate(cane.calipers):
        if c.diameter > hi:
            unit = ("; looks like millimetres" if c.diameter >= 1.0 else
                    "; looks like centimetres" if c.diameter >= 0.1 else "")
            warn_input(src, f"calipers[{i}].diameter", f"{c.diameter:.4g} m is implausible ({lo:g}-{hi:g} m){unit}")
        elif c.diameter < lo:
            warn_input(src, f"calipers[{i}].diameter", f"{c.diameter:.4g} m is implausibly thin ({lo:g}-{hi:g} m)")
    check_modulus(cane.material.flexural_modulus, src, "material.flexural_modulus")
    rho = cane.material.density
    if not (PLAUSIBLE_DENSITY[0] <= rho <= PLAUSIBLE_DENSITY[1]):
        warn_input(src, "material.density", f"{rho:.4g} kg/m^3 is implausible for wood "
                                            f"({PLAUSIBLE_DENSITY[0]:g}-{PLAUSIBLE_DENSITY[1]:g})")
    if len(pts) >= 2 and pts[0, 2] > pts[-1, 2] + 1e-3:
        warn_input(src, "polyline.points", f"the base (first point, z = {pts[0, 2]:.4g} m) is above the tip "
                                           f"(last point, z = {pts[-1, 2]:.4g} m): written tip first?")
    if len(seg) >= 2:
        u = seg / np.linalg.norm(seg, axis=1)[:, None]
        turn = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", u[:-1], u[1:]), -1.0, 1.0)))
        i = int(np.argmax(turn))
        if turn[i] > 90.0:
            n_bad = int((turn > 90.0).sum())
            warn_input(src, f"polyline.points[{i + 1}]",
                       f"the polyline doubles back here (turning angle {turn[i]:.0f} degrees"
                       f"{f'; {n_bad} such points' if n_bad > 1 else ''}): a digitizing error? The smoothed "
                       "centreline keeps the fold")


def load_cane(path: str | Path) -> CaneDescription:
    """Read and validate one cane description YAML file."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise InputError(str(path), "<file>", f"cannot read: {exc.strerror}") from None
    except UnicodeDecodeError:
        raise InputError(str(path), "<file>", "not a text file (cannot decode as UTF-8); expected YAML") from None
    try:
        data = load_yaml(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"line {mark.line + 1}" if mark is not None else "<yaml>"
        raise InputError(str(path), where, f"malformed YAML: {getattr(exc, 'problem', exc)}") from None
    return cane_from_dict(data, str(path))


def cane_to_dict(cane: CaneDescription) -> dict[str, Any]:
    """Inverse of :func:`cane_from_dict` (for writing generated descriptions)."""

    def loc(w: Location) -> dict[str, float]:
        return {"s": w.s} if w.s is not None else {"height": w.height}

    return {
        "id": cane.id,
        "polyline": {"raw": cane.raw_polyline, "points": [[float(v) for v in p] for p in cane.polyline]},
        "calipers": [{**loc(c.where), "diameter": c.diameter} for c in cane.calipers],
        "push_points": [
            {"id": p.id, **loc(p.where), "direction": list(p.direction), **({"trial": p.trial} if p.trial else {})}
            for p in cane.push_points
        ],
        "material": {
            "flexural_modulus": cane.material.flexural_modulus,
            "density": cane.material.density,
            "joint_damping": cane.material.joint_damping,
        },
        "provenance": cane.provenance,
    }
