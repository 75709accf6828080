"""MuJoCo rod backend: the cane's continuum as a MuJoCo 1D elastic flex
(discrete elastic rod: bending and torsion), probed by the harness protocol.

It compiles ``chain.rod`` (the smoothed centreline, the fitted diameter
line, E, density, Poisson ratio; not the chain's links) into a flex built
with ``MjSpec`` (no XML template), the raw-flex equivalent of
``<flexcomp type="direct" dim="1">`` with ``<elasticity young poisson
damping/>``, ``section="circle"`` and the first edge clamped:

* **Nodes**: ``n_elements`` straight edges over the whole cane, uniform on
  either side of a vertex placed exactly at the probe's arc length
  (:func:`canebench.backends.continuum.stations`); every free vertex is a
  body with three slide joints, every unclamped edge a twist body with a
  hinge named ``rod_twist_1 .. rod_twist_{n-1}``, ``rod_twist`` (the names
  MuJoCo binds to the edges' material frames, as ``flexcomp`` generates
  them). Edge lengths are held by the flex's edge equality (the rod has no
  stretching energy); its ``solref`` is ``EDGE_SOLREF`` (stiff: discrete
  integrates equality rows implicitly at any time constant).
* **Clamp**: MuJoCo clamps a rod by pinning the two points of its first
  edge. Pinning the cane's base and its second vertex would fix the whole
  first element, moving the clamp to the second vertex: measured on the
  uniform cantilever, the compliance is then exactly the chain's
  (n-1)(2n-1)/(2n^2) of the beam's (17 % stiff at 10 elements, first
  order). Instead the clamped edge is a *stub* of length ``STUB`` x h
  below the base along the base tangent, so the cane's base is the first
  free-to-bend vertex; with the per-vertex taper its rotational stiffness is
  exactly the beam-consistent 2 EI / h of the clamp's half-element (with
  MuJoCo's own EI / (l0 + l1), 2 EI / (stub + h)). The rod then converges at
  second order: 1 + 1/(2n^2) of the beam's compliance on the uniform
  cantilever (the Voronoi chain of reference-values sec. 5).
* **Taper**: a MuJoCo flex has one radius, hence one EI for every vertex.
  ``taper="per-vertex"`` (default) compiles the flex with one radius and
  then sets every vertex's bending and torsional stiffness in
  ``mjModel.flex_bending`` to the beam-consistent value of the tapered
  section, 1 / (2 int ds/EI(s)) over the vertex's dual segment (torsion the
  same with GJ = EI / (1 + nu)), which is what MuJoCo stores for a uniform
  rod (EI / (l0 + l1)). The layout of ``flex_bending`` is not documented:
  before writing, the build checks that every record holds the vertex
  triplet and exactly the stiffnesses MuJoCo's documented formula gives
  for the compiled radius, and fails the build if not (a MuJoCo upgrade that
  changes the layout fails loudly, never silently). ``taper="uniform"``
  uses only the documented API: one radius, the diameter line at the middle
  of the probed span; its accuracy cost is measured by ``canebench
  converge`` (README "Continuum engines"). Masses are lumped per vertex from
  the tapered section in both cases, twist inertia per edge.
* **Probe**: the vertex at the probe carries a site; the probe actuator is a
  site transmission referenced to a world site at the probe point's rest
  position with its x axis along the probe direction (as in the ``mujoco``
  chain backend), so actuator length is the displacement along that fixed
  direction.
* **Integrator**: ``discrete`` (the only MuJoCo integrator that integrates
  rod elasticity implicitly), Newton solver. ``fast``: the native ``pid``
  actuator (protocol gains, implicit) at the protocol's 1 ms. ``paper``:
  harness PID as an explicit ``motor`` force at 25 us.
* **Damping**: Rayleigh ``RAYLEIGH_DAMPING`` (s) on the flex elasticity (the
  chain's 0.15 N m s/rad over its typical joint stiffness is of that order);
  it sets how fast each step settles, not the sampled force.

Measured (``canebench converge --continuum``, 54 bundled canes, small push):
-0.11 % median, 0.18 % worst against the beam at the default 40 edges
(0.78 % at 20, 0.057 % at 80); one documented radius instead of the
per-vertex taper: -37 % median; the first-edge clamp: +3.1 % median. A full
trial costs ~23x the MuJoCo chain (README "Continuum engines").
"""

from __future__ import annotations

from typing import Any

import mujoco
import numpy as np

from canebench.model.chain import Chain
from canebench.model.geometry import frame_with_x
from canebench.probe.protocol import Protocol

from . import continuum as cont
from .base import DynamicBackend, Simulation

#: default element count over the whole cane (chosen from ``canebench converge``; README "Continuum engines")
ELEMENTS = 40
#: length of the clamped stub edge below the base, as a fraction of the element length
STUB = 0.01
#: Rayleigh damping coefficient of the flex elasticity (s)
RAYLEIGH_DAMPING = 0.01
#: solref of the edge-length equality: time constant (s) and damping ratio
EDGE_SOLREF = (1e-4, 1.0)
#: solimp of the edge-length equality (impedance near 1: a hard constraint)
EDGE_SOLIMP = (0.9999, 0.9999, 0.001, 0.5, 2.0)
TAPERS = ("per-vertex", "uniform")
CLAMPS = ("stub", "first-edge")
FLEX = "rod"


class FlexLayoutError(RuntimeError):
    """``mjModel.flex_bending`` does not hold what the per-vertex taper expects (MuJoCo changed it)."""


def _twist_names(n_edges: int) -> list[str]:
    """Twist joint names of edges 1..n-1 (edge 0 is clamped): flexcomp's naming."""
    return [f"{FLEX}_twist_{e}" if e < n_edges - 1 else f"{FLEX}_twist" for e in range(1, n_edges)]


def build_spec(chain: Chain, dt: float, native_pid: bool, gains: tuple[float, float, float],
               n_elements: int = ELEMENTS, taper: str = "per-vertex",
               clamp: str = "stub") -> tuple[mujoco.MjSpec, dict[str, Any]]:
    """The MjSpec of ``chain``'s continuum and what the build needs afterwards.

    ``clamp="stub"`` (default): rod vertices [stub, base, stations 1..n], the
    stub edge clamped; ``clamp="first-edge"``: rod vertices = stations 0..n,
    the cane's first element clamped (MuJoCo's plain ``<pin id="0 1"/>`` on
    the cane; kept to measure what it costs).
    """
    if taper not in TAPERS:
        raise ValueError(f"taper must be one of {TAPERS}, got {taper!r}")
    if clamp not in CLAMPS:
        raise ValueError(f"clamp must be one of {CLAMPS}, got {clamp!r}")
    g = cont.rod_of(chain)
    st = cont.stations(chain, n_elements)
    h = st.lengths
    t0 = st.tangents[0]
    if clamp == "stub":  # rod vertices: [stub, base, stations 1..n]; edge 0 is the clamped stub
        pts = np.vstack([st.points[0] - STUB * h[0] * t0, st.points])
        first_free = 1  # first station with its own body
    else:  # rod vertices: stations 0..n; edge 0 is the cane's first element
        pts = st.points.copy()
        first_free = 2
    off = 1 if clamp == "stub" else 0  # rod edge e is station element e - off
    n_edges = len(pts) - 1
    if taper == "uniform":
        radius = float(g.diameter(np.array([0.5 * chain.meta["s_push"]]))[0]) / 2
    else:
        radius = float(g.diameter(np.array([st.s[st.push]]))[0]) / 2  # nominal; stiffnesses are set per vertex
    m_el = cont.element_mass(g, st)
    if taper == "uniform":
        m_el = g.density * np.pi * radius**2 * (st.s[1:] - st.s[:-1])
    m_vert = np.zeros(len(st.s))
    m_vert[:-1] += m_el / 2
    m_vert[1:] += m_el / 2

    spec = mujoco.MjSpec()
    spec.modelname = "cane_rod"
    o = spec.option
    o.timestep = dt
    o.integrator = mujoco.mjtIntegrator.mjINT_DISCRETE
    o.solver = mujoco.mjtSolver.mjSOL_NEWTON
    o.gravity = list(map(float, chain.gravity))
    o.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
    world = spec.worldbody
    world.add_site(name="probe_ref", pos=list(map(float, chain.push_point)),
                   quat=list(_quat(frame_with_x(chain.direction))))
    vertbody = [world.name or "world"] * 2
    vert = [*pts[0], *pts[1]]
    probe_body = None
    for i in range(first_free, len(st.s)):  # station i is rod vertex i + off
        b = world.add_body(name=f"v{i}", pos=list(map(float, st.points[i])))
        b.explicitinertial = True
        b.mass = float(m_vert[i])
        b.inertia = [1e-12] * 3  # point mass: a slide-jointed body never rotates
        for ax in np.eye(3):
            b.add_joint(type=mujoco.mjtJoint.mjJNT_SLIDE, axis=list(ax))
        vertbody.append(b.name)
        vert += [0.0, 0.0, 0.0]
        if i == st.push:
            probe_body = b
    if probe_body is None:
        raise ValueError("the probe is on the clamped edge (s_push at the base, or on the first element with "
                         "clamp='first-edge'): nothing to push")
    probe_body.add_site(name="push", pos=[0.0, 0.0, 0.0])
    # twist bodies of edges 1..n_edges-1 (rod edge e is station element e - off)
    d_mid = g.diameter(0.5 * (st.s[:-1] + st.s[1:])) if taper == "per-vertex" else np.full(len(h), 2 * radius)
    for e, name in enumerate(_twist_names(n_edges), start=1):
        b = world.add_body(name=name)
        b.explicitinertial = True
        b.mass = 1e-9
        polar = 0.5 * m_el[e - off] * (d_mid[e - off] / 2) ** 2
        b.inertia = [polar] * 3
        b.add_joint(name=name, type=mujoco.mjtJoint.mjJNT_HINGE, axis=[1.0, 0.0, 0.0])
    f = spec.add_flex()
    f.name = FLEX
    f.dim = 1
    f.radius = radius
    f.vertbody = vertbody
    f.vert = vert
    f.elem = list(np.column_stack([np.arange(n_edges), np.arange(1, n_edges + 1)]).ravel().astype(int))
    f.young = float(g.modulus)
    f.poisson = float(g.poisson_ratio)
    f.damping = RAYLEIGH_DAMPING
    f.contype = 0
    f.conaffinity = 0
    eq = spec.add_equality(type=mujoco.mjtEq.mjEQ_FLEX, name1=FLEX)
    eq.solref = list(EDGE_SOLREF)
    eq.solimp = list(EDGE_SOLIMP)
    kp, ki, kd = gains
    if native_pid:
        a = spec.add_actuator(name="probe", target="push", refsite="probe_ref",
                              trntype=mujoco.mjtTrn.mjTRN_SITE, gear=[1, 0, 0, 0, 0, 0])
        # the chain backend's <pid kp ki kv input="pos"/>: ctrlspec 1 is the "pos" input signature (what the
        # MJCF parser stores for it; the compiled actuator is identical, tests/test_continuum.py checks)
        a.set_to_pid(kp=kp, ki=ki, kv=kd, ctrlspec=1)
    else:
        spec.add_actuator(name="probe", target="push", refsite="probe_ref", trntype=mujoco.mjtTrn.mjTRN_SITE,
                          gear=[1, 0, 0, 0, 0, 0]).set_to_motor()
    info = {"stations": st, "radius": radius, "taper": taper, "n_edges": n_edges, "rod_points": pts, "clamp": clamp}
    return spec, info


def _quat(R: np.ndarray) -> np.ndarray:
    q = np.empty(4)
    mujoco.mju_mat2Quat(q, np.ascontiguousarray(R).ravel())
    return q


#: record length and the positions of (vertex triplet, bending k, torsion k) in ``flex_bending``
_REC, _V, _KB, _KT = 10, slice(0, 3), 4, 8


def set_vertex_stiffness(m: mujoco.MjModel, chain: Chain, info: dict[str, Any]) -> np.ndarray:
    """Write the tapered section's beam-consistent stiffness into every interior vertex.

    Checks first that ``flex_bending`` holds, per interior vertex v = 1..n-1
    in order, the record [v-1, v, v+1, ., EI/(l0+l1), ., ., ., GJ/(l0+l1), .]
    for the compiled radius (MuJoCo's documented stiffness formula); raises
    :class:`FlexLayoutError` otherwise. Returns the bending k written.
    """
    g = cont.rod_of(chain)
    st, r = info["stations"], info["radius"]
    pts = info["rod_points"]
    nv = len(pts)
    fid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_FLEX, FLEX)
    adr = int(m.flex_bendingadr[fid])
    n_rec = nv - 2
    count = m.flex_bending[adr]
    recs = np.asarray(m.flex_bending[adr + 1: adr + 1 + _REC * n_rec]).reshape(-1, _REC) \
        if m.nflexbending >= adr + 1 + _REC * n_rec else None
    l = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    EI0 = g.modulus * np.pi * r**4 / 4
    GJ0 = EI0 / (1 + g.poisson_ratio)  # G (2 I): J = pi r^4 / 2
    kb0, kt0 = EI0 / (l[:-1] + l[1:]), GJ0 / (l[:-1] + l[1:])
    ok = (recs is not None and count == n_rec
          and np.array_equal(recs[:, _V], np.column_stack([np.arange(n_rec), np.arange(1, n_rec + 1),
                                                            np.arange(2, n_rec + 2)]))
          and np.allclose(recs[:, _KB], kb0, rtol=1e-9) and np.allclose(recs[:, _KT], kt0, rtol=1e-9))
    if not ok:
        raise FlexLayoutError(
            f"mjModel.flex_bending of MuJoCo {mujoco.__version__} does not hold the records the per-vertex taper "
            "writes (vertex triplet, EI/(l0+l1), GJ/(l0+l1)); use taper='uniform' or update set_vertex_stiffness")
    # stub: interior vertex v = 1 is the cane's base (dual segment [0, h0/2]), vertex v is station v - 1;
    # first-edge: interior vertex v is station v (1..n-1)
    comp = cont.dual_compliance(g, st)  # stations 0..n-1
    if info["clamp"] != "stub":
        comp = comp[1:]
    kb = 1.0 / (2.0 * comp)
    kt = kb / (1.0 + g.poisson_ratio)
    base = adr + 1
    m.flex_bending[base + _KB: base + _REC * n_rec: _REC] = kb
    m.flex_bending[base + _KT: base + _REC * n_rec: _REC] = kt
    return kb


class MujocoRodSimulation(Simulation):
    def __init__(self, chain: Chain, proto: Protocol, native: bool, n_elements: int = ELEMENTS,
                 taper: str = "per-vertex", clamp: str = "stub") -> None:
        self.native_pid = native
        self.dt = proto.dt
        self.spec, self.info = build_spec(chain, proto.dt, native, (proto.kp, proto.ki, proto.kd), n_elements, taper,
                                          clamp)
        self.m = self.spec.compile()
        if taper == "per-vertex":
            set_vertex_stiffness(self.m, chain, self.info)
        self.d = mujoco.MjData(self.m)
        mujoco.mj_forward(self.m, self.d)
        self._stale = False  # state changed since the actuator length/velocity were computed

    def read(self) -> tuple[float, float]:
        if self._stale:  # mj_step leaves the previous state's kinematics: recompute for the new state
            mujoco.mj_fwdPosition(self.m, self.d)
            mujoco.mj_fwdVelocity(self.m, self.d)
            self._stale = False
        return float(self.d.actuator_length[0]), float(self.d.actuator_velocity[0])

    def step(self, force: float) -> None:
        # the harness evaluated ``force`` from the state read before this step: an explicit force over the step
        self.d.ctrl[0] = force
        mujoco.mj_step(self.m, self.d)
        self._stale = True

    def set_setpoint(self, setpoint: float) -> None:
        self.d.ctrl[0] = setpoint

    def advance(self, n_steps: int) -> None:
        mujoco.mj_step(self.m, self.d, nstep=int(n_steps))
        self._stale = True

    def force(self) -> float:
        mujoco.mj_forward(self.m, self.d)
        self._stale = False
        return float(self.d.actuator_force[0])

    def health(self) -> str | None:
        w = self.d.warning
        for kind in (mujoco.mjtWarning.mjWARN_BADQACC, mujoco.mjtWarning.mjWARN_BADQVEL,
                     mujoco.mjtWarning.mjWARN_BADQPOS):
            if w[int(kind)].number > 0:
                return f"MuJoCo {kind.name} warning (the engine reset the state)"
        return None


class MujocoRodBackend(DynamicBackend):
    """MuJoCo 1D elastic flex (discrete elastic rod) of the cane's continuum."""

    name = "mujoco_rod"
    tags = ("dynamic", "continuum", "native-pid")
    engine_module = "mujoco"
    supports_twist = True  # a continuum: torsion always (GJ = EI / (1 + nu)), whatever the chain's joints

    def __init__(self, n_elements: int = ELEMENTS, taper: str = "per-vertex", clamp: str = "stub") -> None:
        if taper not in TAPERS:
            raise ValueError(f"taper must be one of {TAPERS}, got {taper!r}")
        if clamp not in CLAMPS:
            raise ValueError(f"clamp must be one of {CLAMPS}, got {clamp!r}")
        self.n_elements = int(n_elements)
        self.taper = taper
        self.clamp = clamp

    def settings(self, proto: Protocol) -> dict[str, Any]:
        native = proto.controller == "engine"
        return {
            "engine": "mujoco",
            "version": mujoco.__version__,
            "model": (f"1D elastic flex (discrete elastic rod, circle section), {self.n_elements} edges, clamp "
                      + (f"on a stub edge ({STUB:g} h)" if self.clamp == "stub" else "on the first element")
                      + f", taper {self.taper}"),
            "integrator": "discrete",
            "solver": "Newton",
            "dt": proto.dt,
            "substeps": 1,
            "springs": "flex elasticity (bending + torsion), implicit under discrete",
            "damping": f"Rayleigh {RAYLEIGH_DAMPING:g} s on the flex elasticity",
            "constraints": f"edge-length equality, solref {EDGE_SOLREF}, solimp {EDGE_SOLIMP[:2]}",
            "pid": "native pid actuator, implicit gains" if native else "harness PID, explicit motor force",
            "why": "continuum engine compared with the beam reference (the chain's links are ignored)",
        }

    def build(self, chain: Chain, proto: Protocol) -> MujocoRodSimulation:
        return MujocoRodSimulation(chain, proto, proto.controller == "engine", self.n_elements, self.taper,
                                   self.clamp)
