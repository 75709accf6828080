import numpy as np, mujoco
xml='''<mujoco><option gravity="0 0 0" integrator="implicit" timestep="1e-4"/><worldbody>
<body name="l0"><joint type="hinge" axis="1 0 0"/><joint type="hinge" axis="0 1 0"/><inertial pos="0 0 .15" mass=".1" diaginertia="1e-3 1e-3 1e-4"/>
<body name="l1" pos="0 0 .3"><joint type="hinge" axis="1 0 0"/><joint type="hinge" axis="0 1 0"/><inertial pos="0 0 .15" mass=".1" diaginertia="1e-3 1e-3 1e-4"/></body></body>
</worldbody></mujoco>'''
m=mujoco.MjModel.from_xml_string(xml); d=mujoco.MjData(m)
d.qpos[:]=[0.2,-0.1,0.3,0.05]; mujoco.mj_step1(m,d)
b=2; pw=d.xpos[b]+d.xmat[b].reshape(3,3)@np.array([0.01,0,0.2]); f=np.array([0.3,-0.2,0.5])
jacp=np.zeros((3,m.nv)); mujoco.mj_jac(m,d,jacp,None,pw,b); print("J^T f         ", jacp.T@f)
q=np.zeros(m.nv); mujoco.mj_applyFT(m,d,f,np.zeros(3),pw,b,q); print("mj_applyFT    ", q)
# xfrc_applied: wrench at COM (xipos), world frame
d.xfrc_applied[b,:3]=f; d.xfrc_applied[b,3:]=np.cross(pw-d.xipos[b],f)
qacc_ref=None
d2=mujoco.MjData(m); d2.qpos[:]=d.qpos; d2.qfrc_applied[:]=q; mujoco.mj_forward(m,d2)
mujoco.mj_forward(m,d); print("qacc xfrc     ", d.qacc); print("qacc qfrc     ", d2.qacc)
print("xpos bodies (nodes):", d.xpos[1:].round(4).tolist())
print(mujoco.__version__)
# xfrc_applied set between mj_step1 and mj_step2 enters that step (harness-PID path)
da=mujoco.MjData(m); db=mujoco.MjData(m); da.qpos[:]=db.qpos[:]=[0.2,-0.1,0.3,0.05]
mujoco.mj_step1(m,da); da.xfrc_applied[b,:3]=f; da.xfrc_applied[b,3:]=np.cross(pw-da.xipos[b],f); mujoco.mj_step2(m,da)
db.xfrc_applied[b,:3]=f; db.xfrc_applied[b,3:]=np.cross(pw-d.xipos[b],f); mujoco.mj_step(m,db)
print("step1/xfrc/step2 qvel", da.qvel, "\nmj_step        qvel", db.qvel)
