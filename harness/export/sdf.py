"""The chain as an SDFormat 1.7 model (Gazebo classic 11 and Gazebo Sim read 1.7).

Links are posed in the model frame (the world rest frame of the chain, z
up, base at the origin of the cane's polyline). Each cane link has a solid
cylinder inertial (mass at mid-link, principal moments), a cylinder visual
and collision; each joint is a ``revolute`` about the child link's x, y (or
z) axis with ``<dynamics>``: ``<spring_stiffness>`` (N m/rad),
``<spring_reference>`` 0 and ``<damping>`` (N m s/rad). The first joint's
parent is ``world``: the base is clamped. A ``<frame name="probe">`` attached
to the probe link sits at the probe point with its x axis along the probe
direction (at rest). Gravity is the world's (the chain's value is in the
header comment).
"""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

from ..model.chain import Chain
from .common import AXES, DUMMY_MASS_FRACTION, chain_info, dummy_inertial, fmt, joint_rows, probe_local, rpy

SDF_VERSION = "1.7"


def _sub(parent: ET.Element, tag: str, text: str | None = None, **attrib: str) -> ET.Element:
    e = ET.SubElement(parent, tag, attrib)
    if text is not None:
        e.text = text
    return e


def _inertial(link: ET.Element, mass: float, moments: Any, z_com: float) -> None:
    ine = _sub(link, "inertial")
    _sub(ine, "pose", fmt([0.0, 0.0, z_com, 0.0, 0.0, 0.0]))
    _sub(ine, "mass", fmt(mass))
    t = _sub(ine, "inertia")
    for tag, v in zip(("ixx", "ixy", "ixz", "iyy", "iyz", "izz"),
                      (moments[0], 0.0, 0.0, moments[1], 0.0, moments[2])):
        _sub(t, tag, fmt(v))


def chain_to_sdf(chain: Chain, name: str = "cane", meta: dict[str, Any] | None = None,
                 dummy_mass_fraction: float = DUMMY_MASS_FRACTION) -> str:
    """SDFormat text of ``chain`` as one model named ``name``."""
    root = ET.Element("sdf", version=SDF_VERSION)
    model = _sub(root, "model", name=name)
    _sub(model, "static", "false")
    _sub(model, "self_collide", "false")
    rows = joint_rows(chain, base="world")
    for row in rows:  # links in chain order, each created as a joint's child
        j = row.link
        pose = list(chain.nodes[j]) + list(rpy(chain.frames[j]))
        link = _sub(model, "link", name=row.child)
        _sub(link, "pose", fmt(pose))
        L, r = float(chain.lengths[j]), float(chain.diameters[j]) / 2.0
        if row.child == f"link{j}":
            _inertial(link, float(chain.masses[j]), chain.inertias[j], L / 2.0)
            for kind in ("visual", "collision"):
                g = _sub(link, kind, name=kind)
                _sub(g, "pose", fmt([0.0, 0.0, L / 2.0, 0.0, 0.0, 0.0]))
                cyl = _sub(_sub(g, "geometry"), "cylinder")
                _sub(cyl, "radius", fmt(r))
                _sub(cyl, "length", fmt(L))
        else:
            m, mom = dummy_inertial(chain, j, dummy_mass_fraction)
            _inertial(link, m, mom, 0.0)
    for row in rows:
        joint = _sub(model, "joint", name=row.name, type="revolute")
        _sub(joint, "parent", row.parent)
        _sub(joint, "child", row.child)
        _sub(joint, "pose", fmt([0.0] * 6))  # at the child link's origin (the node), in its frame
        axis = _sub(joint, "axis")
        _sub(axis, "xyz", fmt(AXES[row.axis]))
        lim = _sub(axis, "limit")  # no joint limits: SDF's own "unlimited" values
        _sub(lim, "lower", "-1e16")
        _sub(lim, "upper", "1e16")
        dyn = _sub(axis, "dynamics")
        _sub(dyn, "damping", fmt(row.damping))
        _sub(dyn, "friction", "0")
        _sub(dyn, "spring_reference", fmt(row.rest_angle))
        _sub(dyn, "spring_stiffness", fmt(row.stiffness))
    p, R = probe_local(chain)
    link = f"link{chain.push_link}"
    fr = _sub(model, "frame", name="probe", attached_to=link)
    _sub(fr, "pose", fmt(list(p) + list(rpy(R))), relative_to=link)
    ET.indent(root, "  ")
    info = {**chain_info(chain), **(meta or {})}
    head = ("<?xml version=\"1.0\"?>\n<!-- canebench export (SDFormat " + SDF_VERSION + "): pseudo-rigid-body cane "
            "chain; SI units; joint springs in <dynamics>; intermediate links link<j>_x (and _y with the twist joint) "
            f"carry {dummy_mass_fraction:g} of their link's mass and moments. Chain gravity "
            f"{fmt(chain.gravity)} m/s^2 (set it in your world). Frame 'probe': probe point, x along the probe "
            "direction.\n     canebench: " + json.dumps(info, sort_keys=True).replace("--", "- -") + " -->\n")
    return head + ET.tostring(root, encoding="unicode") + "\n"


def write_sdf(chain: Chain, path: str | Path, name: str = "cane", meta: dict[str, Any] | None = None,
              dummy_mass_fraction: float = DUMMY_MASS_FRACTION) -> Path:
    path = Path(path)
    path.write_text(chain_to_sdf(chain, name, meta, dummy_mass_fraction))
    return path
