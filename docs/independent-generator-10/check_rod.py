"""Verify rod.py against /work/shared/reference-values.md and classic closed forms."""
import numpy as np
from rod import Rod2D

rows = []


def chk(name, got, ref):
    err = abs(got - ref) / abs(ref)
    rows.append((name, got, ref, err))
    print(f"{name:62s} got {got:.6g}  ref {ref:.6g}  rel.err {100*err:.4f} %")


E, d0, L, N = 5e9, 0.01, 1.0, 200
EI = E * np.pi * d0 ** 4 / 64
const = lambda s: np.full_like(np.asarray(s, float), d0)
vert = np.zeros(N)
ex = np.array([1.0, 0.0])

# 1. small deflection, uniform cantilever
rod = Rod2D(L, N, const, E, vert, gravity=False)
chk("1 tip load: tip deflection PL^3/3EI", rod.compliance(L, ex), L ** 3 / (3 * EI))
_, x = rod.cross_compliance(L, ex, L, ex)
chk("1 tip load: tip rotation PL^2/2EI", x[-1], L ** 2 / (2 * EI))
a = 0.6
chk("1 load at a: deflection under load Pa^3/3EI", rod.compliance(a, ex), a ** 3 / (3 * EI))
chk("1 load at a: tip deflection Pa^2(3L-a)/6EI", rod.cross_compliance(a, ex, L, ex)[0],
    a ** 2 * (3 * L - a) / (6 * EI))

# 1b. linear taper
D0, D1 = 0.02, 0.008
r = D1 / D0
lin = lambda s: D0 + (D1 - D0) * np.asarray(s) / L
rod = Rod2D(L, N, lin, E, vert, gravity=False)
EI0 = E * np.pi * D0 ** 4 / 64
chk("1 linear taper r=0.4: tip deflection 64PL^3/(3 pi E d0^3 d1)", rod.compliance(L, ex),
    64 * L ** 3 / (3 * np.pi * E * D0 ** 3 * D1))
chk("1 linear taper r=0.4: tip rotation PL^2/2EI0 (2r+1)/3r^2",
    rod.cross_compliance(L, ex, L, ex)[1][-1], L ** 2 / (2 * EI0) * (2 * r + 1) / (3 * r ** 2))

# 2. large deflection elastica, horizontal cantilever, vertical dead tip load
table = [(0.25, 0.004118, 0.082746, 0.124292), (0.5, 0.01592, 0.162144, 0.244534),
         (1, 0.05643, 0.301721, 0.461352), (2, 0.1606, 0.493457, 0.781750),
         (3, 0.2544, 0.603253, 0.986017), (5, 0.3876, 0.713792, 1.215368),
         (10, 0.5550, 0.810609, 1.430286)]
hor = np.full(N, np.pi / 2)
rod = Rod2D(L, N, const, E, hor, gravity=False)
down = np.array([0.0, -1.0])
th = None
for alpha, lx, ly, ang in table:
    P = alpha * EI / L ** 2
    th = rod.solve_load(L, down, P, nsteps=10, th=th)
    tip = rod.point(L, th)
    chk(f"2 elastica alpha={alpha}: (L-x_tip)/L", (L - tip[0]) / L, lx)
    chk(f"2 elastica alpha={alpha}: y_tip/L", -tip[1] / L, ly)
    chk(f"2 elastica alpha={alpha}: tip angle", th[-1] - np.pi / 2, ang)

# 2b. the same through displacement control (probe) at alpha = 2 and 10
for alpha, lx, ly, ang in (table[3], table[6]):
    F, th = rod.push(L, down, np.linspace(0, ly * L, 200))
    chk(f"2 displacement control y/L={ly}: alpha = F L^2/EI", F[-1] * L ** 2 / EI, alpha)

# 3. quarter circle, in plane (slender, inextensible)
R = 0.5
Lq = np.pi / 2 * R
arc = (np.arange(N) + 0.5) / N * np.pi / 2
rod = Rod2D(Lq, N, const, E, arc, gravity=False)
tip = rod.point(Lq, arc)
chk("3 quarter circle: tip position check x=R", tip[0], R)
chk("3 quarter circle, force along tip radius: (pi/4)PR^3/EI",
    rod.compliance(Lq, [0, 1]), np.pi / 4 * R ** 3 / EI)
chk("3 quarter circle, force along tip tangent: (3pi/4-2)PR^3/EI",
    rod.compliance(Lq, [1, 0]), (3 * np.pi / 4 - 2) * R ** 3 / EI)

# 4. base spring (superposition: PL^3/3EI + PL^2/k)
for kr in (5.0, 50.0):
    rod = Rod2D(L, N, const, E, vert, gravity=False, k_root=kr)
    chk(f"4 base spring k={kr} N m/rad: PL^3/3EI + PL^2/k", rod.compliance(L, ex),
        L ** 3 / (3 * EI) + L ** 2 / kr)
    chk(f"4 base spring k={kr}: load at a=0.6: a^3/3EI + a^2/k", rod.compliance(0.6, ex),
        0.6 ** 3 / (3 * EI) + 0.36 / kr)

# 5. self-weight, horizontal cantilever, small deflection: qL^4/(8EI)
Eb = 2e11
rod = Rod2D(L, N, const, Eb, hor, gravity=True, rest="given")
q = 580 * 9.81 * np.pi * d0 ** 2 / 4
th = rod.solve_load(L, down, 0.0, gamma=1.0, nsteps=1)
EIb = Eb * np.pi * d0 ** 4 / 64
chk("5 self-weight horizontal cantilever: qL^4/8EI", -rod.point(L, th)[1], q * L ** 4 / (8 * EIb))

# 6. 'equilibrium' rest: photographed curved cane is in equilibrium; nonlinear
#    push at small u reproduces the linear compliance (incl. gravity softening)
taper = lambda s: 0.018 * (1 - 0.8 * np.asarray(s) / 1.5)
sc = (np.arange(N) + 0.5) / N
thc = 0.15 + 0.6 * sc ** 2
rod = Rod2D(1.5, N, taper, 4.57e9, thc, gravity=True, rest="equilibrium", k_root=40.0)
print(f"{'6 equilibrium residual max|grad| (N m)':62s} {rod.residual_norm():.2e}")
dd = np.array([np.cos(0.5), -np.sin(0.5)])
c = rod.compliance(0.9, dd)
F, _ = rod.push(0.9, dd, [0, 1e-5, 2e-5])
chk("6 curved cane with gravity: nonlinear push slope vs linear", (F[2] - F[0]) / 2e-5, 1 / c)
th = rod.solve_load(0.9, dd, 1e-3 / 1.0)  # 1 mN load control
chk("6 load control vs linear compliance", dd @ (rod.point(0.9, th) - rod.point(0.9, thc)) / 1e-3, c)

print()
worst = max(r[3] for r in rows)
print(f"{len(rows)} checks, worst relative error {100*worst:.4f} %  ->  {'PASS' if worst < 0.01 else 'FAIL'} (< 1 %)")
