"""Check rod.py against /work/shared/reference-values.md closed forms.

Prints each check with its relative error and PASS/FAIL; exit 1 on any FAIL.
"""
import os as _os
for _v in ('OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS', 'MKL_NUM_THREADS'):
    _os.environ.setdefault(_v, '1')  # one core only

import sys
import numpy as np

from rod import Chain, Solver, Interaction, chain_from_curve

E = 4.57e9
D = 0.010
EI0 = E * np.pi * D ** 4 / 64
L = 1.0
results = []


def report(name, got, want, tol):
    err = abs(got - want) / abs(want)
    ok = err <= tol
    results.append(ok)
    print('%-62s got %-13.6g want %-13.6g rel.err %.2e %s' % (name, got, want, err,
                                                             'PASS' if ok else 'FAIL'))


def straight(n, EI_fn=lambda s: np.full_like(np.asarray(s, float), EI0), length=L,
             k_root=None, angle=0.0):
    """straight rod from the origin along angle (rad from +x), n segments"""
    s = np.linspace(0, length, n + 1)
    xz = np.stack([s * np.cos(angle), s * np.sin(angle)], axis=1)
    return Chain(s, xz, EI_fn, k_root=k_root)


def small_load(chain, p, d, u=1e-6, k_rig=None, inter=()):
    sol = Solver(chain, p, d, k_rig=k_rig, inter=inter)
    F = sol.advance(u)
    return sol, F


print('== 1. small-deflection cantilever (horizontal, load along -z... here +z)')
n = 200
ch = straight(n)
sol, F = small_load(ch, n, [0, 1])
report('tip load: compliance / (L^3/3EI)  (n=200)', (1e-6 / F) / (L ** 3 / (3 * EI0)), 1.0, 1e-4)
rot = sol.th[-1] - ch.th0[-1]
report('tip load: tip rotation vs PL^2/(2EI)', rot, F * L ** 2 / (2 * EI0), 1e-3)
a = 0.6
ch, where = chain_from_curve(lambda s: (s, 0.0), lambda s: np.full_like(np.asarray(s, float), EI0),
                             [a], L, h_target=0.005)
sol, F = small_load(ch, where[a], [0, 1])
report('load at a=0.6L: deflection under load vs Pa^3/(3EI)', 1e-6 / F, a ** 3 / (3 * EI0), 1e-4)
tip = sol.c.positions(sol.th)[-1, 1]
report('load at a=0.6L: tip deflection vs Pa^2(3L-a)/(6EI)', tip, F * a * a * (3 * L - a) / (6 * EI0), 1e-4)

print('== 1b. linearly tapered solid circular section, d1/d0 = r')
for r in (0.5, 2.0):
    d0, d1 = D, D * r
    EIf = lambda s: E * np.pi * (d0 + (d1 - d0) * np.asarray(s) / L) ** 4 / 64
    ch = straight(400, EIf)
    sol, F = small_load(ch, 400, [0, 1])
    report('taper r=%.1f: tip deflection vs 64PL^3/(3 pi E d0^3 d1)' % r, 1e-6 / F,
           64 * L ** 3 / (3 * np.pi * E * d0 ** 3 * d1), 1e-4)
    rot = sol.th[-1] - ch.th0[-1]
    report('taper r=%.1f: tip rotation vs PL^2/(2EI0)(2r+1)/(3r^2)' % r, rot,
           F * L ** 2 / (2 * EI0) * (2 * r + 1) / (3 * r * r), 1e-3)

print('== 5. chain convergence: Voronoi springs, ratio 1 + 1/(2n^2)')
for n in (3, 5, 10, 20):
    ch = straight(n)
    sol, F = small_load(ch, n, [0, 1], u=1e-9)
    report('n=%d ratio to beam' % n, (1e-9 / F) / (L ** 3 / (3 * EI0)), 1 + 1 / (2 * n * n), 1e-6)

print('== 2. large deflection, vertical dead load at the tip (Mattiasson table)')
table = [(0.25, 0.004118, 0.082746, 0.124292), (0.5, 0.01592, 0.162144, 0.244534),
         (1, 0.05643, 0.301721, 0.461352), (2, 0.1606, 0.493457, 0.781750),
         (3, 0.2544, 0.603253, 0.986017), (5, 0.3876, 0.713792, 1.215368),
         (10, 0.5550, 0.810609, 1.430286)]
n = 400
ch = straight(n)
sol = Solver(ch, n, [0, -1])
for alpha, dx, dy, ang in table:
    F = sol.advance(dy * L)          # probe along -z moved to y_tip
    a_got = F * L * L / EI0
    pos = sol.c.positions(sol.th)[-1]
    report('alpha=%-4g: alpha from y_tip/L=%.6f' % (alpha, dy), a_got, alpha, 2e-4)
    report('alpha=%-4g: (L - x_tip)/L' % alpha, (L - pos[0]) / L, dx, 2e-3)
    report('alpha=%-4g: tip angle' % alpha, -(sol.th[-1]), ang, 2e-4)

print('== 3. quarter-circle cantilever, in-plane tip load (small)')
R = 0.5
n = 400
phi = np.linspace(0, np.pi / 2, n + 1)
s = R * phi
xz = np.stack([R - R * np.cos(phi), R * np.sin(phi)], axis=1)
ch = Chain(s, xz, lambda s: np.full_like(np.asarray(s, float), EI0))
for name, d, want in (('along tip radius', [0, 1], np.pi / 4),
                      ('along tip tangent', [1, 0], 3 * np.pi / 4 - 2)):
    sol, F = small_load(ch, n, d, u=1e-7)
    report('quarter circle, force %s: compliance / (R^3/EI)' % name, (1e-7 / F) / (R ** 3 / EI0), want, 1e-3)

print('== extra closed forms (not in the reference file, derived by hand)')
k_root = 25.0
ch = straight(200, k_root=k_root)
sol, F = small_load(ch, 200, [0, 1])
report('root spring: compliance vs L^3/(3EI) + L^2/k_root', 1e-6 / F,
       L ** 3 / (3 * EI0) * (1 + 1 / (2 * 200 ** 2)) + L ** 2 / k_root, 1e-6)
k_rig = 300.0
ch = straight(200)
sol, F = small_load(ch, 200, [0, 1], k_rig=k_rig)
report('rig spring: compliance vs beam + 1/k_rig', 1e-6 / F,
       L ** 3 / (3 * EI0) * (1 + 1 / (2 * 200 ** 2)) + 1 / k_rig, 1e-6)
kb = 1 / (L ** 3 / (3 * EI0) * (1 + 1 / (2 * 200 ** 2)))
ob = Interaction(200, [0, 1], 'gap', k=2 * kb, gap=0.0)
sol, F = small_load(ch, 200, [0, 1], inter=[ob])
report('gap spring engaged at the probe: stiffness vs k_beam + k', F / 1e-6, 3 * kb, 1e-5)
ob = Interaction(200, [0, 1], 'gap', k=2 * kb, gap=0.01)
sol = Solver(ch, 200, [0, 1], inter=[ob])
F1 = sol.advance(0.005)
F2 = sol.advance(0.0050001)
report('gap spring not yet engaged: tangent stiffness vs beam', (F2 - F1) / 1e-7, kb, 2e-3)
# pitched probe on a vertical cantilever: small-load stiffness k0/cos^2(phi)
for ang in (20.0, -30.0):
    chv = straight(200, angle=np.pi / 2)
    p = np.radians(ang)
    d = [np.cos(p), np.sin(p)]
    sol, F = small_load(chv, 200, d, u=1e-7)
    report('probe pitched %+.0f deg: stiffness vs k0/cos^2' % ang, F / 1e-7, kb / np.cos(p) ** 2, 1e-3)
# softening law: beta = 0 is linear; tiny load equals the linear solution
ch2 = Chain(ch.s, ch.r0, lambda s: np.full_like(np.asarray(s, float), EI0),
            soft=(0.6, 0.001, lambda s: np.full_like(np.asarray(s, float), D)))
sol, F = small_load(ch2, 200, [0, 1], u=1e-8)
report('softening law at tiny strain: stiffness vs linear', F / 1e-8, kb, 1e-4)
sol = Solver(ch2, 200, [0, 1])
F = sol.advance(0.04)
sol_lin = Solver(ch, 200, [0, 1])
Fl = sol_lin.advance(0.04)
print('   (softening law, beta 0.6, eps_y 0.1 %%: force at 40 mm is %.3f of linear)' % (F / Fl))

print('\n%d/%d checks pass' % (sum(results), len(results)))
sys.exit(0 if all(results) else 1)
