import numpy as np
from scipy.optimize import fsolve
rng=np.random.default_rng(1)
N=12; L=np.full(N,0.05); phi0=np.pi/2+np.cumsum(rng.normal(0,0.06,N))  # curved planar cane (x,z plane)
K=2.0*np.linspace(3,1,N)
def nodes(q):
    ph=phi0+np.cumsum(q); d=np.c_[np.cos(ph),np.sin(ph)]*L[:,None]; return np.vstack([[0,0],np.cumsum(d,0)]), np.c_[np.cos(ph),np.sin(ph)]
S=np.r_[0,np.cumsum(L)]; sp=0.37; j0=np.searchsorted(S,sp)-1
r0,T0=nodes(np.zeros(N)); P0=r0[j0]+(sp-S[j0])*T0[j0]; t0=T0[j0]
def point(q,s):
    r,T=nodes(q); j=min(np.searchsorted(S,s)-1,N-1); return r[j]+(s-S[j])*T[j], T[j], j
def jac(q,s):  # planar: dr/dq_i = e_y x (p - node_i) for i<=j
    r,T=nodes(q); p,t,j=point(q,s); J=np.zeros((2,N))
    for i in range(j+1): v=p-r[i]; J[:,i]=[-v[1],v[0]]
    return J
perp=lambda v: np.array([-v[1],v[0]])
c=None
for th_deg in (0,10,25,40):
  for mu in (0.0,0.5):
    nrm0=perp(t0); nrm0*=np.sign(nrm0[0]) # cane normal pointing +x
    th=np.radians(th_deg); R=np.array([[np.cos(th),-np.sin(th)],[np.sin(th),np.cos(th)]]); u=R@nrm0; n=perp(u)
    J0=jac(np.zeros(N),sp); C=J0@np.diag(1/K)@J0.T
    d=1e-7; out=[]
    for sig in (1,-1):
        def res(x):
            q,f,s=x[:N],x[N],x[N+1]; p,t,_=point(q,s); nr=perp(t); nr*=np.sign(nr@u)
            G=f*(nr+sig*mu*t); return np.r_[K*q-jac(q,s).T@G, n@(p-P0), u@(p-P0)-d]
        x=fsolve(res,np.r_[np.zeros(N),0,sp],xtol=1e-14)
        p,t,_=point(x[:N],x[N+1]); nr=perp(t); nr*=np.sign(nr@u)
        out.append((sig, u@(x[N]*(nr+sig*mu*t))/d, np.sign(x[N+1]-sp)))
    # formula, in-plane
    nrm=nrm0; 
    for sig,kk,ds in out:
        kf=(u@(nrm+sig*mu*t0))*(nrm@u)/(nrm@C@(nrm+sig*mu*t0))
        print(f"th={th_deg:2d} mu={mu} sigma={sig:+d}: k_nonlin={kk:9.4f} k_formula={kf:9.4f} sign(ds_c)={ds:+.0f} consistent={ds==sig or mu==0}  held={1/(u@C@u):9.4f}")
print("--- true stick (material point held in u and n), cone check")
for th_deg in (0,10,25,40):
    nrm0=perp(t0); nrm0*=np.sign(nrm0[0]); th=np.radians(th_deg)
    R=np.array([[np.cos(th),-np.sin(th)],[np.sin(th),np.cos(th)]]); u=R@nrm0; n=perp(u)
    B=np.c_[u,n]; C2=B.T@C@B; G=B@np.linalg.solve(C2,[1,0])  # force for unit u-displacement, zero n-displacement
    print(f"th={th_deg}: k_stick={G@u:10.3f}  |G.t|/G.nrm={abs(G@t0)/(G@nrm0):8.3f}  (stuck iff <= mu)")
