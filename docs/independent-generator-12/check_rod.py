"""Check rod.py against /work/shared/reference-values.md. Prints each check and its error."""
import numpy as np
from rod import solve_push, Base

rows = []
def rep(name, got, ref):
    err = (got - ref) / ref
    rows.append(abs(err) < 0.01)
    print('%-58s got %-12.6g ref %-12.6g err %+.3e %s' % (name, got, ref, err, 'OK' if abs(err) < 0.01 else 'FAIL'))

E, L, dia = 4.57e9, 0.8, 0.012
I = np.pi * dia**4 / 64; EI = E * I
up = np.pi / 2
small = 1e-5
# 1. small-deflection cantilever tip stiffness 3EI/L^3
u, f = solve_push(L, lambda s: EI, lambda s: up, (1, 0), small, du=small, N=100)
rep('1. cantilever tip stiffness 3EI/L^3 (N/m)', f[-1] / u[-1], 3 * EI / L**3)
# 1b. tapered (linear diameter) cantilever
d0, d1 = 0.018, 0.009
EIt = lambda s: E * np.pi * (d0 + (d1 - d0) * s / L)**4 / 64
u, f = solve_push(L, EIt, lambda s: up, (1, 0), small, du=small, N=200)
rep('1b. linear-taper cantilever 3 pi E d0^3 d1/(64 L^3)', f[-1] / u[-1], 3 * np.pi * E * d0**3 * d1 / (64 * L**3))
# 1c. tip rotation of the tapered cantilever under P
u, f, th, tip, _ = solve_push(L, EIt, lambda s: up, (1, 0), small, du=small, N=400, return_state=True)
P = f[-1]; I0 = np.pi * d0**4 / 64; r = d1 / d0
rot = up - (1.5 * th[-1] - 0.5 * th[-2])
rep('1c. linear-taper tip rotation PL^2/(2EI0)(2r+1)/(3r^2)', rot, P * L**2 / (2 * E * I0) * (2 * r + 1) / (3 * r * r))
# 1d. pitched probe (linear): k = k0 / cos^2(a)
a = np.radians(25)
u, f = solve_push(L, lambda s: EI, lambda s: up, (np.cos(a), np.sin(a)), small, du=small, N=100)
rep('1d. probe pitched 25 deg: 3EI/L^3/cos^2', f[-1] / u[-1], 3 * EI / L**3 / np.cos(a)**2)
# 1e. base rotational spring in series: 1/k = L^3/3EI + L^2/k_root
kr = 20.0
u, f = solve_push(L, lambda s: EI, lambda s: up, (1, 0), small, du=small, N=100, base=Base('linear', kr))
rep('1e. base spring k_root=20: 1/(L^3/3EI + L^2/k_root)', f[-1] / u[-1], 1 / (L**3 / (3 * EI) + L**2 / kr))

# 2. large deflection, horizontal cantilever, vertical dead load (Bisshopp-Drucker)
table = [(0.25, 0.004118, 0.082746, 0.124292), (0.5, 0.01592, 0.162144, 0.244534),
         (1, 0.05643, 0.301721, 0.461352), (2, 0.1606, 0.493457, 0.781750),
         (3, 0.2544, 0.603253, 0.986017), (5, 0.3876, 0.713792, 1.215368),
         (10, 0.5550, 0.810609, 1.430286)]
Lh, EIh = 1.0, 1.0
for al, sh, y, ang in table:
    u, f, th, tip, _ = solve_push(Lh, lambda s: EIh, lambda s: 0.0, (0, -1), y * Lh, du=y * Lh / 60,
                                  N=300, return_state=True)
    rep('2. alpha=%-5g  PL^2/EI at y_tip/L=%.6f' % (al, y), f[-1] * Lh**2 / EIh, al)
    rep('2. alpha=%-5g  (L-x_tip)/L' % al, (Lh - tip[0]) / Lh, sh)
    rep('2. alpha=%-5g  tip angle (rad)' % al, -(1.5 * th[-1] - 0.5 * th[-2]), ang)

# 3. quarter circle, in-plane, base tangent +z curving to +x, tip tangent +x
R = 0.5; EIq = 2.0; Lq = np.pi / 2 * R
th0 = lambda s: up - s / R
u, f = solve_push(Lq, lambda s: EIq, th0, (0, 1), small, du=small, N=400)
rep('3. quarter circle, force along tip radius: (pi/4)R^3/EI', u[-1] / f[-1], np.pi / 4 * R**3 / EIq)
u, f = solve_push(Lq, lambda s: EIq, th0, (1, 0), small, du=small, N=400)
rep('3. quarter circle, force along tip tangent: (3pi/4-2)R^3/EI', u[-1] / f[-1], (3 * np.pi / 4 - 2) * R**3 / EIq)
print('SUMMARY: %d/%d checks within 1%%' % (sum(rows), len(rows)))
