import numpy as np, mujoco
xml='''<mujoco><option gravity="0 0 0"/><worldbody><site name="ref" pos="0 0 .35"/>
<body name="l0"><joint type="hinge" axis="1 0 0"/><joint type="hinge" axis="0 1 0"/><inertial pos="0 0 .15" mass=".1" diaginertia="1e-3 1e-3 1e-4"/><site name="push" pos="0 0 .25"/>
<body name="l1" pos="0 0 .3"><joint type="hinge" axis="1 0 0"/><joint type="hinge" axis="0 1 0"/><inertial pos="0 0 .15" mass=".1" diaginertia="1e-3 1e-3 1e-4"/></body></body>
</worldbody><actuator><motor site="push" refsite="ref" gear="1 0 0 0 0 0"/></actuator></mujoco>'''
m=mujoco.MjModel.from_xml_string(xml); d=mujoco.MjData(m); d.qpos[:]=[0.2,-0.1,0.3,0.05]
sid=m.site("push").id; print("sameframe" , m.site_sameframe[sid] if hasattr(m,'site_sameframe') else 'n/a')
m.site_bodyid[sid]=2; m.site_pos[sid]=[0.01,0,0.2]; mujoco.mj_forward(m,d)
b=2; pw=d.xpos[b]+d.xmat[b].reshape(3,3)@np.array([0.01,0,0.2])
print("site_xpos", d.site_xpos[sid], "expected", pw)
jacp=np.zeros((3,m.nv)); mujoco.mj_jac(m,d,jacp,None,pw,b); print("moment", d.actuator_moment.ravel() if d.actuator_moment.size==m.nv else d.actuator_moment, " J^T x", jacp.T@np.array([1,0,0]))
print("rownnz", d.moment_rownnz, "colind", d.moment_colind[:d.moment_rownnz[0]])
M=np.zeros((m.nu,m.nv)); mujoco.mju_sparse2dense(M,d.actuator_moment,d.moment_rownnz,d.moment_rowadr,d.moment_colind); print("dense moment", M)
