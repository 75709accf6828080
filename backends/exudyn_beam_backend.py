"""Exudyn beam backend: the cane's continuum as Exudyn's geometrically exact
beam (``ObjectBeamGeometricallyExact``: 2-node, shear-deformable, SE(3)
interpolation), integrated in time and probed by the harness protocol.

It compiles ``chain.rod`` (not the chain's links), as ``mujoco_rod`` does:

* **Nodes**: ``n_elements`` straight elements over the whole cane, uniform
  on either side of a node exactly at the probe
  (:func:`canebench.backends.continuum.stations`), each node a
  ``NodeRigidBodyRotVecLG`` (rotation vector, Lie-group updates; no
  Euler-parameter constraint) whose x axis is the mean of its two
  elements' directions, the cross-section axes carried along the cane by
  parallel transport (no reference twist). The element's reference strains
  are those of this rest configuration, so the rest shape is stress-free.
* **Taper**: per element, the section at the element's middle:
  EI = E pi d^4 / 64 (both axes), GJ = EI / (1 + nu) (solid circle, G =
  E / (2 (1 + nu)), J = 2 I), EA = E A and shear kappa G A with Cowper's
  kappa = 6 (1 + nu) / (7 + 6 nu): the physical section (the element's
  dynamic solve converges with it; the 1e4 EI penalty used by the static
  cross-check in tests/test_rod_exudyn.py softens a 1.2 m uniform cantilever
  by 2e-4 in shear). Mass rho A and rotary inertia rho diag(2I, I, I) per
  length; gravity as dead loads on the nodes (each node half of its
  elements' weight). Damping: ObjectBeamGeometricallyExact ignores its
  section's damping matrix (silently: the free vibration of a cantilever is
  identical with 0 and 1 s x stiffness, ``tests/test_continuum.py``), so
  every element carries a relative rotational damper between its nodes,
  ``RAYLEIGH_DAMPING`` x EI / h about the bending axes and x GJ / h about
  its axis (stiffness-proportional, as the MuJoCo rod); without it the
  probe's samples carried an undamped ringing (a 0.3 mm-equivalent force
  offset on the uniform cantilever).
* **Clamp**: a ``GenericJoint`` (all six relative coordinates locked)
  between the ground and the base node, in the base node's frame.
* **Probe**: built, as the ``exudyn`` chain backend, in a *probe frame*
  whose x axis is the probe direction (geometry and gravity rotated into
  it). ``fast`` (engine PID): P and D implicit as a ``CartesianSpringDamper``
  (Kp, Kd along x) between a ground marker at the probe's rest position and
  the probe node; the integral accumulated per step in a pre-step callback
  and folded into the connector's offset. ``paper`` (harness PID): the
  harness PID in the pre-step callback, an explicit ``LoadForceVector``.
* **Integrator**: GeneralizedAlpha, one ``MainSolverImplicitSecondOrder``
  per trial initialised once and advanced with ``SolveSteps`` (continuous
  integration); ``fast``: ``FAST_DT`` with spectral radius
  ``FAST_SPECTRAL_RADIUS``; ``paper``: the protocol's 25 us, radius 1.
  Newton's absolute tolerance is ``NEWTON_ABSOLUTE_TOLERANCE`` (1e-6 in N and
  N m): with the physical section the residual's round-off floor is
  ~1e-8-1e-7, and below it (Exudyn's default 1e-10) the step-size control
  shrinks the step until it fails. On b1c1t1 the stiffness changes by 5e-7
  from 1 ms to 10 ms steps and by 2e-7 from Newton tolerance 1e-6 to 1e-3.

Measured (``canebench converge --continuum``, 54 bundled canes, small push):
-0.031 % median, 0.097 % worst against the beam at the default 20 elements,
no longer changing with the mesh (the Timoshenko section's shear and
extension); a full trial costs ~7x the MuJoCo chain.
"""

from __future__ import annotations

from typing import Any

import exudyn as exu
import numpy as np
from exudyn.itemInterface import (
    Force,
    GenericJoint,
    MarkerBodyRigid,
    MarkerNodePosition,
    MarkerNodeRigid,
    NodeRigidBodyRotVecLG,
    ObjectConnectorRigidBodySpringDamper,
    ObjectBeamGeometricallyExact,
    ObjectGround,
)
from scipy.spatial.transform import Rotation

from canebench.model.chain import Chain
from canebench.model.geometry import frame_with_x
from canebench.probe.protocol import Protocol

from . import continuum as cont
from .base import DynamicBackend
from .exudyn_backend import ExudynProbeLoop

#: default element count over the whole cane (chosen from ``canebench converge``; README "Continuum engines")
ELEMENTS = 20
#: time step of the fast (engine PID) configuration, s
FAST_DT = 1e-2
#: GeneralizedAlpha spectral radius of the fast configuration
FAST_SPECTRAL_RADIUS = 0.8
#: Newton relative tolerance of the fast configuration
FAST_NEWTON_RELATIVE_TOLERANCE = 1e-6
#: Newton absolute tolerance (residual norm, N and N m): above the round-off floor of the physical section
NEWTON_ABSOLUTE_TOLERANCE = 1e-6
#: Rayleigh (stiffness-proportional) damping coefficient, s
RAYLEIGH_DAMPING = 0.01


def node_frames(points: np.ndarray) -> np.ndarray:
    """(n+1, 3, 3) node frames (columns x, y, z): x along the mean direction of
    the node's elements, y and z carried from the base by parallel transport."""
    d = np.diff(points, axis=0)
    t_el = d / np.linalg.norm(d, axis=1, keepdims=True)
    t = np.vstack([t_el[:1], t_el[:-1] + t_el[1:], t_el[-1:]])
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    frames = np.empty((len(points), 3, 3))
    frames[0] = frame_with_x(t[0])
    for i in range(1, len(points)):
        y = frames[i - 1][:, 1]
        y = y - (y @ t[i]) * t[i]
        y /= np.linalg.norm(y)
        frames[i] = np.column_stack([t[i], y, np.cross(t[i], y)])
    return frames


def section(g, s_mid: float) -> exu.BeamSection:
    """The solid circular section of the cane at arc length ``s_mid``."""
    d = float(g.diameter(np.array([s_mid]))[0])
    E, nu = g.modulus, g.poisson_ratio
    A, I = np.pi * d**2 / 4, np.pi * d**4 / 64
    G = E / (2 * (1 + nu))
    kappa = 6 * (1 + nu) / (7 + 6 * nu)
    C = np.diag([E * A, kappa * G * A, kappa * G * A, G * 2 * I, E * I, E * I])
    sec = exu.BeamSection()
    sec.stiffnessMatrix = C
    sec.massPerLength = g.density * A
    sec.inertia = g.density * np.diag([2 * I, I, I])
    return sec


class ExudynBeamSimulation(ExudynProbeLoop):
    """The cane's continuum as geometrically exact beam elements, advanced by a persistent implicit solver."""

    fast_spectral_radius = FAST_SPECTRAL_RADIUS
    fast_newton_rtol = FAST_NEWTON_RELATIVE_TOLERANCE

    def __init__(self, chain: Chain, proto: Protocol, native: bool, n_elements: int = ELEMENTS,
                 dt: float | None = None) -> None:
        self.native_pid = native
        self.dt = float(dt or (FAST_DT if native else proto.dt))
        self.gains = (proto.kp, proto.ki, proto.kd)
        g = cont.rod_of(chain)
        st = cont.stations(chain, n_elements)
        self.stations = st
        Rw = frame_with_x(chain.direction).T  # world -> probe frame (x along the probe)
        P = st.points @ Rw.T
        F = np.einsum("ij,njk->nik", Rw, node_frames(st.points))
        self.SC = exu.SystemContainer()
        mbs = self.mbs = self.SC.AddSystem()
        nodes = [mbs.AddNode(NodeRigidBodyRotVecLG(
            referenceCoordinates=[*map(float, P[i]), *map(float, Rotation.from_matrix(F[i]).as_rotvec())]))
            for i in range(len(P))]
        h = np.linalg.norm(np.diff(P, axis=0), axis=1)
        mids = 0.5 * (st.s[:-1] + st.s[1:])
        for i in range(len(h)):
            mbs.AddObject(ObjectBeamGeometricallyExact(nodeNumbers=[nodes[i], nodes[i + 1]], length=float(h[i]),
                                                       sectionData=section(g, float(mids[i]))))
        # ObjectBeamGeometricallyExact ignores its section's damping matrix (measured: the free vibration of a
        # cantilever is the same with damping 0, 0.01 and 1 s x stiffness), so the material damping is a
        # relative rotational damper between the two nodes of every element: beta EI / h about the bending
        # axes, beta GJ / h about the element axis (Rayleigh, stiffness-proportional, as the MuJoCo rod)
        if RAYLEIGH_DAMPING > 0:
            rig = [mbs.AddMarker(MarkerNodeRigid(nodeNumber=nd)) for nd in nodes]
            for i in range(len(h)):
                d = float(g.diameter(np.array([mids[i]]))[0])
                EI = g.modulus * np.pi * d**4 / 64
                c = RAYLEIGH_DAMPING * EI / h[i]
                D = np.diag([0.0, 0.0, 0.0, c / (1 + g.poisson_ratio), c, c])
                mbs.AddObject(ObjectConnectorRigidBodySpringDamper(markerNumbers=[rig[i], rig[i + 1]],
                                                                   stiffness=np.zeros((6, 6)), damping=D))
        ground = mbs.AddObject(ObjectGround())
        HT = np.eye(4)  # the clamp's frame on the ground: the base node's rest frame, at the base
        HT[:3, :3], HT[:3, 3] = F[0], P[0]
        m_base = mbs.AddMarker(MarkerBodyRigid(bodyNumber=ground, localHT=HT))
        m_n0 = mbs.AddMarker(MarkerNodeRigid(nodeNumber=nodes[0]))
        mbs.AddObject(GenericJoint(markerNumbers=[m_base, m_n0], constrainedAxes=[1] * 6))
        grav = Rw @ np.asarray(chain.gravity, float)
        if np.any(grav):  # dead loads: half of each element's weight on each of its nodes
            m_el = g.density * np.pi * g.diameter(mids) ** 2 / 4 * h
            m_node = np.zeros(len(P))
            m_node[:-1] += m_el / 2
            m_node[1:] += m_el / 2
            for i in range(1, len(P)):
                mk = mbs.AddMarker(MarkerNodePosition(nodeNumber=nodes[i]))
                mbs.AddLoad(Force(markerNumber=mk, loadVector=list(map(float, m_node[i] * grav))))
        self.node = nodes[st.push]
        self.marker = mbs.AddMarker(MarkerNodePosition(nodeNumber=self.node))
        self.x0 = float(P[st.push][0])
        mg = mbs.AddMarker(MarkerBodyRigid(bodyNumber=ground, localPosition=list(map(float, P[st.push])))) \
            if native else None
        self._attach_probe(mg)
        s = self._settings(native)
        s.linearSolver.solverType = exu.LinearSolverType.EigenSparse
        s.timeIntegration.newton.absoluteTolerance = NEWTON_ABSOLUTE_TOLERANCE
        self._start_solver()

    def _output(self, kind: Any) -> Any:
        return self.mbs.GetNodeOutput(self.node, kind)


class ExudynBeamBackend(DynamicBackend):
    """Exudyn's geometrically exact beam of the cane's continuum."""

    name = "exudyn_beam"
    tags = ("dynamic", "continuum", "connector-pd")
    engine_module = "exudyn"
    supports_twist = True  # a continuum: torsion always (GJ = EI / (1 + nu)), whatever the chain's joints

    def __init__(self, n_elements: int = ELEMENTS, dt: float | None = None) -> None:
        self.n_elements = int(n_elements)
        self.dt = dt

    def settings(self, proto: Protocol) -> dict[str, Any]:
        fast = proto.controller == "engine"
        return {
            "engine": "exudyn",
            "version": self.engine_version(),
            "model": (f"ObjectBeamGeometricallyExact, {self.n_elements} elements, section at each element's "
                      "middle (physical EA, kappa GA, GJ, EI), RotVecLG nodes, GenericJoint clamp"),
            "integrator": (f"GeneralizedAlpha (spectral radius {FAST_SPECTRAL_RADIUS if fast else 1.0:g}), "
                           "modified Newton, EigenSparse"),
            "solver": "one MainSolverImplicitSecondOrder per trial, initialised once, advanced with SolveSteps",
            "dt": self.dt or (FAST_DT if fast else proto.dt),
            "substeps": 1,
            "springs": "continuum: beam section stiffness (implicit)",
            "damping": f"section damping = {RAYLEIGH_DAMPING:g} s x section stiffness",
            "pid": ("P and D implicit as a CartesianSpringDamper along the probe; integral explicit per step, "
                    "folded into the connector's offset" if fast
                    else "harness PID in a pre-step callback, explicit LoadForceVector"),
            "why": "continuum engine compared with the beam reference (the chain's links are ignored)",
        }

    def build(self, chain: Chain, proto: Protocol) -> ExudynBeamSimulation:
        return ExudynBeamSimulation(chain, proto, proto.controller == "engine", self.n_elements, self.dt)
