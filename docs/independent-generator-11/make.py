"""Independent synthetic datasets for testing `canebench discover`.

Writes data/dsNN/ (push_points.csv, rig CSVs, canes/b{bush}c{cane}.yaml)
and truth/dsNN.json (never inside data/).  Usage:
    /work/venv/bin/python make.py [--only ds03,ds07] [--out .]
"""
import argparse
import json
import os
import shutil
import sys
import time

import numpy as np
from scipy.interpolate import PchipInterpolator

from rod import Rod

E_STATED = 4.57e9
RHO = 580.0
G = 9.81
NU = 0.3
GF = 9.81e-3          # N per gram-force
SD_LN_E = 0.15

# ----------------------------------------------------------------------------
# dataset table: hidden effects + deliberately varied habits
# ----------------------------------------------------------------------------
DATASETS = [
    dict(id='ds01', seed=1101, effects=[], expect=[], unexplained=False,
         habits=dict(naming='field', order='top_first', hround='5mm', azimuth='in_plane', poly='raw',
                     cal='height', pauses=False, bushes=6, bush_ids='contiguous', base_z=False,
                     dir_junk=False, pp_loc='height', shuffle_csv=False)),
    dict(id='ds02', seed=1102, effects=[], expect=[], unexplained=False,
         habits=dict(naming='nested', order='bottom_first', hround='cm', azimuth='off_plane', poly='smooth',
                     cal='s', pauses=True, bushes=5, bush_ids='gappy', base_z=True,
                     dir_junk=True, pp_loc='height', shuffle_csv=True)),
    dict(id='ds03', seed=1103, effects=['modulus_scale'], expect=['modulus_scale'], unexplained=False,
         habits=dict(naming='flat', order='top_first', hround='cm', azimuth='mixed', poly='raw',
                     cal='mixed', pauses=False, bushes=5, bush_ids='contiguous', base_z=False,
                     dir_junk=False, pp_loc='height', shuffle_csv=False)),
    dict(id='ds04', seed=1104, effects=['root_compliance'], expect=['root_compliance'], unexplained=False,
         habits=dict(naming='field', order='top_first', hround='5mm', azimuth='off_plane', poly='smooth',
                     cal='height', pauses=True, bushes=5, bush_ids='contiguous', base_z=False,
                     dir_junk=True, pp_loc='s', shuffle_csv=False)),
    dict(id='ds05', seed=1105, effects=['rig_compliance'], expect=['rig_compliance'], unexplained=False,
         habits=dict(naming='nested', order='top_first', hround='mm', azimuth='mixed', poly='raw',
                     cal='s', pauses=False, bushes=6, bush_ids='contiguous', base_z=True,
                     dir_junk=False, pp_loc='height', shuffle_csv=True)),
    dict(id='ds06', seed=1106, effects=['probe_misalignment'], expect=['probe_misalignment'], unexplained=False,
         habits=dict(naming='field', order='bottom_first', hround='cm', azimuth='in_plane', poly='raw',
                     cal='mixed', pauses=False, bushes=5, bush_ids='gappy', base_z=False,
                     dir_junk=False, pp_loc='height', shuffle_csv=False)),
    dict(id='ds07', seed=1107, effects=['base_flare'], expect=['base_flare'], unexplained=False,
         habits=dict(naming='flat', order='top_first', hround='5mm', azimuth='off_plane', poly='smooth',
                     cal='height', pauses=True, bushes=5, bush_ids='contiguous', base_z=False,
                     dir_junk=True, pp_loc='height', shuffle_csv=False)),
    dict(id='ds08', seed=1108, effects=['obstruction'], expect=['obstruction'], unexplained=False,
         habits=dict(naming='field', order='top_first', hround='5mm', azimuth='mixed', poly='raw',
                     cal='mixed', pauses=False, bushes=6, bush_ids='contiguous', base_z=False,
                     dir_junk=False, pp_loc='height', shuffle_csv=False)),
    dict(id='ds09', seed=1109, effects=['rig_compliance', 'base_flare'], expect=['rig_compliance', 'base_flare'],
         unexplained=False,
         habits=dict(naming='nested', order='bottom_first', hround='cm', azimuth='off_plane', poly='raw',
                     cal='s', pauses=False, bushes=5, bush_ids='gappy', base_z=True,
                     dir_junk=False, pp_loc='height', shuffle_csv=True)),
    dict(id='ds10', seed=1110, effects=['trellis_wire'], expect=[], unexplained=True,
         habits=dict(naming='field', order='top_first', hround='5mm', azimuth='mixed', poly='smooth',
                     cal='height', pauses=False, bushes=5, bush_ids='contiguous', base_z=False,
                     dir_junk=False, pp_loc='height', shuffle_csv=False)),
    dict(id='ds11', seed=1111, effects=['viscoelastic'], expect=[], unexplained=True,
         habits=dict(naming='flat', order='top_first', hround='cm', azimuth='off_plane', poly='raw',
                     cal='mixed', pauses=True, bushes=5, bush_ids='contiguous', base_z=False,
                     dir_junk=True, pp_loc='height', shuffle_csv=False)),
    dict(id='ds12', seed=1112, effects=['crack'], expect=[], unexplained=True,
         habits=dict(naming='nested', order='top_first', hround='5mm', azimuth='in_plane', poly='raw',
                     cal='s', pauses=False, bushes=5, bush_ids='gappy', base_z=False,
                     dir_junk=False, pp_loc='s', shuffle_csv=True)),
]

OOL_NOTES = {
    'trellis_wire': 'a trellis wire ties each cane above its highest push: bilateral horizontal spring at one '
                    'material point (not in the library: neither a base, rig, modulus, flare nor angle effect)',
    'viscoelastic': 'the cane is viscoelastic (standard linear solid on the elastic force, tau ~ 6-14 s): the '
                    'force relaxes with time, visible at the rig pauses (time-stamp gaps) and as softening',
    'crack': 'a cracked cane: a soft hinge-like joint (bending spring in series) between two push points, '
             'so pushes above the crack are soft and pushes below it are not',
}


# ----------------------------------------------------------------------------
# cane geometry
# ----------------------------------------------------------------------------
class Cane:
    pass


def make_curve(rng, L, base, theta0, k1, k2, phi0, omega, n=3001):
    s = np.linspace(0, L, n)
    th = theta0 + k1 * s + k2 * s ** 2
    th = np.clip(th, -1.1, 1.1)
    ph = phi0 + omega * s
    t = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], 1)
    r = np.zeros((n, 3))
    r[1:] = np.cumsum(0.5 * (t[1:] + t[:-1]) * np.diff(s)[:, None], 0)
    r += base
    return s, r


def interp_curve(s, r, q):
    q = np.atleast_1d(q)
    return np.stack([np.interp(q, s, r[:, k]) for k in range(3)], 1)


def s_at_height(s, r, z):
    return float(np.interp(z, r[:, 2], s))   # z monotone


def diam_fn(c, flare=False):
    def d(s):
        s = np.asarray(s, float)
        base = c.d_tip + (c.d_base - c.d_tip) * np.clip(1 - s / c.L, 0, 1) ** c.p
        bump = np.ones_like(s)
        for (sb, a, w) in c.bumps:
            bump = bump + a * np.exp(-0.5 * ((s - sb) / w) ** 2)
        out = base * bump
        if flare and c.flare is not None:
            A, lam = c.flare
            out = out * (1 + A * np.exp(-s / lam))
        return out
    return d


def rod_for(c, flare=False, E=None, k_root=None, soft=None, n_uniform=48):
    """Rod on a grid with the special material points as nodes."""
    L = c.L
    u = np.linspace(0, L, n_uniform + 1)
    h = L / n_uniform
    special = sorted(set(np.round(c.special_s, 6)))
    keep = [x for x in u if all(abs(x - sp) > 0.35 * h for sp in special) or x in (0.0, L)]
    grid = np.unique(np.concatenate([keep, special]))
    grid = grid[(grid >= 0) & (grid <= L)]
    r = interp_curve(c.s_fine, c.r_fine, grid)
    dfun = diam_fn(c, flare)
    E = c.E if E is None else E
    # exact integrals of flexibility over dual intervals, mass over segments
    hs = np.diff(grid)
    edges = np.concatenate([[0.0], 0.5 * (grid[:-1] + grid[1:]), [L]])
    EI_eff = np.empty(len(grid))
    for i in range(len(grid)):
        a, b = edges[i], edges[i + 1]
        q = np.linspace(a, b, 41)
        flex = np.trapezoid(1.0 / (E * np.pi * dfun(q) ** 4 / 64), q)
        EI_eff[i] = (b - a) / flex if b > a else E * np.pi * dfun(grid[i]) ** 4 / 64
    # Rod uses dual lengths h0/2, (h_{i-1}+h_i)/2 which equal these edges' widths
    wpl = np.empty(len(hs))
    for i in range(len(hs)):
        q = np.linspace(grid[i], grid[i + 1], 21)
        wpl[i] = np.trapezoid(RHO * np.pi * dfun(q) ** 2 / 4 * G, q) / hs[i]
    soft_nodes = None
    if soft:
        soft_nodes = {int(np.argmin(abs(grid - ss))): kb for ss, kb in soft}
    rod = Rod(r, dfun(grid), E, nu=NU, k_root=k_root, soft_joints=soft_nodes,
              EI_nodes=EI_eff, GJ_nodes=EI_eff / (1 + NU), weight_per_len=wpl)
    rod.grid = grid
    return rod


def node_of(rod, s):
    return int(np.argmin(abs(rod.grid - s)))


def probe_axis(c, s_p, az, angle_deg):
    """Azimuth az (unit horizontal), pitched perpendicular to the +-150 mm chord of the
    true cane, plus angle_deg (positive up)."""
    lo, hi = max(0.0, s_p - 0.15), min(c.L, s_p + 0.15)
    p = interp_curve(c.s_fine, c.r_fine, [lo, hi])
    t = p[1] - p[0]; t /= np.linalg.norm(t)
    p0 = np.arctan2(-(az @ t), t[2])
    p_ = p0 + np.radians(angle_deg)
    e = np.cos(p_) * az + np.sin(p_) * np.array([0, 0, 1.0])
    return e / np.linalg.norm(e), np.degrees(p0)


# ----------------------------------------------------------------------------
# push simulation
# ----------------------------------------------------------------------------
F_CAP = 13.0   # N: above the 1000 gf stop whatever the tare


def simulate_push(rod, xg, node, e, springs=(), record=(), max_step=4e-3):
    """Adaptive displacement grid up to 47 mm or F_CAP. Returns delta (m), F (N), recorded."""
    F1, x1, rec1, pos0, ok = rod.push(node, e, [5e-4], xg, springs, record)
    k0 = max(F1[0] / 5e-4, 1e-3)
    step = float(np.clip(F_CAP / k0 / 9, 4e-4, max_step))
    deltas = [5e-4]
    d = 5e-4
    while d < 0.047:
        d = d + step
        deltas.append(d)
    deltas = np.array(deltas)
    out_F, out_rec, oks = [], [], True
    # do in chunks so we can stop at F_CAP
    Fs, xs, rec, pos0, ok = None, None, None, None, True
    chunk = 4
    allF, allrec, alld = [], [], []
    xcur = xg
    e = np.asarray(e, float) / np.linalg.norm(e)
    rc = rod.positions(xg, None, springs)[node].copy()
    probe = {'node': node, 'e': e, 'rc': rc, 'mode': 'disp', 'delta': 0.0}
    hist = [(0.0, xg.copy())]
    for d in deltas:
        probe['delta'] = d
        d1, x1_ = hist[-1]
        if len(hist) >= 2:
            d0_, x0_ = hist[-2]
            guess = x1_ + (x1_ - x0_) * (d - d1) / (d1 - d0_)
        else:
            guess = x1_.copy()
        xn, ok = rod.solve(guess, probe, springs)
        if not ok:
            xs_ = x1_.copy()
            for dd in np.linspace(d1, d, 6)[1:]:
                probe['delta'] = dd
                xs_, ok = rod.solve(xs_, probe, springs, maxit=60)
            xn = xs_
        oks &= ok
        hist.append((d, xn.copy()))
        alld.append(d); allF.append(xn[6])
        if record:
            p = rod.positions(xn, probe, springs)
            allrec.append(p[list(record)])
        if xn[6] > F_CAP:
            break
    dd = np.concatenate([[0.0], alld]); FF = np.concatenate([[0.0], allF])
    recs = None
    if record:
        p0 = rod.positions(xg, None, springs)[list(record)]
        recs = np.concatenate([p0[None], np.array(allrec)], 0)
    return dd, FF, recs, oks


class Curve:
    """Force (N) as a function of cane displacement delta (m) along the probe, extrapolated linearly."""

    def __init__(self, d, F):
        self.d, self.F = np.asarray(d), np.asarray(F)
        self.p = PchipInterpolator(self.d, self.F)
        self.k_end = (self.F[-1] - self.F[-2]) / (self.d[-1] - self.d[-2])

    def __call__(self, x):
        x = np.asarray(x, float)
        out = self.p(np.clip(x, 0, self.d[-1]))
        out = np.where(x > self.d[-1], self.F[-1] + self.k_end * (x - self.d[-1]), out)
        return np.where(x < 0, 0.0, out)


def series_curve(curve, k_rig):
    """Probe travel x = delta + F/k_rig: returns F as a function of x."""
    d = np.linspace(0, curve.d[-1], 400)
    F = curve(d)
    x = d + F / k_rig
    return Curve(x, F)


# ----------------------------------------------------------------------------
# rig trace
# ----------------------------------------------------------------------------
def softplus_mm(x, w=0.25):
    x = np.asarray(x, float)
    return w * np.where(x / w > 30, x / w, np.log1p(np.exp(np.minimum(x / w, 30))))


def trace(curve_x, rig, visco=None):
    """curve_x: F (N) vs probe travel after contact (m). Returns dict of arrays (all rows until stop)."""
    n = 88
    j = np.arange(n)
    xp = 0.5 * j                                  # probe travel since first sample (mm)
    xc = xp - rig['c0']
    if rig.get('slip') is not None:
        js, dlt = rig['slip']
        xc = np.where(j >= js, xc - dlt, xc)
    de = softplus_mm(xc)
    de = np.where(xc < -2, 0.0, de)
    F = curve_x(de * 1e-3)
    dt = np.full(n, 500.0)
    for (jp, extra) in rig.get('pauses', []):
        dt[jp] += extra
    dt[0] = 0.0
    tms = np.cumsum(dt)
    if visco is not None:
        g_inf, tau = visco
        q = np.zeros(n); Fv = np.zeros(n)
        for k in range(n):
            dF = F[k] - (F[k - 1] if k else 0.0)
            decay = np.exp(-dt[k] / 1000.0 / tau) if k else 1.0
            q[k] = (q[k - 1] if k else 0.0) * decay + dF * np.exp(-0.25 / tau)
            Fv[k] = g_inf * F[k] + (1 - g_inf) * q[k]
        F = Fv
    Fgf = F / GF
    return j, xp, tms, Fgf


def rig_rows(Fgf, rig, rng):
    n = len(Fgf)
    j = np.arange(n)
    raw = rig['tare'] + rig['drift'] * j + Fgf + rng.normal(0, rig['noise'], n)
    spikes = rng.random(n) < 0.012
    raw = raw + spikes * rng.normal(0, 25, n)
    stop = n
    over = np.nonzero(raw >= 1000.0)[0]
    if len(over):
        stop = over[0] + 1
    if rig.get('trunc') is not None:
        stop = min(stop, rig['trunc'])
    return raw[:stop]


def write_csv(path, rig, raw, tms, height_mm):
    it0 = rig['it0']
    lines = ['Iteration,Time Stamp,Load Cell Reading (gf),Displacement (mm),Height (mm)']
    for k in range(len(raw)):
        ts = (rig['ts0'] + tms[k] + 32768) % 65536 - 32768
        lines.append(f"{float(it0 + k)},{float(ts)},{round(float(raw[k]), 2)},{float(rig['x0'] + 0.5 * k)},{height_mm}")
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, 'w', newline='') as f:
        f.write('\r\n'.join(lines) + '\r\n')


def clean_slope(Fgf, tare, contact_limit_mm=45.0, xp=None, c0=0.0):
    """Rig-style slope (N/mm): fit force vs displacement where net force > 20 gf, before the stop
    (raw >= 1000 gf) and within 45 mm of contact. Noise-free."""
    n = len(Fgf)
    xp = 0.5 * np.arange(n) if xp is None else xp
    raw = tare + Fgf
    over = np.nonzero(raw >= 1000)[0]
    stop = over[0] + 1 if len(over) else n
    m = np.zeros(n, bool); m[:stop] = True
    m &= Fgf > 20
    m &= (xp - c0) <= contact_limit_mm
    if m.sum() < 3:
        return None
    A = np.polyfit(xp[m], Fgf[m] * GF, 1)
    return float(A[0])


# ----------------------------------------------------------------------------
# dataset generation
# ----------------------------------------------------------------------------
def fmt(v, nd=5):
    return repr(round(float(v), nd))


def gen_canes(rng, H, n_bush):
    if H['bush_ids'] == 'gappy':
        ids = sorted(rng.choice(np.arange(1, 10), n_bush, replace=False).tolist())
    else:
        ids = list(range(1, n_bush + 1))
    canes = []
    for b in ids:
        nc = int(rng.choice([1, 2, 3, 3, 4]))
        cids = list(range(1, nc + 1))
        if H['bush_ids'] == 'gappy' and nc >= 2 and rng.random() < 0.5:
            cids = sorted(rng.choice(np.arange(1, 6), nc, replace=False).tolist())
        for cc in cids:
            c = Cane(); c.bush = int(b); c.cane = int(cc); c.id = f'b{b}c{cc}'
            c.n_push = int(rng.choice([2, 3, 3, 4]))
            canes.append(c)
    return canes


def build_geometry(c, rng, H):
    z_top = rng.uniform(0.62, 1.05)
    gaps = rng.uniform(0.06, 0.14, c.n_push - 1)
    zs = z_top - np.concatenate([[0], np.cumsum(gaps)])
    zs = np.maximum(zs, 0.38)
    c.theta0 = rng.uniform(0.02, 0.35)
    c.k1 = rng.uniform(-0.15, 0.45)
    c.k2 = rng.uniform(-0.1, 0.2)
    c.phi0 = rng.uniform(-np.pi, np.pi)
    c.omega = rng.choice([-1, 1]) * rng.uniform(0.2, 1.3)   # twist of the bending plane (rad/m)
    base = np.array([rng.uniform(-0.15, 0.15), rng.uniform(-0.15, 0.15),
                     rng.uniform(0.02, 0.07) if H['base_z'] else 0.0])
    L = 1.0
    for _ in range(3):
        s, r = make_curve(rng, L, base, c.theta0, c.k1, c.k2, c.phi0, c.omega)
        s_top = s_at_height(s, r, z_top) if r[-1, 2] > z_top else L
        L = s_top + rng.uniform(0.12, 0.5)
    L = float(min(L, 1.7))
    s, r = make_curve(rng, L, base, c.theta0, c.k1, c.k2, c.phi0, c.omega)
    assert np.all(np.diff(r[:, 2]) > 0)
    c.L, c.s_fine, c.r_fine, c.base = L, s, r, base
    c.z_push = zs
    c.s_push = np.array([s_at_height(s, r, z) for z in zs])
    # diameters
    c.d_base = float(np.exp(rng.uniform(np.log(0.011), np.log(0.030))))
    c.d_tip = rng.uniform(0.0025, 0.0038)
    c.p = rng.uniform(0.45, 1.2)
    c.bumps = []
    for _ in range(int(rng.integers(2, 6))):
        c.bumps.append((rng.uniform(0.05, L - 0.05), rng.uniform(0.03, 0.10), rng.uniform(0.006, 0.015)))
    c.flare = None
    # calipers: three, away from push points, lowest between 0.10 and 0.45 m height
    zc = []
    lo = rng.uniform(0.10, 0.45)
    zc.append(lo)
    while len(zc) < 3:
        z = rng.uniform(lo + 0.05, min(z_top + 0.08, r[-1, 2] - 0.08))
        if all(abs(z - q) > 0.04 for q in zc) and all(abs(z - q) > 0.015 for q in zs):
            zc.append(z)
    c.cal_s = np.array(sorted(s_at_height(s, r, z) for z in zc))
    if rng.random() < 0.4:     # a bud / knot right at one caliper
        k = int(rng.integers(0, 3))
        c.bumps.append((float(c.cal_s[k]), rng.uniform(0.08, 0.18), rng.uniform(0.006, 0.01)))
        c.knot_at_caliper = int(k)
    else:
        c.knot_at_caliper = None
    c.special_s = list(c.s_push)


def lean_azimuth(c, s_p):
    p = interp_curve(c.s_fine, c.r_fine, [max(0, s_p - 0.15), min(c.L, s_p + 0.15)])
    t = p[1] - p[0]
    h = np.array([t[0], t[1], 0.0])
    if np.linalg.norm(h) < 1e-6:
        h = np.array([1.0, 0, 0])
    return h / np.linalg.norm(h)


def rot_z(v, a):
    ca, sa = np.cos(a), np.sin(a)
    return np.array([ca * v[0] - sa * v[1], sa * v[0] + ca * v[1], v[2]])


def chaikin_free_digitize(c, pos_nodes, grid, rng, H):
    """Polyline points digitized on the (gravity-loaded) cane, base first."""
    if H['poly'] == 'raw':
        n = 12
        gap = c.L / (n - 1)
        ss = [0.0]
        while len(ss) < n - 1:
            ss.append(ss[-1] + gap * rng.uniform(0.78, 1.22))
        ss = np.array(ss)
        ss = ss * (c.L - gap * 0.5) / max(ss[-1], 1e-9) if ss[-1] > c.L - 0.3 * gap else ss
        ss = np.append(ss[ss < c.L - 0.3 * gap], c.L)
        pts = np.stack([np.interp(ss, grid, pos_nodes[:, k]) for k in range(3)], 1)
        pts[1:-1] += rng.normal(0, 0.002, pts[1:-1].shape)
        pts[-1] += rng.normal(0, 0.002, 3)
    else:
        ss = np.linspace(0, c.L, 31)
        pts = np.stack([np.interp(ss, grid, pos_nodes[:, k]) for k in range(3)], 1)
        pts[1:] += rng.normal(0, 0.0005, pts[1:].shape)
    pts[0] = c.base
    return pts


def make_dataset(cfg, out_root):
    t_start = time.time()
    rng = np.random.default_rng(cfg['seed'])
    H = cfg['habits']
    dsid = cfg['id']
    ddir = os.path.join(out_root, 'data', dsid)
    if os.path.exists(ddir):
        shutil.rmtree(ddir)
    os.makedirs(os.path.join(ddir, 'canes'))
    canes = gen_canes(rng, H, H['bushes'])
    for c in canes:
        build_geometry(c, rng, H)
    # per-cane modulus scatter, recentred to geometric mean 1
    z = rng.normal(0, SD_LN_E, len(canes))
    z -= z.mean()
    for c, zz in zip(canes, z):
        c.E_rel = float(np.exp(zz))
    effects = cfg['effects']
    P = {}   # global effect parameters
    if 'modulus_scale' in effects:
        P['scale'] = float(rng.choice([rng.uniform(0.55, 0.72), rng.uniform(1.4, 1.8)]))
    if 'probe_misalignment' in effects:
        P['angle_deg'] = float(rng.choice([-1, 1]) * rng.uniform(23.0, 25.0))
    if 'base_flare' in effects:
        P['flare_A_median'] = float(rng.uniform(1.0, 1.3))
        P['flare_lambda_median'] = float(rng.uniform(0.08, 0.11))
        for c in canes:
            c.flare = (P['flare_A_median'] * np.exp(rng.normal(0, 0.15)),
                       P['flare_lambda_median'] * np.exp(rng.normal(0, 0.1)))
    if 'viscoelastic' in effects:
        P['g_inf'] = float(rng.uniform(0.5, 0.6))
        P['tau_s'] = float(rng.uniform(6.0, 14.0))
    scale = P.get('scale', 1.0)
    angle = P.get('angle_deg', 0.0)
    bush_ids = sorted(set(c.bush for c in canes))
    # wire / crack geometry (material points become nodes)
    for c in canes:
        c.wire = None; c.crack = None
        if 'trellis_wire' in effects:
            s_top = c.s_push.max()
            c.wire_s = float(min(c.L - 0.03, s_top + rng.uniform(0.08, 0.2)))
            c.special_s.append(c.wire_s)
        if 'crack' in effects and rng.random() < 0.9:
            order = np.argsort(-c.s_push)       # highest first
            k = 1 if c.n_push == 2 else 2
            s_hi, s_lo = c.s_push[order[k - 1]], c.s_push[order[k]]
            c.crack_s = float(s_lo + rng.uniform(0.3, 0.7) * (s_hi - s_lo))
            c.special_s.append(c.crack_s)
            c.crack = True
    trials = []
    # trial numbering
    pp_rows = []
    cane_yaml = {}
    sizes = {e: [] for e in effects}
    sizes_all = []
    n_solved = 0
    for c in canes:
        E_true = E_STATED * c.E_rel * scale
        c.E = E_true
        k_root = None
        if 'root_compliance' in effects:
            if 'k_root_by_bush' not in P:
                P['k_root_by_bush'] = {}
                P['_root_c'] = {b: float(np.exp(rng.uniform(np.log(0.35), np.log(1.3)))) for b in bush_ids}
        wire_springs = []
        soft = None
        # --- rods: with all effects, and baseline without the hidden physical effects
        base_rod = rod_for(c, flare=False, E=E_STATED * c.E_rel)
        xg0, ok0 = base_rod.gravity_state()
        c.rod0, c.xg0 = base_rod, xg0
        c.trial_data = []
        # orders
        order = np.argsort(-c.s_push) if H['order'] == 'top_first' else np.argsort(c.s_push)
        az_base = lean_azimuth(c, float(np.median(c.s_push)))
        if H['azimuth'] == 'in_plane' or (H['azimuth'] == 'mixed' and rng.random() < 0.5):
            off = rng.normal(0, 0.12) + (np.pi if rng.random() < 0.5 else 0.0)
            c.az_mode = 'in_plane'
        else:
            off = rng.choice([-1, 1]) * rng.uniform(np.radians(35), np.radians(90))
            c.az_mode = 'off_plane'
        c.az = rot_z(az_base, off)
        for tno, ip in enumerate(order, start=1):
            s_p = float(c.s_push[ip])
            az = rot_z(c.az, rng.normal(0, 0.05))
            c.trial_data.append(dict(trial=tno, s=s_p, z=float(interp_curve(c.s_fine, c.r_fine, s_p)[0, 2]), az=az))
    # root compliance values per bush need the baseline stiffness: set from beam estimate
    if 'root_compliance' in effects:
        for b in bush_ids:
            kb = []
            for c in canes:
                if c.bush != b:
                    continue
                EI0 = E_STATED * c.E_rel * np.pi * diam_fn(c)(0.02) ** 4 / 64
                hbar = float(np.mean([td['z'] for td in c.trial_data]))
                kb.append(3 * EI0 / hbar)
            P['k_root_by_bush'][str(b)] = float(P['_root_c'][b] * np.exp(np.mean(np.log(kb))))
        P.pop('_root_c')
    # -------------------------------------------------------------------------
    rig_k_target = None
    for c in canes:
        k_root = P['k_root_by_bush'][str(c.bush)] if 'root_compliance' in effects else None
        soft = None
        if c.crack:
            # hinge compliance (s_top - s_c)^2 / k_c = 1/(c k_top) with k_top the intact cane's
            # stiffness at its highest push (c in 0.8-2: the top push softens by ln(1 + 1/c))
            s_top = float(c.s_push.max())
            td_top = max(c.trial_data, key=lambda t: t['s'])
            e_top, _ = probe_axis(c, s_top, td_top['az'], 0.0)
            Ft, _, _, _, _ = c.rod0.push(node_of(c.rod0, s_top), e_top, [5e-4], c.xg0)
            k_top = Ft[0] / 5e-4
            c.crack_k = float(rng.uniform(0.8, 2.0) * (s_top - c.crack_s) ** 2 * k_top)
            soft = [(c.crack_s, c.crack_k)]
        eff_rod = None
        physical = any(e in effects for e in ('modulus_scale', 'root_compliance', 'base_flare', 'crack', 'trellis_wire'))
        if physical:
            eff_rod = rod_for(c, flare=('base_flare' in effects), E=c.E, k_root=k_root, soft=soft)
            springs_w = []
            if 'trellis_wire' in effects:
                anchor = interp_curve(c.s_fine, c.r_fine, c.wire_s)[0]
                EIw = c.E * np.pi * diam_fn(c)(c.wire_s) ** 4 / 64
                c.wire_k = float(rng.uniform(4.0, 10.0) * 3 * EIw / c.wire_s ** 3 * 8)
                springs_w = [dict(kind='lateral', node=node_of(eff_rod, c.wire_s), k=c.wire_k, anchor=anchor)]
            c.springs_w = springs_w
            xge, oke = eff_rod.gravity_state(springs_w)
        else:
            c.springs_w = []
        for td in c.trial_data:
            e_true, p0 = probe_axis(c, td['s'], td['az'], angle)
            e_nom, _ = probe_axis(c, td['s'], td['az'], 0.0)
            td['e'] = e_true; td['pitch_perp_deg'] = p0
            # baseline push (no hidden effect; per-cane E scatter kept)
            nb = node_of(c.rod0, td['s'])
            d0, F0, _, ok = simulate_push(c.rod0, c.xg0, nb, e_nom)
            n_solved += 1
            td['curve0'] = Curve(d0, F0)
            if physical:
                ne = node_of(eff_rod, td['s'])
                d1, F1, _, ok1 = simulate_push(eff_rod, xge, ne, e_true, c.springs_w)
                td['curve'] = Curve(d1, F1); n_solved += 1
                ok &= ok1
            elif angle != 0.0:
                d1, F1, _, ok1 = simulate_push(c.rod0, c.xg0, nb, e_true)
                td['curve'] = Curve(d1, F1); n_solved += 1
                ok &= ok1
            else:
                td['curve'] = td['curve0']
            td['ok'] = bool(ok)
    # rig compliance: choose k_rig from the median baseline stiffness
    if 'rig_compliance' in effects:
        ks = np.array([td['curve0'](0.004) / 0.004 for c in canes for td in c.trial_data])
        # target: median ln(1 + k/k_rig) ~ 0.35 on the canes without other effects
        lo, hi = 1.0, 1e6
        for _ in range(60):
            mid = np.sqrt(lo * hi)
            if np.median(np.log1p(ks / mid)) > 0.35:
                lo = mid
            else:
                hi = mid
        P['k_rig'] = float(np.sqrt(lo * hi))
    # -------------------------------------------------------------------------
    # rig traces
    x_abs = rng.uniform(0, 600)
    ts_clock = rng.uniform(-32768, 32767)
    trial_truth = []
    for c in canes:
        for td in c.trial_data:
            rig = {}
            rig['c0'] = float(rng.choice([rng.uniform(0, 1.0), rng.uniform(1.0, 9.0), rng.uniform(1.0, 9.0)]))
            rig['tare'] = float(rng.choice([rng.uniform(-112, -15), rng.uniform(-112, -15), rng.uniform(-20, 75)]))
            rig['drift'] = float(rng.normal(0, 0.12))
            rig['noise'] = float(rng.uniform(0.6, 2.5))
            rig['it0'] = 2 if rng.random() < 0.85 else 3
            x_abs = (x_abs + rng.uniform(30, 60)) % 1150
            rig['x0'] = round(x_abs * 2) / 2
            ts_clock = ts_clock + rng.uniform(20000, 60000)
            rig['ts0'] = float(round(ts_clock))
            rig['slip'] = None
            rig['trunc'] = None
            rig['pauses'] = []
            if H['pauses']:
                for _ in range(int(rng.choice([0, 1, 1, 2]))):
                    rig['pauses'].append((int(rng.integers(15, 80)), float(rng.choice([1500, 2500, 4000, 6000, 9000]))))
            curve = td['curve']
            curve0 = td['curve0']
            if 'rig_compliance' in effects:
                cx = series_curve(curve, P['k_rig'])
            else:
                cx = curve
            visco = (P['g_inf'], P['tau_s']) if 'viscoelastic' in effects else None
            td['obstruction_onset_mm'] = None
            # obstruction: second body near the push point, along the probe axis
            if 'obstruction' in effects:
                j, xp, tms, Fgf = trace(cx, rig)
                over = np.nonzero(rig['tare'] + Fgf >= 1000)[0]
                d_stop = min(43.5 - rig['c0'], (xp[over[0]] - rig['c0']) if len(over) else 99.0)
                if d_stop > 10.0 and rng.random() < 0.36:
                    rod0 = c.rod0
                    s_o = max(0.05, td['s'] - rng.uniform(0.0, 0.1))
                    # need a node at s_o: build a rod with it
                    c.special_s.append(s_o)
                    r_o = rod_for(c, E=c.E)
                    xg_o, _ = r_o.gravity_state()
                    n_p, n_o = node_of(r_o, td['s']), node_of(r_o, s_o)
                    dd, FF, recs, ok = simulate_push(r_o, xg_o, n_p, td['e'], (), [n_o])
                    onset = float(rng.uniform(0.3, 0.62) * d_stop)
                    g_on = np.interp(onset * 1e-3, dd, (recs[:, 0, :] - recs[0, 0, :]) @ td['e'])
                    k0 = FF[1] / dd[1]
                    k_o = float(rng.uniform(2.0, 4.5) * k0 * ((td['s'] / s_o) ** 3 if s_o > 0 else 1))
                    anchor = recs[0, 0, :]
                    spr = [dict(kind='gap', node=n_o, k=k_o, anchor=anchor, e=td['e'], gap=float(g_on), w=1.5e-4)]
                    dd2, FF2, _, ok2 = simulate_push(r_o, xg_o, n_p, td['e'], spr, max_step=0.7e-3)
                    n_solved += 2
                    td['curve'] = Curve(dd2, FF2)
                    cx = td['curve']
                    td['obstruction_onset_mm'] = onset
                    td['obstruction'] = dict(s_m=s_o, k_N_per_m=k_o, gap_mm=float(g_on * 1e3))
                    c.special_s.remove(s_o)
            else:
                # slips and truncations (kept out of the obstruction set so elbows stay clean)
                pass
            u = rng.random()
            if u < 0.06 and td['obstruction_onset_mm'] is None:
                rig['slip'] = (int(rng.integers(25, 70)), float(rng.uniform(1.5, 5.0)))
            elif u < 0.10 and td['obstruction_onset_mm'] is None:
                rig['trunc'] = int(rng.integers(24, 60))
            j, xp, tms, Fgf = trace(cx, rig, visco)
            raw = rig_rows(Fgf, rig, rng)
            td['rig'] = rig
            td['n_rows'] = len(raw)
            # clean slopes with and without the hidden effects, same rig geometry (no slip/noise)
            rig_clean = dict(rig, slip=None, trunc=None)
            _, _, _, Fw = trace(cx, rig_clean, visco)
            _, _, _, Fo = trace(curve0, rig_clean, None)
            kw = clean_slope(Fw, rig['tare'], c0=rig['c0'])
            ko = clean_slope(Fo, rig['tare'], c0=rig['c0'])
            td['k_with'] = kw; td['k_without'] = ko
            # per-effect sizes (each effect alone vs baseline)
            td['raw'] = raw; td['tms'] = tms
    # per-effect sizes for two-effect set: compute each alone (cheap for rig; flare alone = curve)
    for c in canes:
        for td in c.trial_data:
            rig_clean = dict(td['rig'], slip=None, trunc=None)
            _, _, _, Fo = trace(td['curve0'], rig_clean, None)
            ko = clean_slope(Fo, td['rig']['tare'], c0=td['rig']['c0'])
            td['size_by_effect'] = {}
            if ko is None:
                continue
            for e in effects:
                if e == 'rig_compliance':
                    cx = series_curve(td['curve0'], P['k_rig'])
                    v = None
                elif e == 'base_flare' and 'rig_compliance' in effects:
                    cx = td['curve']; v = None
                elif e == 'viscoelastic':
                    cx = td['curve']; v = (P['g_inf'], P['tau_s'])
                else:
                    cx = td['curve']; v = None
                if e == 'obstruction' and td['obstruction_onset_mm'] is None:
                    continue
                if e == 'crack' and not (c.crack and td['s'] > c.crack_s):
                    td['size_by_effect'][e] = 0.0
                    continue
                _, _, _, Fe = trace(cx, rig_clean, v)
                ke = clean_slope(Fe, td['rig']['tare'], c0=td['rig']['c0'])
                if ke is not None:
                    td['size_by_effect'][e] = float(np.log(ke / ko))
    # -------------------------------------------------------------------------
    # write files
    def trial_path(c, tno):
        if H['naming'] == 'field':
            return f'trials/bush_{c.bush}_branch_{c.cane}_trial_{tno}.csv'
        if H['naming'] == 'nested':
            return f'trials/bush{c.bush}/cane{c.cane}_push{tno}.csv'
        return f'rig/B{c.bush}C{c.cane}T{tno}.csv'

    def hround(z_m):
        mm = z_m * 1000
        if H['hround'] == 'cm':
            return int(round(mm / 10) * 10)
        if H['hround'] == '5mm':
            return int(round(mm / 5) * 5)
        return int(round(mm))

    for c in canes:
        dfun = diam_fn(c, flare=c.flare is not None)
        pos_g = c.rod0.positions(c.xg0)
        grid = c.rod0.grid
        pts = chaikin_free_digitize(c, pos_g, grid, rng, H)
        for td in c.trial_data:
            rel = trial_path(c, td['trial'])
            hmm = hround(td['z'])
            write_csv(os.path.join(ddir, rel), td['rig'], td['raw'], td['tms'], hmm)
            d_pp = dfun(td['s']) * 1000 + rng.normal(0, 0.15)
            pp_rows.append([c.bush, c.cane, td['trial'], hmm, round(float(d_pp), 1), rel])
            td['file'] = rel; td['height_mm_recorded'] = hmm
        # YAML
        y = []
        y.append(f'id: {c.id}')
        y.append('polyline:')
        y.append(f"  raw: {'true' if H['poly'] == 'raw' else 'false'}")
        y.append('  points:')
        for p in pts:
            y.append(f'    - [{fmt(p[0])}, {fmt(p[1])}, {fmt(p[2])}]')
        y.append('calipers:')
        for k, sc in enumerate(c.cal_s):
            dm = dfun(sc) + rng.normal(0, 0.00015)
            dm = round(dm * 1e4) / 1e4
            use_s = H['cal'] == 's' or (H['cal'] == 'mixed' and k % 2 == 1)
            if use_s:
                y.append(f'  - {{s: {fmt(sc, 3)}, diameter: {fmt(dm, 4)}}}')
            else:
                zc = interp_curve(c.s_fine, c.r_fine, sc)[0, 2]
                y.append(f'  - {{height: {fmt(zc, 3)}, diameter: {fmt(dm, 4)}}}')
        y.append('push_points:')
        for td in sorted(c.trial_data, key=lambda t: t['trial']):
            y.append(f'  - id: "{td["trial"]}"')
            if H['pp_loc'] == 's':
                y.append(f'    s: {fmt(round(td["s"] * 200) / 200, 3)}')   # tape measure along the cane, 5 mm
            else:
                y.append(f'    height: {fmt(td["height_mm_recorded"] / 1000.0, 3)}')
            a = td['az'].copy()
            if H['dir_junk']:
                a = a * rng.uniform(0.5, 3.0)
                a[2] = rng.uniform(-0.3, 0.3)
            y.append(f'    direction: [{fmt(a[0], 4)}, {fmt(a[1], 4)}, {fmt(a[2], 4)}]')
            y.append(f'    trial: ../{td["file"]}')
        y.append('material:')
        y.append('  flexural_modulus: 4.57e+9')
        y.append('  density: 580.0')
        y.append('  joint_damping: 0.15')
        y.append('provenance:')
        y.append('  synthetic: true')
        y.append('  assumptions: ["independent synthetic set (indep11); geometry digitized from the loaded cane"]')
        with open(os.path.join(ddir, 'canes', f'{c.id}.yaml'), 'w') as f:
            f.write('\n'.join(y) + '\n')
    if H['shuffle_csv']:
        rng.shuffle(pp_rows)
    else:
        pp_rows.sort(key=lambda r: (r[0], r[1], r[2]))
    with open(os.path.join(ddir, 'push_points.csv'), 'w', newline='') as f:
        f.write('bush,cane,trial,height_mm,diameter_mm,file\r\n')
        for r_ in pp_rows:
            f.write(','.join(str(v) for v in r_) + '\r\n')
    # -------------------------------------------------------------------------
    # truth
    hidden = []
    for e in effects:
        sz = [td['size_by_effect'].get(e) for c in canes for td in c.trial_data]
        sz = [v for v in sz if v is not None]
        entry = dict(effect=e, in_library=e in ('modulus_scale', 'root_compliance', 'rig_compliance', 'base_flare',
                                                  'probe_misalignment', 'obstruction'))
        if e == 'modulus_scale':
            entry.update(scope='global', params={'scale': P['scale']})
        elif e == 'root_compliance':
            entry.update(scope='per_bush', params={'k_root_by_bush': P['k_root_by_bush'],
                                                   'k_root_by_cane': {c.id: P['k_root_by_bush'][str(c.bush)] for c in canes}})
        elif e == 'rig_compliance':
            entry.update(scope='global', params={'k_rig': P['k_rig']})
        elif e == 'probe_misalignment':
            entry.update(scope='global', params={'angle_deg': P['angle_deg']})
        elif e == 'base_flare':
            entry.update(scope='per_cane', params={'law': 'd(s) = d_taper(s) * (1 + A exp(-s/lambda))',
                                                   'A_median': P['flare_A_median'], 'lambda_m_median': P['flare_lambda_median'],
                                                   'by_cane': {c.id: {'A': c.flare[0], 'lambda_m': c.flare[1]} for c in canes}})
        elif e == 'obstruction':
            entry.update(scope='per_trial', params={'n_trials_obstructed': int(sum(td['obstruction_onset_mm'] is not None for c in canes for td in c.trial_data))})
        elif e == 'trellis_wire':
            entry.update(scope='per_cane', note=OOL_NOTES[e], params={'by_cane': {c.id: {'s_m': c.wire_s, 'k_N_per_m': c.wire_k} for c in canes}})
        elif e == 'viscoelastic':
            entry.update(scope='global', note=OOL_NOTES[e], params={'g_inf': P['g_inf'], 'tau_s': P['tau_s']})
        elif e == 'crack':
            entry.update(scope='per_cane', note=OOL_NOTES[e], params={'by_cane': {c.id: {'s_m': c.crack_s, 'k_bend_N_m_per_rad': c.crack_k} for c in canes if c.crack}})
        nz = [abs(v) for v in sz if v != 0.0]
        entry['size'] = dict(median_abs_log_ratio_all_trials=float(np.median(np.abs(sz))) if sz else None,
                             median_abs_log_ratio_affected=float(np.median(nz)) if nz else None,
                             median_log_ratio=float(np.median(sz)) if sz else None,
                             n_trials=len(sz),
                             noise_reference_sd_ln_E=SD_LN_E,
                             definition='ln(k_with/k_without) per trial, rig-style slope (net > 20 gf, before the 1000 gf raw stop, '
                                        'first 45 mm of contact), noise-free; obstruction: obstructed trials only; crack: trials above the crack')
        hidden.append(entry)
    comb = [np.log(td['k_with'] / td['k_without']) for c in canes for td in c.trial_data
            if td['k_with'] and td['k_without']]
    truth = dict(
        dataset=dsid, seed=cfg['seed'], generator='indep11/make.py',
        expected=dict(named=cfg['expect'], unexplained=cfg['unexplained'],
                      note='named: the library effects the tool should name (nothing else); '
                           'unexplained: whether an out-of-library effect is present'),
        hidden_effects=hidden,
        combined_size_median_abs_log_ratio=float(np.median(np.abs(comb))) if comb else None,
        per_cane_modulus=dict(stated=E_STATED, sd_ln=SD_LN_E, recentred_geomean=True,
                              by_cane={c.id: c.E_rel * E_STATED * P.get('scale', 1.0) for c in canes}),
        habits=H,
        rig_notes='tare -112..75 gf, drift ~N(0,0.12) gf/sample, noise 0.6-2.5 gf + 1.2% spikes, dead zone 0-9 mm, '
                  '0.5 mm steps, 500 ms stamps (16-bit wrap), stop at raw >= 1000 gf, <= 88 rows, ~6% slips, ~4% truncations',
        canes=[dict(id=c.id, bush=c.bush, cane=c.cane, L_m=c.L, E_rel=c.E_rel, d_base_m=c.d_base, d_tip_m=c.d_tip,
                    taper_exponent=c.p, twist_rad_per_m=c.omega, azimuth_mode=c.az_mode,
                    knot_at_caliper=c.knot_at_caliper, caliper_s_m=c.cal_s.tolist(),
                    flare=(list(c.flare) if c.flare is not None else None)) for c in canes],
        trials=[dict(bush=c.bush, cane=c.cane, trial=td['trial'], id=f'b{c.bush}c{c.cane}t{td["trial"]}',
                     file=td['file'], stem=os.path.splitext(os.path.basename(td['file']))[0],
                     s_m=td['s'], height_true_mm=td['z'] * 1000, height_recorded_mm=td['height_mm_recorded'],
                     probe_axis=td['e'].tolist(), pitch_perp_deg=td['pitch_perp_deg'],
                     dead_zone_mm=td['rig']['c0'], tare_gf=td['rig']['tare'], slip=td['rig']['slip'],
                     truncated_at_row=td['rig']['trunc'], pauses=td['rig']['pauses'], n_rows=td['n_rows'],
                     k_with_N_per_mm=td['k_with'],
                     k_without_N_per_mm=td['k_without'],
                     size_by_effect=td['size_by_effect'],
                     obstruction_onset_mm=td['obstruction_onset_mm'],
                     obstruction=td.get('obstruction'), solver_ok=td['ok'])
                for c in canes for td in c.trial_data],
    )
    os.makedirs(os.path.join(out_root, 'truth'), exist_ok=True)
    with open(os.path.join(out_root, 'truth', f'{dsid}.json'), 'w') as f:
        json.dump(truth, f, indent=1)
    ks = [t['k_with_N_per_mm'] for t in truth['trials'] if t['k_with_N_per_mm']]
    print(f"{dsid}: {len(canes)} canes, {len(truth['trials'])} trials, effects {effects}, "
          f"k {min(ks):.3f}-{max(ks):.3f} N/mm, sizes "
          + ', '.join(f"{h['effect']}={h['size']['median_abs_log_ratio_all_trials']:.3f}"
                      + (f"/{h['size']['median_abs_log_ratio_affected']:.3f}" if h['size']['median_abs_log_ratio_affected'] else '')
                      for h in hidden)
          + f", solves {n_solved}, all ok {all(t['solver_ok'] for t in truth['trials'])}, {time.time() - t_start:.1f}s", flush=True)
    return truth


def validate(ddir):
    import yaml, csv
    errs = []
    rows = list(csv.DictReader(open(os.path.join(ddir, 'push_points.csv'), newline='')))
    files = set()
    for r in rows:
        if not os.path.exists(os.path.join(ddir, r['file'])):
            errs.append(f"missing {r['file']}")
        files.add(os.path.normpath(r['file']))
    for fn in sorted(os.listdir(os.path.join(ddir, 'canes'))):
        y = yaml.safe_load(open(os.path.join(ddir, 'canes', fn)))
        cid = fn[:-5]
        if y['id'] != cid or not (cid.startswith('b') and 'c' in cid):
            errs.append(f'{fn}: id')
        pts = np.array(y['polyline']['points'], float)
        if len(pts) < 2 or np.any(np.linalg.norm(np.diff(pts, axis=0), axis=1) == 0):
            errs.append(f'{fn}: polyline')
        if pts[0, 2] > pts[:, 2].min() + 1e-9:
            errs.append(f'{fn}: base not first/lowest')
        if len(y['calipers']) != 3:
            errs.append(f'{fn}: calipers')
        for k, cp in enumerate(y['calipers']):
            if (('s' in cp) + ('height' in cp)) != 1 or not cp['diameter'] > 0:
                errs.append(f'{fn}: calipers[{k}]')
            if 'height' in cp and not (pts[0, 2] <= cp['height'] <= pts[:, 2].max()):
                errs.append(f'{fn}: calipers[{k}] height off cane')
        ids = [p['id'] for p in y['push_points']]
        if len(set(ids)) != len(ids) or len(ids) < 1:
            errs.append(f'{fn}: push ids')
        for p in y['push_points']:
            if (('s' in p) + ('height' in p)) != 1:
                errs.append(f'{fn}: push loc')
            tf = os.path.normpath(os.path.join('canes', p['trial']))
            if tf not in files:
                errs.append(f'{fn}: trial {p["trial"]} not in push_points.csv')
            b, c_ = cid[1:].split('c')
            if not any(r['bush'] == b and r['cane'] == c_ and os.path.normpath(r['file']) == tf for r in rows):
                errs.append(f'{fn}: trial row mismatch')
        if y['material']['flexural_modulus'] != 4.57e9:
            errs.append(f'{fn}: modulus')
    return errs


if __name__ == '__main__':
    ap = argparse.ArgumentParser()
    ap.add_argument('--only', default='')
    ap.add_argument('--out', default=os.path.dirname(os.path.abspath(__file__)))
    a = ap.parse_args()
    only = set(a.only.split(',')) if a.only else None
    t0 = time.time()
    for cfg in DATASETS:
        if only and cfg['id'] not in only:
            continue
        make_dataset(cfg, a.out)
        errs = validate(os.path.join(a.out, 'data', cfg['id']))
        if errs:
            print('  VALIDATION ERRORS:', errs[:10])
            sys.exit(1)
    print(f'done in {time.time() - t0:.0f}s')
