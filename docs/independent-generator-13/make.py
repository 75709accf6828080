"""Generate the indep13 synthetic test bed: data/ds01..ds12 and truth/dsNN.json.

usage: python make.py [--seed 1313] [--only ds03,ds07] [--out DIR]

Deterministic from the seed (each set draws from its own generator seeded by
seed and set number).  One core, no multiprocessing.
"""
import os as _os
for _v in ('OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS', 'MKL_NUM_THREADS'):
    _os.environ.setdefault(_v, '1')  # one core only


import argparse
import json
import os
import shutil
import sys
import time

import numpy as np
import yaml

from rod import Chain, Solver, Interaction, chain_from_curve

HERE = os.path.dirname(os.path.abspath(__file__))
GF = 9.80665e-3            # N per gram-force
DEFAULT_E = 4.57e9         # the documented default stated modulus
STEP = 0.5e-3              # rig step, m
MAX_ROWS = 88              # iterations 2..89
H_ELEM = 0.008             # target element length of the truth solver (m)

# --------------------------------------------------------------------------
# the sets
# --------------------------------------------------------------------------
BASE = dict(
    n_bush=6, n_cane=3, sigma_lnE=0.15, stated_E=None, scale=1.0,
    noise_gf=1.5, cal_rule='span', cal_noise_mm=0.12, cal_by_s=0.4,
    n_clicks=(10, 15), click_noise=0.0025, lean_deg=(-8, 8), turn_deg=(-25, 25),
    d_push=(8.0, 17.0), top_push=(0.72, 0.98),
    k_root=None, k_root_by_bush=None, k_rig=None, flare=None, angle=0.0, jitter_deg=2.0,
    obstruct_frac=0.0, rub=None, soft=None, push_by_s=False, csv_style='field',
    description='', habit='', expected=[], unexplained=False, ool=None,
)

SETS = {
    'ds01': dict(
        description='null: stated modulus 6.3 GPa in every YAML (true median 6.3 GPa)',
        habit='material.flexural_modulus stated as 6.3e9 (far from the 4.57 GPa default); '
              'moderately curved canes (15-35 deg of turning)',
        stated_E=6.3e9, turn_deg=(15, 35), sigma_lnE=0.15, noise_gf=1.4),
    'ds02': dict(
        description='modulus_scale 0.58 global (E_true = 0.58 x stated 4.57 GPa)',
        habit='no material block (default modulus); 5 bushes x 3 canes',
        n_bush=5, scale=0.58, sigma_lnE=0.14, noise_gf=2.5,
        expected=[dict(effect='modulus_scale', scope='global', params=dict(scale=0.58))]),
    'ds03': dict(
        description='root_compliance varying by plant (k_root 20..170 N m/rad by bush, +-10 % per cane)',
        habit='5 bushes x 3 canes, thick bases; calipers spanning base to top push',
        n_bush=5, sigma_lnE=0.12, stated_E=4.57e9, d_push=(8.0, 15.0),
        k_root_by_bush=[20.0, 35.0, 60.0, 100.0, 170.0], noise_gf=1.6,
        expected=[dict(effect='root_compliance', scope='per_cane', params=dict(k_root='per_cane'))]),
    'ds04': dict(
        description='rig_compliance k_rig = 320 N/m global',
        habit='4 bushes x 4 canes; thick canes so that many trials are stiff',
        n_bush=4, n_cane=4, k_rig=320.0, sigma_lnE=0.14, d_push=(10.0, 18.0),
        noise_gf=3.0, csv_style='dash',
        expected=[dict(effect='rig_compliance', scope='global', params=dict(k_rig=320.0))]),
    'ds05': dict(
        description='base_flare: d x (1 + A exp(-s/l)), A 0.55-0.80, l 0.10-0.15 m, calipers above 0.48 m',
        habit='6 bushes x 2 canes (36 trials); calipers on the upper cane only (0.48 m to top push)',
        n_cane=2, sigma_lnE=0.13, cal_rule='upper', flare=dict(A=(0.55, 0.80), l=(0.10, 0.15)),
        noise_gf=1.2,
        expected=[dict(effect='base_flare', scope='global', params={})]),
    'ds06': dict(
        description='probe_misalignment +32 deg (toward +z) global, per-trial jitter 2 deg',
        habit='4 bushes x 4 canes; low between-cane scatter (sigma ln E 0.07)',
        n_bush=4, n_cane=4, angle=32.0, sigma_lnE=0.07, cal_noise_mm=0.08, noise_gf=1.3,
        expected=[dict(effect='probe_misalignment', scope='global', params=dict(angle_deg=32.0))]),
    'ds07': dict(
        description='obstruction in ~35 % of trials (second body near the push, 1.8-3.5x stiffening)',
        habit='6 bushes x 3 canes, calipers given by arc length s only',
        obstruct_frac=0.35, cal_by_s=1.0, sigma_lnE=0.15, noise_gf=2.2,
        expected=[dict(effect='obstruction', scope='per_trial', params={})]),
    'ds08': dict(
        description='null: canes leaning 20-30 deg in the push plane, pushed toward and away from the lean',
        habit='3 bushes x 6 canes (many canes per bush); push points located by arc length s; '
              'no material block',
        n_bush=3, n_cane=6, lean_deg=(20, 30), lean_signed=True, turn_deg=(-15, 15),
        push_by_s=True, sigma_lnE=0.15, noise_gf=2.8, top_push=(0.70, 0.92)),
    'ds09': dict(
        description='modulus_scale 1.55 (stated 3.6 GPa, true median 5.58 GPa) + obstruction in ~30 % of trials',
        habit='5 bushes x 3 canes; stated 3.6 GPa',
        n_bush=5, stated_E=3.6e9, scale=1.55, obstruct_frac=0.30, sigma_lnE=0.14, noise_gf=1.7,
        expected=[dict(effect='modulus_scale', scope='global', params=dict(scale=1.55)),
                  dict(effect='obstruction', scope='per_trial', params={})]),
    'ds10': dict(
        description='root_compliance k_root = 60 N m/rad + probe_misalignment -30 deg (toward -z), global',
        habit='6 bushes x 3 canes, low scatter (sigma ln E 0.08)',
        k_root=60.0, angle=-30.0, sigma_lnE=0.08, cal_noise_mm=0.08, noise_gf=1.5,
        csv_style='dash',
        expected=[dict(effect='root_compliance', scope='global', params=dict(k_root=60.0)),
                  dict(effect='probe_misalignment', scope='global', params=dict(angle_deg=-30.0))]),
    'ds11': dict(
        description='OOL: stick-slip frictional rub against a crossing neighbour cane below the pushes '
                    '(most canes): stiff stick phase, then a sawtooth of slips',
        habit='5 bushes x 3 canes',
        n_bush=5, rub=dict(frac=0.87, z=(0.28, 0.45), mus_N=(3.0, 5.0), ratio_k=(0.35, 0.50),
                           kc_rel=(1.2, 2.5)),
        sigma_lnE=0.14, noise_gf=2.0, unexplained=True, ool='stick-slip rub'),
    'ds12': dict(
        description='OOL: strain-softening (nonlinear-elastic green) wood everywhere along the cane: '
                    'M = EI[(1-b) k + b k_y tanh(k/k_y)], b = 0.70, yield strain 0.07-0.10 %',
        habit='8 bushes x 2 canes (few canes per bush)',
        n_bush=8, n_cane=2, soft=dict(beta=0.70, eps_y=(0.0007, 0.0010)), sigma_lnE=0.14,
        noise_gf=2.5, unexplained=True, ool='strain-softening wood'),
}


# --------------------------------------------------------------------------
# geometry of one cane (truth)
# --------------------------------------------------------------------------
class Cane:
    def __init__(self, rng, cfg, bush, cane, E_true, base_xy):
        self.bush, self.cane = bush, cane
        self.id = 'b%dc%d' % (bush, cane)
        self.L = rng.uniform(1.35, 1.85)
        lean = rng.uniform(*cfg['lean_deg'])
        if cfg.get('lean_signed'):
            lean *= rng.choice([-1.0, 1.0])
        turn = rng.uniform(*cfg['turn_deg']) * rng.choice([-1.0, 1.0])
        # angle from vertical along s: lean + turn distributed (more near the top) + a wiggle
        w_amp = np.radians(rng.uniform(0.5, 2.0))
        w_k = rng.uniform(4.0, 9.0)
        w_ph = rng.uniform(0, 2 * np.pi)
        frac = rng.uniform(0.3, 0.7)
        s = np.linspace(0, self.L, 4001)
        tt = s / self.L
        th = (np.radians(lean) + np.radians(turn) * (frac * tt + (1 - frac) * tt ** 2)
              + w_amp * np.sin(w_k * s + w_ph) - w_amp * np.sin(w_ph))
        ds = s[1] - s[0]
        x = np.concatenate([[0], np.cumsum(0.5 * (np.sin(th[1:]) + np.sin(th[:-1])) * ds)])
        z = np.concatenate([[0], np.cumsum(0.5 * (np.cos(th[1:]) + np.cos(th[:-1])) * ds)])
        self.s_grid, self.x_grid, self.z_grid, self.th_grid = s, x, z, th
        self.lean_deg, self.turn_deg = lean, turn
        # plane azimuth (the probe approaches from the aisle: around +x), push sign
        self.psi = np.radians(rng.uniform(-30, 30))
        self.base = np.array([base_xy[0], base_xy[1], 0.0])
        # diameter law
        dp = np.exp(rng.uniform(np.log(cfg['d_push'][0]), np.log(cfg['d_push'][1]))) * 1e-3
        ratio = 1.0
        self.p_taper = rng.uniform(0.8, 1.25)
        self.d_tip = rng.uniform(2.8, 4.2) * 1e-3
        self._dp, self._ratio = dp, ratio
        # bud bumps: gaussians +-2..4 % of 10-20 mm width
        nb = rng.integers(6, 12)
        self.bumps = [(rng.uniform(0.05, self.L - 0.05), rng.uniform(-0.035, 0.04),
                       rng.uniform(0.005, 0.010)) for _ in range(nb)]
        self.flare = None
        if cfg['flare']:
            self.flare = (rng.uniform(*cfg['flare']['A']), rng.uniform(*cfg['flare']['l']))
        self.E = E_true
        self.z_top = float(z[-1])

    def set_base_diameter(self, s_ref):
        """d_base such that the smooth law passes through d_push at s_ref"""
        xp = (s_ref / self.L) ** self.p_taper
        self.d_base = (self._dp - self.d_tip * xp) / (1 - xp)

    def d_smooth(self, s):
        s = np.clip(np.asarray(s, float) / self.L, 0, 1)
        return self.d_base - (self.d_base - self.d_tip) * s ** self.p_taper

    def d(self, s, flare=True):
        s = np.asarray(s, float)
        out = self.d_smooth(s)
        bump = np.zeros_like(s)
        for c, a, w in self.bumps:
            bump += a * np.exp(-0.5 * ((s - c) / w) ** 2)
        out = out * (1 + bump)
        if flare and self.flare is not None:
            A, l = self.flare
            out = out * (1 + A * np.exp(-s / l))
        return out

    def EI(self, s, flare=True, E=None):
        E = self.E if E is None else E
        return E * np.pi * self.d(s, flare) ** 4 / 64

    def xz(self, s):
        return (float(np.interp(s, self.s_grid, self.x_grid)),
                float(np.interp(s, self.s_grid, self.z_grid)))

    def s_at_height(self, z):
        return float(np.interp(z, self.z_grid, self.s_grid))

    def to3d(self, x, z, y=0.0):
        c, sn = np.cos(self.psi), np.sin(self.psi)
        return self.base + np.array([x * c - y * sn, x * sn + y * c, z])


def probe_dir_2d(xz_fn, s_p, L, sign, angle_deg, window=0.15):
    """perpendicular to the chord over +-window, horizontal part along sign*x,
    then pitched by angle_deg toward +z.  Returns (d, n, t_up)."""
    a = np.array(xz_fn(max(0.0, s_p - window)))
    b = np.array(xz_fn(min(L, s_p + window)))
    t = (b - a) / np.linalg.norm(b - a)
    if t[1] < 0:
        t = -t
    n = np.array([t[1], -t[0]])
    if n[0] * sign < 0:
        n = -n
    ph = np.radians(angle_deg)
    # rotate toward +z: use t_up (positive z component)
    d = np.cos(ph) * n + np.sin(ph) * t
    return d / np.linalg.norm(d), n, t


# --------------------------------------------------------------------------
# the model as the files describe it (for the noise / bias estimate only)
# --------------------------------------------------------------------------
def chaikin(P, it=5, q=0.25):
    P = np.asarray(P, float)
    for _ in range(it):
        Q = [P[0]]
        for a, b in zip(P[:-1], P[1:]):
            Q.append((1 - q) * a + q * b)
            Q.append(q * a + (1 - q) * b)
        Q.append(P[-1])
        P = np.array(Q)
    return P


class View:
    """the cane as a reader of the files would build it (stated E, linear taper
    through the calipers, smoothed polyline, perpendicular probe, clamp)."""

    def __init__(self, cane, clicks3d, calipers, E_stated):
        loc = clicks3d - cane.base
        c, sn = np.cos(cane.psi), np.sin(cane.psi)
        x = loc[:, 0] * c + loc[:, 1] * sn
        z = loc[:, 2] + cane.base[2]
        P = chaikin(np.stack([x, z], axis=1))
        seg = np.hypot(*np.diff(P, axis=0).T)
        self.S = np.concatenate([[0], np.cumsum(seg)])
        self.P = P
        self.L = self.S[-1]
        ss, dd = [], []
        for cal in calipers:
            if 's' in cal:
                ss.append(cal['s'])
            else:
                ss.append(self.s_at_height(cal['height']))
            dd.append(cal['diameter'])
        self.fit = np.polyfit(ss, dd, 1)
        self.E = E_stated

    def xz(self, s):
        return (float(np.interp(s, self.S, self.P[:, 0])), float(np.interp(s, self.S, self.P[:, 1])))

    def s_at_height(self, z):
        zz = self.P[:, 1]
        i = int(np.argmax(zz >= z))
        if i == 0:
            return 0.0
        f = (z - zz[i - 1]) / (zz[i] - zz[i - 1])
        return float(self.S[i - 1] + f * (self.S[i] - self.S[i - 1]))

    def EI(self, s):
        d = np.maximum(np.polyval(self.fit, np.asarray(s, float)), 1e-3)
        return self.E * np.pi * d ** 4 / 64


# --------------------------------------------------------------------------
# pushing
# --------------------------------------------------------------------------
def slope_fit(u, F):
    """rig-style stiffness: LSQ slope of F on u over 20 gf < F <= 1000 gf, u <= 43.5 mm"""
    u, F = np.asarray(u), np.asarray(F)
    m = (F > 20 * GF) & (u <= 0.0435 + 1e-9)
    stop = np.nonzero(F >= 1000 * GF)[0]
    if len(stop):
        m &= np.arange(len(F)) <= stop[0]
    if m.sum() < 3:
        m = F > 0
    if m.sum() < 2:
        return float('nan')
    return float(np.polyfit(u[m], F[m], 1)[0])


def shape_rms_gf(u, F):
    """RMS (gf) of the residual about the rig-style straight-line fit (noise free)"""
    u, F = np.asarray(u), np.asarray(F)
    m = (F > 20 * GF) & (u <= 0.0435 + 1e-9)
    stop = np.nonzero(F >= 1000 * GF)[0]
    if len(stop):
        m &= np.arange(len(F)) <= stop[0]
    if m.sum() < 4:
        return 0.0
    p = np.polyfit(u[m], F[m], 1)
    return float(np.sqrt(np.mean((F[m] - np.polyval(p, u[m])) ** 2)) / GF)


def coarse_curve(solver, du=1.5e-3, umax=0.0435):
    us, Fs = [], []
    u = du
    while u <= umax + 1e-12:
        F = solver.advance(u)
        us.append(u)
        Fs.append(F)
        if F >= 1000 * GF:
            break
        u += du
    return np.array(us), np.array(Fs)


def build_solver(cane_like, EI_fn, s_p, d, k_root=None, k_rig=None, extra_s=(), soft=None,
                 inter_fn=None, h=H_ELEM):
    s_max = max([s_p] + list(extra_s))
    ch, where = chain_from_curve(cane_like.xz, EI_fn, [s_p] + list(extra_s), s_max,
                                 h_target=h, k_root=k_root, soft=soft)
    inter = inter_fn(where) if inter_fn else []
    return Solver(ch, where[s_p], d, k_rig=k_rig, inter=inter), where


# --------------------------------------------------------------------------
# rig CSV
# --------------------------------------------------------------------------
def fmt_float(v, nd=2):
    r = round(float(v), nd)
    if r == 0:
        r = 0.0
    return repr(r)


class RigClock:
    """the rig's running counters: 16-bit ms time stamp and absolute probe position"""

    def __init__(self, rng):
        self.rng = rng
        self.t_ms = int(rng.integers(-30000, 30000))
        self.pos_mm = float(rng.integers(0, 400)) * 0.5

    def reset(self):
        self.t_ms = 0
        self.pos_mm = 0.0

    def rows(self, loads, height_mm):
        it0 = 3 if self.rng.random() < 0.15 else 2
        out = []
        for k, f in enumerate(loads):
            it = it0 + k
            t = self.t_ms + 500 * it
            tw = ((t + 32768) % 65536) - 32768
            pos = self.pos_mm + 0.5 * it
            out.append('%s,%s,%s,%s,%d' % (fmt_float(it, 1), fmt_float(tw, 1), fmt_float(f, 2),
                                           fmt_float(pos, 1), height_mm))
        last_it = it0 + len(loads) - 1
        self.t_ms = self.t_ms + 500 * last_it
        self.pos_mm = self.pos_mm + 0.5 * last_it
        return out


HEADER = 'Iteration,Time Stamp,Load Cell Reading (gf),Displacement (mm),Height (mm)'


# --------------------------------------------------------------------------
# one set
# --------------------------------------------------------------------------
def make_set(name, cfg_over, seed, out_root):
    t0 = time.time()
    cfg = dict(BASE)
    cfg.update(cfg_over)
    num = int(name[2:])
    rng = np.random.default_rng([seed, num])
    data = os.path.join(out_root, 'data', name)
    if os.path.isdir(data):
        shutil.rmtree(data)
    os.makedirs(os.path.join(data, 'canes'))
    os.makedirs(os.path.join(data, 'trials'))
    stated = cfg['stated_E'] if cfg['stated_E'] else DEFAULT_E
    E_med_true = stated * cfg['scale']

    canes = []
    # per-cane log-normal modulus; z-scores centred within the set so that the
    # set's geometric-mean modulus is exactly the stated median (no lucky sets)
    zE = rng.standard_normal(cfg['n_bush'] * cfg['n_cane'])
    zE = (zE - zE.mean()) / zE.std(ddof=1)
    for b in range(1, cfg['n_bush'] + 1):
        bush_y = (b - 1) * 1.25
        for c in range(1, cfg['n_cane'] + 1):
            E = E_med_true * np.exp(cfg['sigma_lnE'] * zE[(b - 1) * cfg['n_cane'] + c - 1])
            base_xy = (rng.uniform(-0.08, 0.08), bush_y + rng.uniform(-0.10, 0.10))
            canes.append(Cane(rng, cfg, b, c, E, base_xy))

    truth_canes, truth_trials, push_rows, ob_truth = {}, {}, [], {}
    clock = RigClock(rng)
    angle_glob = cfg['angle']
    for cane in canes:
        # ---- push points (truth heights), trial 1 highest
        top = min(rng.uniform(*cfg['top_push']), cane.z_top - 0.25)
        heights = [top]
        for _ in range(2):
            heights.append(heights[-1] - rng.uniform(0.088, 0.112))
        s_push = [cane.s_at_height(hh) for hh in heights]
        cane.set_base_diameter(s_push[1])
        # root
        k_root = cfg['k_root']
        if cfg['k_root_by_bush']:
            k_root = cfg['k_root_by_bush'][cane.bush - 1] * float(np.exp(0.10 * rng.standard_normal()))
        # rub (stick-slip) per cane
        rub = None
        if cfg['rub'] and rng.random() < cfg['rub']['frac']:
            R = cfg['rub']
            z_f = rng.uniform(*R['z'])
            rub = dict(s=cane.s_at_height(z_f), z=z_f, mus=rng.uniform(*R['mus_N']),
                       ratio=rng.uniform(*R['ratio_k']), kc_rel=rng.uniform(*R['kc_rel']))
        soft = None
        if cfg['soft']:
            soft = (cfg['soft']['beta'], rng.uniform(*cfg['soft']['eps_y']), lambda s, cn=cane: cn.d(s))
        push_sign = 1.0 if rng.random() < 0.5 else -1.0
        if cfg.get('lean_signed'):
            pass  # lean sign is random already; push sign random too
        # ---- clicks (raw polyline)
        nck = int(rng.integers(cfg['n_clicks'][0], cfg['n_clicks'][1] + 1))
        gaps = cane.L / (nck - 1) * (1 + rng.uniform(-0.25, 0.25, nck - 1))
        gaps *= cane.L / gaps.sum()
        s_clk = np.concatenate([[0], np.cumsum(gaps)])
        s_clk[-1] = cane.L
        clicks = []
        for sc in s_clk:
            x, z = cane.xz(sc)
            nz = rng.normal(0, cfg['click_noise'], 3)
            p = cane.to3d(x + nz[0], z + nz[2], nz[1])
            clicks.append(p)
        clicks = np.array(clicks)
        # ---- calipers
        if cfg['cal_rule'] == 'span':
            cal_s = [rng.uniform(0.12, 0.25), rng.uniform(0.38, 0.52), s_push[0] + rng.uniform(-0.06, 0.06)]
        elif cfg['cal_rule'] == 'upper':
            cal_s = [cane.s_at_height(rng.uniform(0.48, 0.53)), rng.uniform(0.60, 0.66),
                     s_push[0] + rng.uniform(-0.04, 0.04)]
        else:
            raise ValueError(cfg['cal_rule'])
        cal_s.sort()
        calipers = []
        for sc in cal_s:
            dm = float(cane.d(sc)) * 1e3 + rng.normal(0, cfg['cal_noise_mm'])
            dm = round(dm, 1) * 1e-3
            if rng.random() < cfg['cal_by_s']:
                calipers.append({'s': round(float(sc), 3), 'diameter': round(dm, 5)})
            else:
                calipers.append({'height': round(cane.xz(sc)[1], 3), 'diameter': round(dm, 5)})
        view = View(cane, clicks, calipers, stated)

        cane_truth = dict(E=cane.E, E_over_stated=cane.E / stated, length=cane.L,
                          lean_deg=cane.lean_deg, turn_deg=cane.turn_deg,
                          d_base_mm=float(cane.d(0.0, flare=False) * 1e3),
                          d_push_mm=[float(cane.d(sp) * 1e3) for sp in s_push],
                          k_root=k_root, flare=cane.flare, rub=rub,
                          eps_y=None if soft is None else soft[1], push_sign=push_sign)
        truth_canes[cane.id] = cane_truth

        yaml_pushes = []
        order = [0, 1, 2] if rng.random() < 0.7 else list(rng.permutation(3))
        trial_files = {}
        for ti in range(3):
            t = ti + 1
            if cfg['csv_style'] == 'field':
                fn = 'trials/bush_%d_branch_%d_trial_%d.csv' % (cane.bush, cane.cane, t)
            else:
                fn = 'trials/B%d-C%d-T%d.csv' % (cane.bush, cane.cane, t)
            trial_files[ti] = fn

        for ti in order:
            t = ti + 1
            tid = '%st%d' % (cane.id, t)
            s_p = s_push[ti]
            h_true = heights[ti]
            h_tape = int(round(h_true * 1e3 + rng.normal(0, 2.5)))
            ang = angle_glob + rng.normal(0, cfg['jitter_deg'])
            d, n, tup = probe_dir_2d(cane.xz, s_p, cane.L, push_sign, ang)
            d0, _, _ = probe_dir_2d(cane.xz, s_p, cane.L, push_sign, ang - angle_glob)
            g0 = rng.uniform(0.2, 6.5) * 1e-3 if rng.random() > 0.1 else rng.uniform(6.5, 10.0) * 1e-3
            tare = rng.uniform(-110, -15) if rng.random() > 0.2 else rng.uniform(-5, 40)
            k_rig = cfg['k_rig']

            def EI_t(s, cn=cane):
                return cn.EI(s)

            # probe positions after contact at each sample
            u_s = np.arange(MAX_ROWS) * STEP - g0

            # ---------- truth trace
            extra, inter_fn = [], None
            ob = None
            if cfg['obstruct_frac'] and rng.random() < cfg['obstruct_frac']:
                ob = dict(s=min(cane.L - 0.02, s_p + rng.uniform(-0.05, 0.15)),
                          r=rng.uniform(1.8, 3.5), frac=rng.uniform(0.25, 0.65))
            if ob:
                extra.append(ob['s'])
            if rub:
                extra.append(rub['s'])
            sol, where = build_solver(cane, EI_t, s_p, d, k_root=k_root, k_rig=k_rig,
                                      extra_s=extra, soft=soft)
            # free pass (also the 'without obstruction' truth, and the rub-free one if no rub)
            F_free = np.zeros(MAX_ROWS)
            dob = np.zeros(MAX_ROWS)
            for k, u in enumerate(u_s):
                if u <= 0:
                    continue
                F_free[k] = sol.advance(u)
                if ob:
                    dob[k] = sol.node_delta(where[ob['s']], d)
                if F_free[k] + tare * GF > 1000 * GF + 0.3:
                    F_free[k + 1:] = np.nan
                    break
            F_with = F_free.copy()
            onset_mm = None
            if ob:
                valid = np.nonzero((u_s > 0) & np.isfinite(F_free))[0]
                u_end = u_s[valid[-1]]
                if u_end >= 0.012:
                    u_on = max(0.004, ob['frac'] * u_end)
                    gap = float(np.interp(u_on, u_s[valid], dob[valid]))
                    # stiffness of the cane at the probe and at the obstruction point (small load)
                    kp = F_free[valid[0]] / u_s[valid[0]]
                    ratio_dd = dob[valid[0]] / u_s[valid[0]]
                    k_o = ob['r'] * kp / max(ratio_dd, 0.2) ** 2
                    sol2, where2 = build_solver(
                        cane, EI_t, s_p, d, k_root=k_root, k_rig=k_rig, extra_s=extra, soft=soft,
                        inter_fn=lambda w: [Interaction(w[ob['s']], d, 'gap', k=k_o, gap=gap)])
                    F_with = np.zeros(MAX_ROWS)
                    for k, u in enumerate(u_s):
                        if u <= 0:
                            continue
                        F_with[k] = sol2.advance(u)
                        if F_with[k] + tare * GF > 1000 * GF + 0.3:
                            F_with[k + 1:] = np.nan
                            break
                    onset_mm = float(u_on * 1e3)
                    ob.update(gap=gap, k_o=k_o, onset_mm=onset_mm)
                else:
                    ob = None
            rub_info = None
            if rub:
                # lateral stiffness of the cane at the rub point
                solr, wr = build_solver(cane, EI_t, rub['s'], d, k_root=k_root, soft=None)
                k_lat = solr.advance(1e-5) / 1e-5
                k_c = rub['kc_rel'] * k_lat
                mus, muk = rub['mus'], rub['mus'] * rub['ratio']
                it_rub = Interaction(where[rub['s']], d, 'anchor', k=k_c, a=0.0)
                sol3, _ = build_solver(cane, EI_t, s_p, d, k_root=k_root, k_rig=k_rig,
                                       extra_s=extra, soft=soft, inter_fn=lambda w: [it_rub])
                F_with = np.zeros(MAX_ROWS)
                nslip = 0
                for k, u in enumerate(u_s):
                    if u <= 0:
                        continue
                    F = sol3.advance(u)
                    dl = sol3.node_delta(it_rub.node, d)
                    fc = k_c * (dl - it_rub.a)
                    if abs(fc) > mus:
                        it_rub.kind = 'force'
                        it_rub.f = np.sign(fc) * muk
                        th, F2, ok = sol3.solve_at(u)
                        if not ok:
                            raise RuntimeError('slip solve failed')
                        sol3.th, sol3.F = th, F2
                        dl = sol3.node_delta(it_rub.node, d)
                        it_rub.kind = 'anchor'
                        it_rub.a = dl - it_rub.f / k_c
                        F = F2
                        nslip += 1
                    F_with[k] = F
                    if F + tare * GF > 1000 * GF + 0.3:
                        F_with[k + 1:] = np.nan
                        break
                rub_info = dict(k_c=k_c, k_lat=k_lat, mus_N=mus, muk_N=muk, slips=nslip)

            # ---------- readings
            n_rows = MAX_ROWS
            readings = []
            for k in range(n_rows):
                f = F_with[k] if np.isfinite(F_with[k]) else None
                if f is None:
                    break
                r = f / GF + tare + rng.normal(0, cfg['noise_gf'])
                readings.append(r)
                if r >= 1000.0:
                    break
            # iteration may start at 3: then at most 87 rows
            rows = clock.rows(readings, h_tape)
            if len(rows) and int(float(rows[-1].split(',')[0])) > 89:
                rows = rows[:len(rows) - (int(float(rows[-1].split(',')[0])) - 89)]
            with open(os.path.join(data, trial_files[ti]), 'w', newline='') as fh:
                fh.write(HEADER + '\r\n')
                for r in rows:
                    fh.write(r + '\r\n')

            # ---------- stiffness measures (noise free)
            valid = np.isfinite(F_with) & (u_s > 0)
            k_with = slope_fit(u_s[valid], F_with[valid])
            # without the hidden effect(s), and with each continuous effect alone
            def k_only(on=(), rms=False):
                E_k = cane.E if 'scale' in on else cane.E / cfg['scale']
                sol_k, _ = build_solver(
                    cane, lambda s, cn=cane, E_k=E_k: cn.EI(s, flare='flare' in on, E=E_k), s_p,
                    d if 'angle' in on else d0,
                    k_root=k_root if 'root' in on else None,
                    k_rig=k_rig if 'rig' in on else None,
                    soft=soft if 'soft' in on else None, h=0.012)
                uu, FF = coarse_curve(sol_k, du=0.5e-3 if rms else 1.5e-3)
                return (slope_fit(uu, FF), shape_rms_gf(uu, FF)) if rms else slope_fit(uu, FF)
            k_wo, rms_wo = k_only((), rms=True)
            rms_with = shape_rms_gf(u_s[valid], F_with[valid])
            cont = [e for e, on in (('scale', cfg['scale'] != 1.0), ('root', k_root is not None),
                                    ('rig', k_rig is not None), ('flare', cane.flare is not None),
                                    ('angle', angle_glob != 0.0), ('soft', soft is not None)) if on]
            k_alone = {e: k_only((e,)) for e in cont} if len(cont) > 1 else {}
            k_alone_free = float(slope_fit(u_s[np.isfinite(F_free) & (u_s > 0)],
                                           F_free[np.isfinite(F_free) & (u_s > 0)]))
            # view model (what the files say)
            s_view = view.s_at_height(h_tape / 1e3) if not cfg['push_by_s'] else round(s_p, 3)
            dv, _, _ = probe_dir_2d(view.xz, s_view, view.L, push_sign, 0.0)
            sol_v, _ = build_solver(view, view.EI, s_view, dv, h=0.012)
            uu, FF = coarse_curve(sol_v)
            k_view = slope_fit(uu, FF)

            truth_trials[tid] = dict(
                file=trial_files[ti], height_true_m=h_true, height_tape_mm=h_tape, s_push=s_p,
                angle_deg=ang, dead_zone_mm=g0 * 1e3, tare_gf=tare, rows=len(rows),
                stopped_at_1000=bool(readings and readings[-1] >= 1000.0),
                obstruction=ob, obstruction_onset_mm=onset_mm, rub=rub_info,
                k_with=k_with, k_without=k_wo, k_view=k_view, k_each_alone=k_alone,
                k_with_but_obstruction_or_rub=k_alone_free,
                shape_rms_gf_with=rms_with, shape_rms_gf_without=rms_wo)
            ob_truth[tid] = onset_mm
            yp = {'id': str(t)}
            if cfg['push_by_s']:
                yp['s'] = round(float(s_p + rng.normal(0, 0.003)), 3)
            else:
                yp['height'] = round(h_tape / 1e3, 3)
            hx = np.cos(cane.psi) * push_sign
            hy = np.sin(cane.psi) * push_sign
            yp['direction'] = [round(float(hx), 4), round(float(hy), 4), 0]
            yp['trial'] = '../' + trial_files[ti]
            yaml_pushes.append((t, yp))
            diam_push = round(float(cane.d(s_p)) * 1e3 + rng.normal(0, 0.15), 1)
            push_rows.append((cane.bush, cane.cane, t, h_tape, diam_push, trial_files[ti]))
        yaml_pushes.sort(key=lambda p: p[0])
        doc = {
            'id': cane.id,
            'polyline': {'raw': True,
                         'points': [[round(float(v), 4) for v in p] for p in clicks]},
            'calipers': calipers,
            'push_points': [p for _, p in yaml_pushes],
        }
        if cfg['stated_E']:
            doc['material'] = {'flexural_modulus': float(cfg['stated_E']), 'density': 580.0,
                               'joint_damping': 0.15}
        doc['provenance'] = {'synthetic': True,
                             'assumptions': ['synthetic test bed indep13; polyline clicked on a photo',
                                             'calipers read with a vernier, 0.1 mm']}
        with open(os.path.join(data, 'canes', cane.id + '.yaml'), 'w') as fh:
            yaml.safe_dump(doc, fh, sort_keys=False, default_flow_style=None)
        if rng.random() < 0.08:
            clock.reset()

    push_rows.sort()
    with open(os.path.join(data, 'push_points.csv'), 'w') as fh:
        fh.write('bush,cane,trial,height_mm,diameter_mm,file\n')
        for r in push_rows:
            fh.write('%d,%d,%d,%d,%s,%s\n' % (r[0], r[1], r[2], r[3], repr(r[4]), r[5]))

    # ---------- summary statistics
    ids = sorted(truth_trials)
    lw = np.array([np.log(truth_trials[i]['k_with'] / truth_trials[i]['k_without']) for i in ids])
    lv = np.array([np.log(truth_trials[i]['k_without'] / truth_trials[i]['k_view']) for i in ids])
    cane_of = [i[:i.index('t')] for i in ids]
    cmeans = {}
    for c, v in zip(cane_of, lv):
        cmeans.setdefault(c, []).append(v)
    cm = np.array([np.mean(v) for v in cmeans.values()])
    within = np.array([v - np.mean(cmeans[c]) for c, v in zip(cane_of, lv)])
    affected = np.ones(len(ids), bool)
    if cfg['obstruct_frac'] and not any(e['effect'] != 'obstruction' for e in cfg['expected']):
        affected = np.array([truth_trials[i]['obstruction'] is not None for i in ids])
    if cfg['rub']:
        affected = np.array([truth_canes[i[:i.index('t')]]['rub'] is not None for i in ids])
    eff_present = bool(cfg['expected']) or cfg['ool'] is not None
    size = float(np.median(np.abs(lw[affected]))) if eff_present else 0.0
    expected = []
    for e in cfg['expected']:
        e = json.loads(json.dumps(e))
        if e['params'].get('k_root') == 'per_cane':
            e['params']['k_root'] = {c: truth_canes[c]['k_root'] for c in truth_canes}
            e['params_median'] = {'k_root': float(np.median(list(e['params']['k_root'].values())))}
        expected.append(e)
    # per-effect sizes (median |ln k ratio|, noise free)
    sizes = {}
    T = [truth_trials[i] for i in ids]
    each = set(e for tr in T for e in tr['k_each_alone'])
    for e in sorted(each):
        v = [abs(np.log(tr['k_each_alone'][e] / tr['k_without'])) for tr in T if e in tr['k_each_alone']]
        sizes[e] = float(np.median(v))
    obs = [tr for tr in T if tr['obstruction'] is not None]
    if obs:
        sizes['obstruction'] = float(np.median([abs(np.log(tr['k_with'] / tr['k_with_but_obstruction_or_rub']))
                                                for tr in obs]))
    rubs = [tr for tr in T if tr['rub'] is not None]
    if rubs:
        sizes['rub'] = float(np.median([abs(np.log(tr['k_with'] / tr['k_with_but_obstruction_or_rub']))
                                        for tr in rubs]))
    shape = dict(median_rms_with_gf=float(np.median([tr['shape_rms_gf_with'] for tr in T])),
                 median_rms_without_gf=float(np.median([tr['shape_rms_gf_without'] for tr in T])),
                 noise_gf=cfg['noise_gf'])
    apparent = float(np.median(np.log([truth_trials[i]['k_with'] / truth_trials[i]['k_view']
                                       for i, a in zip(ids, affected) if a]))) if eff_present else 0.0
    truth = dict(
        set=name, seed=seed, description=cfg['description'], habit=cfg['habit'],
        stated_modulus_Pa=stated, stated_in_yaml=bool(cfg['stated_E']),
        true_median_modulus_Pa=E_med_true, sigma_lnE=cfg['sigma_lnE'],
        expected=dict(named=expected, unexplained=bool(cfg['unexplained'])),
        out_of_library=cfg['ool'],
        n_trials=len(ids), n_canes=len(truth_canes),
        size_median_abs_ln_k=size, size_by_effect=sizes, trace_shape=shape, apparent_median_ln_k_with_over_view=apparent,
        n_affected=int(affected.sum()) if eff_present else 0,
        between_cane_noise_sd_ln_k=float(np.std(cm, ddof=1)),
        within_cane_sd_ln_k=float(np.std(within, ddof=1) if len(within) > 1 else 0.0),
        bias_mean_ln_k_without_over_view=float(np.mean(lv)),
        bias_se=float(np.std(cm, ddof=1) / np.sqrt(len(cm))),
        obstruction_onsets_mm=ob_truth,
        canes=truth_canes, trials=truth_trials, config={k: v for k, v in cfg.items()
                                                       if k not in ('soft',)} | {'soft': cfg['soft']},
    )
    os.makedirs(os.path.join(out_root, 'truth'), exist_ok=True)
    with open(os.path.join(out_root, 'truth', name + '.json'), 'w') as fh:
        json.dump(truth, fh, indent=1, default=float)
    n_ob = sum(1 for v in ob_truth.values() if v is not None)
    print('%s  trials %2d  size %.3f (n=%d) %s apparent %+.3f  noise(between-cane) %.3f  within %.3f  bias %+.3f +- %.3f  '
          'obstructed %d  [%.1fs]  %s' % (
              name, len(ids), size, truth['n_affected'], {k: round(v, 3) for k, v in sizes.items()}, apparent,
              truth['between_cane_noise_sd_ln_k'],
              truth['within_cane_sd_ln_k'], truth['bias_mean_ln_k_without_over_view'], truth['bias_se'],
              n_ob, time.time() - t0, cfg['description'][:60]), flush=True)
    return truth


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument('--seed', type=int, default=1313)
    ap.add_argument('--only', default='')
    ap.add_argument('--out', default=HERE)
    a = ap.parse_args(argv)
    names = sorted(SETS) if not a.only else a.only.split(',')
    for nm in names:
        make_set(nm, SETS[nm], a.seed, a.out)


if __name__ == '__main__':
    main()
