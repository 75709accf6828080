"""Cross-check of the beam reference against Exudyn's geometrically exact
beam element (ObjectBeamGeometricallyExact: 2-node, shear-deformable,
Lie-group strains) on bundled canes, small deflection, gravity off.

Exudyn's model here: nodes (Euler-parameter rigid nodes) on the rod's rest
centreline, each with its x axis along the rest tangent; per element the
section at its midpoint: EI_y = EI_z = EI, GJ = EI/(1+nu), and axial/shear
stiffness 1e4 EI (near-inextensible, near-unshearable, i.e. Kirchhoff; the
element's static solve does not converge with the physical E A here). Its
own discretization error is second order: measured 0.9 %, 0.39 %, 0.11 % at
50, 100, 200 elements on b1c1t1; hence 200 elements and a 0.3 % tolerance.
"""

import numpy as np
import pytest

from canebench.backends.beam_backend import BeamStatic, rod_spec
from canebench.model.chain import build_chain
from canebench.model.config import ModelConfig
from canebench.model.geometry import frame_with_x

exu = pytest.importorskip("exudyn")
from exudyn.itemInterface import (  # noqa: E402
    Force,
    GenericJoint,
    MarkerBodyRigid,
    MarkerNodeRigid,
    NodeRigidBodyEP,
    ObjectBeamGeometricallyExact,
    ObjectGround,
)
from scipy.spatial.transform import Rotation  # noqa: E402


def _ep(R):
    x, y, z, w = Rotation.from_matrix(R).as_quat()
    return [w, x, y, z]


def exudyn_beam_stiffness(chain, n_el=200, F=1e-2):
    spec = rod_spec(chain, gravity=False)
    L, sp = spec.length, chain.meta["s_push"]
    n1 = max(1, round(n_el * sp / L))
    n2 = n_el - n1
    s = np.concatenate([np.linspace(0, sp, n1 + 1), np.linspace(sp, L, n2 + 1)[1:]])
    sf = np.linspace(0, L, 40001)
    tf = spec.tangent(sf)
    tf /= np.linalg.norm(tf, axis=1, keepdims=True)
    pf = spec.base + np.concatenate([[np.zeros(3)], np.cumsum(0.5 * (tf[1:] + tf[:-1]) * np.diff(sf)[:, None], 0)])
    P = np.column_stack([np.interp(s, sf, pf[:, k]) for k in range(3)])
    T = spec.tangent(s)
    SC = exu.SystemContainer()
    mbs = SC.AddSystem()
    nodes = [mbs.AddNode(NodeRigidBodyEP(referenceCoordinates=list(P[i]) + _ep(frame_with_x(T[i])))) for i in range(len(s))]
    nu = chain.rod.poisson_ratio
    for i in range(len(s) - 1):
        EI = spec.ei(np.array([0.5 * (s[i] + s[i + 1])]))[0]
        sec = exu.BeamSection()
        sec.stiffnessMatrix = np.diag([1e4 * EI, 1e4 * EI, 1e4 * EI, EI / (1 + nu), EI, EI])
        sec.massPerLength = 1e-3
        sec.inertia = 1e-9 * np.eye(3)
        mbs.AddObject(ObjectBeamGeometricallyExact(nodeNumbers=[nodes[i], nodes[i + 1]],
                                                   length=float(np.linalg.norm(P[i + 1] - P[i])), sectionData=sec))
    ground = mbs.AddObject(ObjectGround(referencePosition=list(P[0])))
    mg = mbs.AddMarker(MarkerBodyRigid(bodyNumber=ground, localPosition=[0, 0, 0]))
    m0 = mbs.AddMarker(MarkerNodeRigid(nodeNumber=nodes[0]))
    mbs.AddObject(GenericJoint(markerNumbers=[mg, m0], rotationMarker0=frame_with_x(T[0])))
    mbs.AddLoad(Force(markerNumber=mbs.AddMarker(MarkerNodeRigid(nodeNumber=nodes[n1])),
                      loadVector=list(F * chain.direction)))
    mbs.Assemble()
    ss = exu.SimulationSettings()
    ss.solution.file.write = False
    ss.staticSolver.verboseMode = 0
    ss.staticSolver.newton.absoluteTolerance = 1e-6  # residual in N: 1e-4 of the 1e-2 N load
    ss.staticSolver.newton.relativeTolerance = 1e-8
    ss.linearSolver.solverType = exu.LinearSolverType.EigenSparse
    mbs.SolveStatic(ss)
    u = mbs.GetNodeOutput(nodes[n1], exu.OutputVariableType.Displacement)
    return F / (u @ chain.direction)


@pytest.mark.parametrize("trial_id", ["b1c1t1", "b3c1t2", "b6c2t3"])
def test_rod_matches_exudyn_geometrically_exact_beam(bundled_trials, trial_id):
    t = next(t for t in bundled_trials if t.id == trial_id)
    chain = build_chain(t.cane, t.push_id, ModelConfig(gravity=0.0))
    k_rod = BeamStatic(chain, n_elements=96).linear_stiffness()
    k_exu = exudyn_beam_stiffness(chain)
    assert k_exu / k_rod - 1 == pytest.approx(0, abs=3e-3)
