import numpy as np
rng=np.random.default_rng(3)
t=np.array([0.1,0.05,1.0]); t/=np.linalg.norm(t)
A=rng.normal(size=(3,6)); C=A@A.T*1e-3+0.02*(np.eye(3)-np.outer(t,t))   # compliance with some coupling
th=np.radians(25); l=np.array([0,1.0,0]); a=np.array([1.0,0,0]); ez=np.array([0,0,1.0])
u=np.cos(th)*a+np.sin(th)*ez
nrm=np.cross(t,l); nrm/=np.linalg.norm(nrm); nrm*=np.sign(nrm@u); b=np.cross(t,nrm); Q=np.c_[nrm,b]
mu,sig=0.5,1
def k_of(e):
    B=Q+sig*mu*np.outer(t,e); f=np.linalg.solve(Q.T@C@B,Q.T@u); return u@B@f, f
k1,f=k_of(np.array([1.0,0]))
e=f/np.linalg.norm(f)
for i in range(30):
    k,f=k_of(e); e_new=f/np.linalg.norm(f)
    if np.linalg.norm(e_new-e)<1e-14: break
    e=e_new
print("e1 form k=",k1," |f| fixed point k=",k," after",i,"iters, f2/f1=",f[1]/f[0])
