import numpy as np, pybullet as p
import canebench.model.chain as ch
from canebench.backends.pybullet_backend import _Model
nodes=np.array([[0,0,0],[0.02,0,0.3],[0.05,0.01,0.6]],float)
c=ch.assemble_chain(nodes,np.array([0.01,0.008]),5e9,900,0.0,"paper",1,nodes[1]+0.5*(nodes[2]-nodes[1]),np.array([1.,0,0]),0.0)
m=_Model(c); cl=m.c; cl.setGravity(0,0,0); dt=1e-5; cl.setPhysicsEngineParameter(fixedTimeStep=dt,numSubSteps=0)
q=np.array([0.2,-0.1,0.3,0.05]); m.set_q(q)
cl.setJointMotorControlArray(m.body,m.joints,p.TORQUE_CONTROL,forces=[0.0]*4)
st=cl.getLinkState(m.body,3,computeForwardKinematics=1); R=np.array(cl.getMatrixFromQuaternion(st[5])).reshape(3,3)
loc=np.array([0.001,0.0,0.1]); pw=np.array(st[4])+R@loc; f=np.array([0.3,-0.2,0.5])
lin,_=cl.calculateJacobian(m.body,3,list(loc),list(q),[0.]*4,[0.]*4); J=np.array(lin)
M=np.array(cl.calculateMassMatrix(m.body,list(q)))
cl.applyExternalForce(m.body,3,list(f),list(pw),p.WORLD_FRAME); cl.stepSimulation()
qd=np.array([s[1] for s in cl.getJointStates(m.body,m.joints)])
print("dqd/dt   ",qd/dt); print("M^-1J^Tf ",np.linalg.solve(M,J.T@f))
sts=cl.getLinkStates(m.body,[1,3],computeForwardKinematics=1); print("link frame origins (nodes):",[np.round(s[4],4).tolist() for s in sts])
print(p.getLinkStates.__doc__)
