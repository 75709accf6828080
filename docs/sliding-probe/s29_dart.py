import numpy as np, dartpy as dart, sys
sys.path.insert(0,'/work/main')
# 2-link skeleton of universal joints, tilted; apply world force at world point with isOffsetLocal False, compare to J^T f
w=dart.simulation.World(); w.setGravity(np.zeros(3)); w.setTimeStep(1e-4)
sk=dart.dynamics.Skeleton("s"); par=None; bodies=[]
for j in range(2):
    jt,b=sk.createUniversalJointAndBodyNodePair(par)
    T=dart.math.Isometry3(); T.set_translation(np.array([0,0,0.3*j])); jt.setTransformFromParentBodyNode(T)
    jt.setAxis1(np.array([1.,0,0])); jt.setAxis2(np.array([0,1.,0]))
    b.setMass(0.1); b.setMomentOfInertia(1e-3,1e-3,1e-4,0,0,0); b.setLocalCOM(np.array([0,0,0.15])); par=b; bodies.append(b)
w.addSkeleton(sk); sk.setPositions(np.array([0.2,-0.1,0.3,0.05]))
b=bodies[1]; Tw=b.getWorldTransform(); pw=Tw.translation()+Tw.rotation()@np.array([0.01,0.0,0.2])
f=np.array([0.3,-0.2,0.5])
b.addExtForce(f, pw, False, False)
tau_ext=sk.getExternalForces() if hasattr(sk,'getExternalForces') else None
J=b.getLinearJacobian(Tw.rotation().T@(pw-Tw.translation()))  # offset local, world coords
print("J^T f      ", J.T@f)
print("ext forces ", tau_ext)
b.clearExternalForces(); b.addExtForce(f, Tw.rotation().T@(pw-Tw.translation()), False, True)
print("local off  ", sk.getExternalForces())
print("getWorldTransform().matrix shape", Tw.matrix().shape)
T=dart.math.Isometry3(); T.set_translation(np.array([0,0,0.1]))
fr=dart.dynamics.SimpleFrame(bodies[0],"probe",T)
fr.setParentFrame(bodies[1]); fr.setRelativeTranslation(np.array([0.01,0,0.2]))
print("moved SimpleFrame:", fr.getWorldTransform().translation(), "expected", pw)
