"""Minimal reproductions of what the continuum engines do that their users
should know (README "Continuum engines"). Plain MuJoCo and Exudyn, no canebench:

    python reports/continuum_engine_findings.py

1. MuJoCo 4 1D flex, circle section: the bending stiffness it stores is
   E (pi r^4 / 4) / (l0 + l1) per vertex, the correct area moment of a solid
   circle (MuJoCo's older cable plugin was reported to use a wrong one), and a
   uniform cantilever matches the beam to the discrete rod's O(1/n^2).
2. MuJoCo's clamp ``<pin id="0 1"/>`` pins the first *edge*: on a cantilever
   whose first two points are its own, the clamp moves to the second point and
   the rod is stiff by 2n^2 / ((n-1)(2n-1)) - 1 (17 % with 10 edges, first
   order), exactly the chain closed form (reference-values sec. 5).
3. Exudyn 1.13 ObjectBeamGeometricallyExact accepts BeamSection.dampingMatrix
   without error and ignores it: the free vibration is identical with damping
   0 and 1 s x stiffness.
"""

from __future__ import annotations

import numpy as np

E, NU, RHO = 4.57e9, 0.3, 580.0


def mujoco_rod_xml(points: np.ndarray, radius: float, pin: str) -> str:
    pts = " ".join(f"{v:.9g}" for v in points.ravel())
    el = " ".join(f"{i} {i + 1}" for i in range(len(points) - 1))
    return f"""<mujoco>
  <option timestep="0.001" integrator="discrete" solver="Newton" gravity="0 0 0"><flag contact="disable"/></option>
  <worldbody>
    <flexcomp name="rod" type="direct" dim="1" radius="{radius}" mass="{RHO * np.pi * radius**2 * 1.2}"
              point="{pts}" element="{el}">
      <elasticity young="{E}" poisson="{NU}" damping="0.01"/>
      <edge equality="true" solref="0.0001 1" solimp="0.9999 0.9999 0.001 0.5 2"/>
      <contact contype="0" conaffinity="0"/>
      <pin id="{pin}"/>
    </flexcomp>
  </worldbody>
</mujoco>"""


def static_tip(xml: str, force: np.ndarray, seconds: float = 20.0) -> np.ndarray:
    """Tip displacement under a constant tip force once settled."""
    import mujoco

    m = mujoco.MjModel.from_xml_string(xml)
    d = mujoco.MjData(m)
    tip = m.nbody - 1
    while m.body(tip).name.startswith("rod_twist"):
        tip -= 1
    mujoco.mj_forward(m, d)
    x0 = d.xpos[tip].copy()
    d.xfrc_applied[tip, :3] = force
    mujoco.mj_step(m, d, nstep=int(seconds / m.opt.timestep))
    return d.xpos[tip] - x0


def finding_1_and_2() -> None:
    import mujoco

    L, r, n = 1.2, 0.006, 20
    EI = E * np.pi * r**4 / 4
    # the stored stiffness of one interior vertex
    pts = np.column_stack([np.zeros(4), np.zeros(4), [0.0, 0.1, 0.25, 0.3]])
    m = mujoco.MjModel.from_xml_string(mujoco_rod_xml(pts, r, "0 1"))
    rec = m.flex_bending[1:11]
    print(f"1. MuJoCo {mujoco.__version__} flex circle section, vertex 1 (edges 0.1 and 0.15 m): stored bending "
          f"k = {rec[4]:.6g}, E pi r^4/4 / (l0+l1) = {EI / 0.25:.6g} (pi r^4/2 would give {2 * EI / 0.25:.6g}); "
          f"torsion {rec[8]:.6g}, G J / (l0+l1) = {EI / (1 + NU) / 0.25:.6g}")
    # a uniform cantilever with a stub clamp (the cane starts at the second point)
    h = L / n
    s = np.concatenate([[-0.01 * h], np.linspace(0, L, n + 1)])
    pts = np.column_stack([np.zeros_like(s), np.zeros_like(s), s])
    P = 0.01
    w = static_tip(mujoco_rod_xml(pts, r, "0 1"), np.array([P, 0, 0]))
    k_beam = 3 * EI / L**3
    print(f"   uniform cantilever, {n} edges + a stub edge (1 % of an edge) clamped below the base: k / (3EI/L^3) = "
          f"{P / w[0] / k_beam:.5f}; the discrete rod's closed form 1/(1 + 1/(2n^2) + 1.5 stub/n) = "
          f"{1 / (1 + 1 / (2 * n * n) + 1.5 * 0.01 / n):.5f} (Voronoi chain, reference-values sec. 5, plus the stub)")
    n = 10
    s = np.linspace(0, L, n + 1)
    pts = np.column_stack([np.zeros_like(s), np.zeros_like(s), s])
    w = static_tip(mujoco_rod_xml(pts, r, "0 1"), np.array([P, 0, 0]))
    print(f"2. <pin id=\"0 1\"/> on the cantilever's own first edge, {n} edges: k / (3EI/L^3) = "
          f"{P / w[0] / k_beam:.5f}; chain clamped at the second point, 2n^2/((n-1)(2n-1)) = "
          f"{2 * n * n / ((n - 1) * (2 * n - 1)):.5f}")


def exudyn_free_vibration(section_damping: float, connector_damping: float = 0.0) -> np.ndarray:
    """Tip displacement of a 4-element Exudyn beam cantilever (d 12 mm, 1.2 m) released under a
    step load, 0.3 s in 1 ms steps; damping as the section's matrix (x stiffness, s) and/or as
    relative rotational dampers between nodes (x EI / h, s)."""
    import exudyn as exu
    from exudyn.itemInterface import (Force, GenericJoint, MarkerBodyRigid, MarkerNodeRigid, NodeRigidBodyRotVecLG,
                                      ObjectBeamGeometricallyExact, ObjectConnectorRigidBodySpringDamper,
                                      ObjectGround, SensorNode)
    from scipy.spatial.transform import Rotation

    n, d, L = 4, 0.012, 1.2
    A, I = np.pi * d**2 / 4, np.pi * d**4 / 64
    C = np.diag([E * A, E / 2.6 * A, E / 2.6 * A, E * I / 1.3, E * I, E * I])
    SC = exu.SystemContainer()
    mbs = SC.AddSystem()
    R = np.array([[0.0, 0, -1], [0, 1, 0], [1, 0, 0]])  # x axis along world z
    rv = list(Rotation.from_matrix(R).as_rotvec())
    nodes = [mbs.AddNode(NodeRigidBodyRotVecLG(referenceCoordinates=[0, 0, L * i / n] + rv)) for i in range(n + 1)]
    for i in range(n):
        sec = exu.BeamSection()
        sec.stiffnessMatrix, sec.dampingMatrix = C, section_damping * C
        sec.massPerLength, sec.inertia = RHO * A, RHO * np.diag([2 * I, I, I])
        mbs.AddObject(ObjectBeamGeometricallyExact(nodeNumbers=[nodes[i], nodes[i + 1]], length=L / n,
                                                   sectionData=sec))
        if connector_damping:
            mk = [mbs.AddMarker(MarkerNodeRigid(nodeNumber=nodes[j])) for j in (i, i + 1)]
            mbs.AddObject(ObjectConnectorRigidBodySpringDamper(
                markerNumbers=mk, stiffness=np.zeros((6, 6)),
                damping=np.diag([0, 0, 0, 1, 1, 1]) * connector_damping * E * I / (L / n)))
    g = mbs.AddObject(ObjectGround())
    HT = np.eye(4)
    HT[:3, :3] = R
    mbs.AddObject(GenericJoint(markerNumbers=[mbs.AddMarker(MarkerBodyRigid(bodyNumber=g, localHT=HT)),
                                              mbs.AddMarker(MarkerNodeRigid(nodeNumber=nodes[0]))],
                               constrainedAxes=[1] * 6))
    mbs.AddLoad(Force(markerNumber=mbs.AddMarker(MarkerNodeRigid(nodeNumber=nodes[-1])), loadVector=[0.01, 0, 0]))
    sensor = mbs.AddSensor(SensorNode(nodeNumber=nodes[-1], storeInternal=True,
                                      outputVariableType=exu.OutputVariableType.Displacement))
    mbs.Assemble()
    s = exu.SimulationSettings()
    s.solution.file.write = False
    s.timeIntegration.verboseMode = 0
    s.timeIntegration.newton.absoluteTolerance = 1e-6
    s.timeIntegration.generalizedAlpha.spectralRadius = 1.0
    s.timeIntegration.endTime, s.timeIntegration.numberOfSteps = 0.3, 300
    mbs.SolveDynamic(s)
    return np.asarray(mbs.GetSensorStoredData(sensor))[:, 1]


def finding_3() -> None:
    import exudyn as exu

    a, b = exudyn_free_vibration(0.0), exudyn_free_vibration(1.0)
    print(f"3. Exudyn {exu.__version__} ObjectBeamGeometricallyExact, step load on a cantilever, 0.3 s: tip "
          f"displacement range {np.ptp(a):.4e} m; largest difference between section damping 0 and 1 s x "
          f"stiffness: {np.max(np.abs(a - b)):.1e} m (no error, no effect)")


if __name__ == "__main__":
    finding_1_and_2()
    finding_3()
