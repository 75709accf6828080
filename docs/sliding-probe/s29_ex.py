import numpy as np, exudyn as exu
from exudyn.itemInterface import *
SC=exu.SystemContainer(); mbs=SC.AddSystem()
z=[0.0]*4
node=mbs.AddNode(NodeGenericODE2(referenceCoordinates=z,initialCoordinates=[0.2,-0.1,0.3,0.05],initialCoordinates_t=z,numberOfODE2Coordinates=4))
kt=mbs.AddObject(ObjectKinematicTree(nodeNumber=node,jointTypes=[exu.JointType.RevoluteX,exu.JointType.RevoluteY]*2,linkParents=[-1,0,1,2],
  jointTransformations=exu.Matrix3DList([np.eye(3)]*4),jointOffsets=exu.Vector3DList([[0,0,0],[0,0,0],[0,0,0.3],[0,0,0]]),
  linkInertiasCOM=exu.Matrix3DList([np.zeros((3,3)),np.diag([1e-3,1e-3,1e-4])]*2),linkCOMs=exu.Vector3DList([[0,0,0],[0,0,.15]]*2),
  linkMasses=[0,.1,0,.1],gravity=[0,0,0]))
mk=mbs.AddMarker(MarkerKinematicTreeRigid(objectNumber=kt,linkNumber=1,localPosition=[0,0,0.1]))
ld=mbs.AddLoad(LoadForceVector(markerNumber=mk,loadVector=[0.3,-0.2,0.5]))
mbs.Assemble()
print("before", mbs.GetMarkerOutput(mk,exu.OutputVariableType.Position))
mbs.SetMarkerParameter(mk,"linkNumber",3); mbs.SetMarkerParameter(mk,"localPosition",[0.01,0,0.2])
print("after ", mbs.GetMarkerOutput(mk,exu.OutputVariableType.Position))
s=exu.SimulationSettings()
s.solution.file.write=False; s.timeIntegration.verboseMode=0; ti=s.timeIntegration; ti.endTime=1e-4; ti.numberOfSteps=1
sol=exu.MainSolverImplicitSecondOrder(); sol.InitializeSolver(mbs,s)
print([a for a in dir(sol) if 'Load' in a or 'Residual' in a or 'Compute' in a][:30])
print([a for a in dir(sol) if "Get" in a])
sol.ComputeODE2RHS(mbs); print("RHS after moving marker:", np.array(sol.GetSystemResidual())[:4])
mbs.SetMarkerParameter(mk,"linkNumber",1); mbs.SetMarkerParameter(mk,"localPosition",[0,0,0.1])
sol.ComputeODE2RHS(mbs); print("RHS back on link 1:     ", np.array(sol.GetSystemResidual())[:4])
mbs.SetLoadParameter(ld,"loadVector",[0,0,0]); sol.ComputeODE2RHS(mbs); print("zero load:", np.array(sol.GetSystemResidual())[:4])
try:
    print("superelem:", [mbs.GetObjectOutputSuperElement(kt, exu.OutputVariableType.Position, i) for i in range(4)])
except Exception as e: print("superelement:", type(e).__name__, str(e)[:200])
print(mbs.GetObjectOutputSuperElement.__doc__[:400])
import timeit; print("GetMarkerOutput us:", timeit.timeit(lambda: mbs.GetMarkerOutput(mk,exu.OutputVariableType.Position),number=2000)/2000*1e6)
print("SetMarkerParameter us:", timeit.timeit(lambda: mbs.SetMarkerParameter(mk,"localPosition",[0,0,0.1]),number=2000)/2000*1e6)
