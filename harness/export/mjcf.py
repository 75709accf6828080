"""The chain as a MuJoCo model, built with MuJoCo's ``MjSpec`` API.

One builder, :func:`chain_spec`, serves both the MuJoCo backend (which
compiles the spec in memory) and ``canebench export`` (which writes it as
MJCF with :func:`write_mjcf`). Per link: one body at the link's rest pose,
two hinge joints about the body's x then y axis (a third about z with the
twist joint) with the chain's spring stiffness, ``springref`` 0 and
damping; an explicit inertial (mass at mid-link, principal moments); a
capsule for display (mass 0: the inertial is the physics). The probe is a
site ``push`` on the probe link at the probe point, and a world site
``probe_ref`` at its rest position with its x axis along the fixed probe
direction; an actuator ``probe`` with a site transmission referenced to
``probe_ref`` has the displacement along the probe direction as its length
and applies its force along it.
"""

from __future__ import annotations

import contextlib
from pathlib import Path
from typing import Any, Iterator

import mujoco
import numpy as np

from ..model.chain import Chain
from ..model.geometry import frame_with_x

#: MuJoCo integrators by name (the MJCF attribute values)
INTEGRATORS = {
    "euler": mujoco.mjtIntegrator.mjINT_EULER,
    "rk4": mujoco.mjtIntegrator.mjINT_RK4,
    "implicit": mujoco.mjtIntegrator.mjINT_IMPLICIT,
    "implicitfast": mujoco.mjtIntegrator.mjINT_IMPLICITFAST,
    "discrete": mujoco.mjtIntegrator.mjINT_DISCRETE,
}

#: collision bits of the exported cane's geoms: they collide with ordinary
#: geoms (contype = conaffinity = 1) but never with each other (2 & 1 = 0)
CANE_CONTYPE, CANE_CONAFFINITY = 2, 1


def quat(R: np.ndarray) -> np.ndarray:
    """MuJoCo quaternion (w, x, y, z) of a rotation matrix."""
    q = np.empty(4)
    mujoco.mju_mat2Quat(q, np.ascontiguousarray(R, dtype=float).ravel())
    return q


#: time step of exported models and of the MuJoCo backend's fast protocol: with the
#: ``discrete`` integrator (springs, damping and PID gains implicit) 5 ms moves the
#: probed stiffness by <= 3.2e-4 from 1 ms on the 54 bundled trials (README, "Performance")
FAST_DT = 5e-3


def chain_spec(chain: Chain, dt: float = FAST_DT, integrator: str = "discrete", probe: str | None = "motor",
               gains: tuple[float, float, float] | None = None, contacts: bool = False,
               name: str = "cane") -> mujoco.MjSpec:
    """An ``MjSpec`` of ``chain``.

    Parameters
    ----------
    dt, integrator : float, str
        Time step (s) and integrator (``discrete``, ``implicit``, ...).
    probe : ``"motor"``, ``"pid"`` or None
        The probe actuator: a force (N) along the probe direction (``motor``,
        ctrl is the force), MuJoCo's native PID on the displacement along it
        (``pid``, ctrl is the setpoint in m; needs ``gains`` = (kp, ki, kd)),
        or none.
    contacts : bool
        False: the cane never collides (contact disabled, as the benchmark
        runs it). True: its geoms collide with ordinary geoms a user adds
        (a gripper, a probe), never with each other.
    """
    spec = mujoco.MjSpec()
    spec.modelname = name
    spec.compiler.degree = False
    spec.compiler.autolimits = True
    opt = spec.option
    opt.timestep = float(dt)
    opt.integrator = INTEGRATORS[integrator]
    opt.solver = mujoco.mjtSolver.mjSOL_NEWTON
    opt.gravity = np.asarray(chain.gravity, float)
    if not contacts:
        opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
    world = spec.worldbody
    world.add_site(name="probe_ref", pos=np.asarray(chain.push_point, float),
                   quat=quat(frame_with_x(chain.direction)))
    parent = world
    axes = [("x", (1.0, 0.0, 0.0)), ("y", (0.0, 1.0, 0.0)), ("z", (0.0, 0.0, 1.0))][: chain.joints_per_link]
    kbits = (CANE_CONTYPE, CANE_CONAFFINITY) if contacts else (0, 0)
    for j in range(chain.n_links):
        R, p = chain.relative_pose(j)
        body = parent.add_body(name=f"link{j}", pos=p, quat=quat(R))
        stiff = [chain.stiffness[j], chain.stiffness[j]]
        if chain.twist_stiffness is not None:
            stiff.append(chain.twist_stiffness[j])
        for (ax, vec), k in zip(axes, stiff):
            body.add_joint(name=f"j{j}{ax}", type=mujoco.mjtJoint.mjJNT_HINGE, axis=vec,
                           stiffness=[float(k), 0.0, 0.0], damping=[float(chain.damping), 0.0, 0.0], springref=0.0)
        L, r = float(chain.lengths[j]), float(chain.diameters[j]) / 2.0
        body.explicitinertial = True
        body.ipos = [0.0, 0.0, L / 2.0]
        body.mass = float(chain.masses[j])
        body.inertia = np.asarray(chain.inertias[j], float)
        body.add_geom(type=mujoco.mjtGeom.mjGEOM_CAPSULE, fromto=[0.0, 0.0, 0.0, 0.0, 0.0, L],
                      size=[r, 0.0, 0.0], contype=kbits[0], conaffinity=kbits[1], mass=0.0)
        if j == chain.push_link:
            body.add_site(name="push", pos=chain.local(j, chain.push_point))
        parent = body
    if probe is not None:
        act = spec.add_actuator(name="probe", trntype=mujoco.mjtTrn.mjTRN_SITE, target="push", refsite="probe_ref",
                                gear=[1.0, 0.0, 0.0, 0.0, 0.0, 0.0])
        if probe == "pid":
            if gains is None:
                raise ValueError("a pid probe needs gains (kp, ki, kd)")
            kp, ki, kd = (float(g) for g in gains)
            act.set_to_pid(kp=kp, kv=kd, ki=ki, ctrlspec=1)  # ctrlspec 1: the control is the position setpoint
        elif probe == "motor":
            act.set_to_motor()
        else:
            raise ValueError(f"unknown probe actuator {probe!r} (motor, pid or None)")
    return spec


@contextlib.contextmanager
def full_precision() -> Iterator[bool]:
    """MuJoCo's XML writer at 17 significant digits (exact doubles) instead of 6.

    MuJoCo has no public switch; its test helper's thread-local setting
    ``_mjPRIVATE__set_xml_precision`` (an int in MuJoCo 4) is used when
    present and restored afterwards. Yields whether it applied; without it
    the file is MuJoCo's usual 6-digit XML (relative error ~1e-6).
    """
    lib = None
    if mujoco.__version__.split(".")[0] == "4":
        try:
            import ctypes
            import glob
            import os

            lib = ctypes.CDLL(sorted(glob.glob(os.path.join(os.path.dirname(mujoco.__file__), "libmujoco.so*")))[0])
            get, put = lib._mjPRIVATE__get_xml_precision, lib._mjPRIVATE__set_xml_precision
            get.restype, get.argtypes, put.argtypes = ctypes.c_int, [], [ctypes.c_int]
            old = get()
            if not 1 <= old <= 20:
                lib = None
        except (OSError, AttributeError, IndexError):
            lib = None
    if lib is None:
        yield False
        return
    put(17)
    try:
        yield True
    finally:
        put(old)


def chain_model(chain: Chain, **kwargs: Any) -> mujoco.MjModel:
    """The compiled model of :func:`chain_spec` (same arguments)."""
    return chain_spec(chain, **kwargs).compile()


def to_mjcf(chain: Chain, meta: dict[str, Any] | None = None, **kwargs: Any) -> str:
    """MJCF text of the exported cane: 5 ms ``discrete`` integrator (MuJoCo >= 4.0; with it
    springs, damping and a ``pid`` actuator's gains are implicit; an explicit controller
    driving the ``motor`` with stiff gains needs a smaller ``dt``),
    a ``probe`` motor (ctrl = force in N along the probe direction), geoms
    that collide with a user's geoms; the chain's provenance and ``meta`` go
    into a ``canebench`` custom text element (JSON, ``model.text_data``)."""
    kwargs.setdefault("contacts", True)
    spec = chain_spec(chain, **kwargs)
    import json

    from .common import chain_info

    spec.add_text(name="canebench", data=json.dumps({**chain_info(chain), **(meta or {})}, sort_keys=True))
    spec.compile()  # to_xml needs a compiled spec; also validates
    with full_precision():
        xml = spec.to_xml()
    head = ("<!-- canebench export: a pseudo-rigid-body cane chain. Links: bodies link0..; joints jNx, jNy"
            + (", jNz" if chain.twist_stiffness is not None else "")
            + " with torsional springs (stiffness, springref 0) and damping; site 'push' is the probe point, "
              "world site 'probe_ref' its rest position with x along the probe direction; actuator 'probe' "
              "pushes along it (ctrl = force, N). SI units. -->\n")
    return head + xml


def write_mjcf(chain: Chain, path: str | Path, meta: dict[str, Any] | None = None, **kwargs: Any) -> Path:
    path = Path(path)
    path.write_text(to_mjcf(chain, meta, **kwargs))
    return path
