"""The chain as URDF, plus a sidecar with the joint springs URDF cannot hold.

URDF has joint damping (``<dynamics damping>``) but no joint springs. The
sidecar (``<name>.springs.yaml``) lists, for every revolute joint by name,
``stiffness`` (N m/rad), ``damping`` (N m s/rad) and ``rest_angle`` (rad),
so that tau = -stiffness (q - rest_angle) - damping qdot, and how PyBullet,
Isaac Lab and Gazebo users apply them (:data:`SIDECAR_NOTE`). For Gazebo
the URDF also carries the springs in ``<gazebo reference="joint">``
extension blocks (``springStiffness``, ``springReference``), which
sdformat's URDF converter maps to the SDF joint springs and other parsers
ignore.

Joints are ``continuous`` about x, y (and z) of the link's rest frame, with
``base`` (massless, to be fixed) as the root and intermediate links as in
:mod:`canebench.export.common`. A fixed leaf link ``probe`` sits at the probe
point with its x axis along the probe direction.
"""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import yaml

from ..model.chain import Chain
from .common import (AXES, DUMMY_MASS_FRACTION, JointRow, chain_info, dummy_inertial, fmt, joint_rows,
                     probe_local, rpy)

SIDECAR_FORMAT = "canebench-joint-springs/1"

SIDECAR_NOTE = """\
URDF has no joint springs. Every joint below is a torsional spring-damper:
  tau = -stiffness * (q - rest_angle) - damping * qdot     (N m; q in rad)
Load the URDF with a FIXED base (the cane is clamped at its base link).
PyBullet: loadURDF(path, useFixedBase=True, flags=p.URDF_USE_INERTIA_FROM_FILE);
  disable the default velocity motors once
  (setJointMotorControlArray(body, idx, p.VELOCITY_CONTROL, forces=[0]*n)) and
  changeDynamics(body, i, jointDamping=0) (damping is applied below); then every
  step: setJointMotorControlArray(body, idx, p.TORQUE_CONTROL,
  forces=-K*(q - rest) - c*qdot). Bullet's POSITION_CONTROL gains are not in
  N m/rad, so use torque control. These springs are explicit: keep the time
  step below the explicit stability limit (canebench's PyBullet backend
  computes it from the mass matrix).
Isaac Lab: import the URDF (fix_base=True) and give the joints an
  ImplicitActuatorCfg(joint_names_expr=[...], stiffness={name: stiffness},
  damping={name: damping}, effort_limit=<large>) with the articulation's
  default joint positions = rest_angle (0): PhysX's implicit joint drive is
  the spring, stable at any step.
Gazebo: use the SDF export (spring_stiffness / spring_reference / damping in
  each joint's <dynamics>), or this URDF: its <gazebo reference="jNx"> blocks
  carry springStiffness / springReference, which Gazebo's URDF converter maps
  to the same SDF elements.
"""


def _sub(parent: ET.Element, tag: str, **attrib: str) -> ET.Element:
    return ET.SubElement(parent, tag, attrib)


def _inertial(link: ET.Element, mass: float, moments: Any, z_com: float) -> None:
    ine = _sub(link, "inertial")
    _sub(ine, "origin", xyz=fmt([0.0, 0.0, z_com]), rpy="0 0 0")
    _sub(ine, "mass", value=fmt(mass))
    _sub(ine, "inertia", ixx=fmt(moments[0]), iyy=fmt(moments[1]), izz=fmt(moments[2]), ixy="0", ixz="0", iyz="0")


def chain_to_urdf(chain: Chain, name: str = "cane", dummy_mass_fraction: float = DUMMY_MASS_FRACTION,
                  gazebo_springs: bool = True) -> str:
    """URDF text of ``chain`` (robot ``name``)."""
    robot = ET.Element("robot", name=name)
    base = _sub(robot, "link", name="base")
    _inertial(base, 0.0, (0.0, 0.0, 0.0), 0.0)  # a link without <inertial> gets 1 kg in PyBullet
    rows = joint_rows(chain, base="base")
    for row in rows:
        j = row.link
        first = row.axis == "x"
        R, p = chain.relative_pose(j) if first else (None, None)
        joint = _sub(robot, "joint", name=row.name, type="continuous")
        _sub(joint, "parent", link=row.parent)
        _sub(joint, "child", link=row.child)
        if first:  # the link's rest frame in its parent's; later joints of the link are at the same frame
            _sub(joint, "origin", xyz=fmt(p), rpy=fmt(rpy(R)))
        else:
            _sub(joint, "origin", xyz="0 0 0", rpy="0 0 0")
        _sub(joint, "axis", xyz=fmt(AXES[row.axis]))
        _sub(joint, "dynamics", damping=fmt(row.damping), friction="0")
        link = _sub(robot, "link", name=row.child)
        if row.child == f"link{j}":
            L, r = float(chain.lengths[j]), float(chain.diameters[j]) / 2.0
            _inertial(link, float(chain.masses[j]), chain.inertias[j], L / 2.0)
            for kind in ("visual", "collision"):
                g = _sub(link, kind)
                _sub(g, "origin", xyz=fmt([0.0, 0.0, L / 2.0]), rpy="0 0 0")
                _sub(_sub(g, "geometry"), "cylinder", radius=fmt(r), length=fmt(L))
        else:
            m, mom = dummy_inertial(chain, j, dummy_mass_fraction)
            _inertial(link, m, mom, 0.0)
    p, R = probe_local(chain)
    joint = _sub(robot, "joint", name="probe_fixed", type="fixed")
    _sub(joint, "parent", link=f"link{chain.push_link}")
    _sub(joint, "child", link="probe")
    _sub(joint, "origin", xyz=fmt(p), rpy=fmt(rpy(R)))
    _inertial(_sub(robot, "link", name="probe"), 0.0, (0.0, 0.0, 0.0), 0.0)
    if gazebo_springs:
        for row in rows:
            gz = _sub(robot, "gazebo", reference=row.name)
            ET.SubElement(gz, "springStiffness").text = fmt(row.stiffness)
            ET.SubElement(gz, "springReference").text = fmt(row.rest_angle)
        gz = _sub(robot, "gazebo", reference="probe_fixed")
        ET.SubElement(gz, "preserveFixedJoint").text = "true"  # keep the probe frame (Gazebo lumps fixed joints)
    ET.indent(robot, "  ")
    head = ('<?xml version="1.0"?>\n<!-- canebench export: pseudo-rigid-body cane chain; SI units. URDF cannot '
            f'hold joint springs: see {name}.springs.yaml beside this file. -->\n')
    return head + ET.tostring(robot, encoding="unicode") + "\n"


def sidecar(chain: Chain, urdf_file: str, meta: dict[str, Any] | None = None,
            dummy_mass_fraction: float = DUMMY_MASS_FRACTION) -> dict[str, Any]:
    """The sidecar's content: springs per joint, the probe, provenance."""
    rows: list[JointRow] = joint_rows(chain)
    p, _ = probe_local(chain)
    return {
        "format": SIDECAR_FORMAT,
        "urdf": urdf_file,
        "units": {"stiffness": "N m/rad", "damping": "N m s/rad", "rest_angle": "rad", "length": "m"},
        "joints": {r.name: {"stiffness": r.stiffness, "damping": r.damping, "rest_angle": r.rest_angle}
                   for r in rows},
        "probe": {"link": "probe", "parent_link": f"link{chain.push_link}", "point_in_link": [float(x) for x in p],
                  "point_world": [float(x) for x in chain.push_point],
                  "direction_world": [float(x) for x in chain.direction],
                  "note": "the probe pushes the point along the fixed world direction (the 'probe' link's x at rest)"},
        "gravity": [float(g) for g in chain.gravity],
        "intermediate_link_mass_fraction": dummy_mass_fraction,
        "canebench": {**chain_info(chain), **(meta or {})},
    }


def sidecar_text(data: dict[str, Any]) -> str:
    note = "".join(f"# {line}\n" if line else "#\n" for line in SIDECAR_NOTE.splitlines())
    return (f"# canebench joint springs for {data['urdf']}\n#\n{note}"
            + yaml.safe_dump(json.loads(json.dumps(data)), sort_keys=False, default_flow_style=None, width=100))


def load_sidecar(path: str | Path) -> dict[str, Any]:
    """Read a sidecar back (checks its format tag)."""
    try:
        data = yaml.safe_load(Path(path).read_text())
    except yaml.YAMLError:
        data = None
    if not isinstance(data, dict) or data.get("format") != SIDECAR_FORMAT:
        raise ValueError(f"{path}: not a {SIDECAR_FORMAT} file")
    return data


def write_urdf(chain: Chain, path: str | Path, name: str = "cane", meta: dict[str, Any] | None = None,
               dummy_mass_fraction: float = DUMMY_MASS_FRACTION) -> tuple[Path, Path]:
    """Write ``path`` (URDF) and ``<stem>.springs.yaml`` beside it; return both paths."""
    path = Path(path)
    path.write_text(chain_to_urdf(chain, name, dummy_mass_fraction))
    side = path.with_name(path.stem + ".springs.yaml")
    side.write_text(sidecar_text(sidecar(chain, path.name, meta, dummy_mass_fraction)))
    return path, side
