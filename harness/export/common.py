"""What every export format shares: joint table, link names, poses, provenance.

URDF and SDF joints have one axis, so each cane link becomes a chain of
links joined by single-axis revolute joints: ``link{j}_x`` after joint
``j{j}x``, ``link{j}_y`` after ``j{j}y`` when the twist joint follows, and
the physical link ``link{j}`` after the last joint of the link. The
intermediate links sit at the joint (the link's rest frame) and carry
``DUMMY_MASS_FRACTION`` of the link's mass and moments: zero would match the
chain exactly, but Gazebo drops links without inertia (with everything
hanging from them) and ODE/PhysX need positive masses. 1e-4 changes no
stiffness (springs and kinematics are untouched) and total mass by 0.01 %
per intermediate link.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from ..model.chain import Chain
from ..model.geometry import frame_with_x

DUMMY_MASS_FRACTION = 1.0e-4
AXES = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}


@dataclass(frozen=True)
class JointRow:
    """One single-axis joint of the exported chain."""

    name: str
    link: int  # cane link index
    axis: str  # x, y or z of the link frame
    parent: str  # URDF/SDF link names
    child: str
    stiffness: float  # N m/rad
    damping: float  # N m s/rad
    rest_angle: float = 0.0  # rad (spring reference)


def joint_rows(chain: Chain, base: str = "base") -> list[JointRow]:
    """Every joint in chain order, with the links it connects."""
    rows = []
    parent = base
    letters = "xyz"[: chain.joints_per_link]
    for j in range(chain.n_links):
        for i, ax in enumerate(letters):
            child = f"link{j}" if i == len(letters) - 1 else f"link{j}_{ax}"
            k = chain.twist_stiffness[j] if ax == "z" else chain.stiffness[j]
            rows.append(JointRow(f"j{j}{ax}", j, ax, parent, child, float(k), float(chain.damping)))
            parent = child
    return rows


def rpy(R: np.ndarray) -> np.ndarray:
    """URDF/SDF roll-pitch-yaw (fixed axes X, Y, Z) of a rotation matrix."""
    with warnings.catch_warnings():  # gimbal lock: scipy still returns angles that compose to R
        warnings.simplefilter("ignore", UserWarning)
        return Rotation.from_matrix(np.asarray(R, float)).as_euler("xyz")


def fmt(v: Any) -> str:
    """Space-separated shortest round-trip reprs (every float exact in the file)."""
    return " ".join(repr(float(x)) for x in np.atleast_1d(v))


def probe_local(chain: Chain) -> tuple[np.ndarray, np.ndarray]:
    """(point, rotation) of the probe frame in the probe link's frame: origin at the
    probe point, x along the probe direction at rest."""
    k = chain.push_link
    return chain.local(k, chain.push_point), chain.frames[k].T @ frame_with_x(chain.direction)


def dummy_inertial(chain: Chain, j: int, fraction: float = DUMMY_MASS_FRACTION) -> tuple[float, np.ndarray]:
    """(mass, principal moments) of an intermediate link of cane link ``j``."""
    return fraction * float(chain.masses[j]), fraction * np.asarray(chain.inertias[j], float)


def chain_info(chain: Chain) -> dict[str, Any]:
    """Provenance of an exported chain (plain JSON)."""
    from .. import __version__

    m = chain.meta or {}
    info = {
        "canebench_version": __version__,
        "cane": m.get("cane"),
        "push_point": m.get("push_point"),
        "source": m.get("source"),
        "synthetic": bool(m.get("synthetic", False)),
        "chain_fingerprint": chain.fingerprint(),
        "n_links": chain.n_links,
        "n_joints": chain.n_dof,
        "twist_joint": chain.twist_stiffness is not None,
        "modulus_pa": float(chain.modulus),
        "damping": float(chain.damping),
        "gravity": [float(g) for g in chain.gravity],
        "base_compliance": float(getattr(chain, "base_compliance", 0.0)),
        "push_link": int(chain.push_link),
        "push_point_world": [float(x) for x in chain.push_point],
        "probe_direction_world": [float(x) for x in chain.direction],
        "config": _plain(m.get("config")),
        "assumptions": list(m.get("assumptions", [])),
        "warnings": list(m.get("warnings", [])),
    }
    return info


def _plain(v: Any) -> Any:
    """JSON-safe copy (tuples to lists, non-finite floats to strings, objects to str)."""
    if isinstance(v, dict):
        return {str(k): _plain(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    if isinstance(v, (bool, int, str)) or v is None:
        return v
    if isinstance(v, float):
        return v if math.isfinite(v) else str(v)
    if isinstance(v, np.generic):
        return _plain(v.item())
    return str(v)
