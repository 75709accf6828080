"""Write data/dsNN (field layout: push_points.csv, rig CSVs, canes/b{B}c{C}.yaml) and truth/dsNN.json.

usage: python make.py [01 02 ...]      (default: all 12 sets)
Truth model: rod.py (planar geometrically exact Kirchhoff rod with self-weight, shooting + RK4).
"""
import json
import os
import sys
import time

import numpy as np

from rod import RodBatch, natural_from_photo

HERE = os.path.dirname(os.path.abspath(__file__))
GF = 9.80665e-3          # N per gram-force
RHO = 580.0
G = 9.81
INCH = 0.0254

# ----------------------------------------------------------------------------------------------
# set definitions
SETS = {
    '01': dict(kind='null', bushes=list(range(101, 110)), canes=2, pushes=3, style='row',
               E_stated=4.57e9, write_material=False, dmed=22.5, noise=(1.0, 2.2), loc='height'),
    '02': dict(kind='scale', scale=0.60, bushes=[3, 4, 5, 6, 7, 8, 9], canes=2, pushes=3, style='dots',
               E_stated=5.2e9, write_material=True, dmed=21.8, noise=(1.2, 2.6), loc='height'),
    '03': dict(kind='root_plant', bushes=[11, 12, 13, 14, 15, 16], canes=3, pushes=3, style='field',
               E_stated=4.57e9, write_material=True, dmed=23.9, noise=(1.0, 2.0), loc='mixed',
               k_root_bush=[55.0, 320.0, 110.0, 210.0, 75.0, 150.0]),
    '04': dict(kind='rig', k_rig=380.0, bushes=[1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12], canes=1, pushes=3,
               style='time', E_stated=4.57e9, write_material=True, dmed=26.8, noise=(1.4, 3.0), loc='height'),
    '05': dict(kind='pitch', angle=38.0, bushes=[21, 22, 23, 24, 25, 26, 27], canes=2, pushes=3, style='row',
               E_stated=4.4e9, write_material=True, dmed=21.8, noise=(1.0, 2.0), loc='height'),
    '06': dict(kind='flare', h_top=(0.68, 0.88), bushes=[2, 5, 6, 9, 10, 13], canes=3, pushes=3, style='dots',
               E_stated=4.57e9, write_material=False, dmed=20.3, noise=(1.0, 2.4), loc='mixed'),
    '07': dict(kind='null', bushes=[31, 32, 33, 34], canes=3, pushes=4, spacing_in=3.0, style='field',
               E_stated=3.9e9, write_material=True, dmed=23.2, noise=(1.5, 3.0), loc='s'),
    '08': dict(kind='obstruction', p_obs=0.36, bushes=list(range(1, 10)), canes=2, pushes=3, style='time',
               E_stated=4.57e9, write_material=True, dmed=21.8, noise=(1.0, 2.2), loc='height'),
    '09': dict(kind='rig+obstruction', k_rig=520.0, p_obs=0.35, bushes=[41, 42, 43, 44, 45, 46, 47],
               canes=2, pushes=3, style='row', E_stated=4.57e9, write_material=True, dmed=24.6,
               noise=(1.0, 2.4), loc='mixed'),
    '10': dict(kind='ool_thick', beta=1.6, bushes=[1, 2, 3, 4, 5, 6], canes=3, pushes=3, style='dots',
               E_stated=4.57e9, write_material=True, dmed=21.8, dsd=0.33, noise=(1.0, 2.2), loc='height'),
    '11': dict(kind='ool_play', bushes=[7, 8, 9, 10, 11, 12, 13], canes=2, pushes=3, style='field',
               E_stated=4.57e9, write_material=False, dmed=22.5, noise=(1.0, 2.0), loc='height',
               lean_toward=1.0),
    '12': dict(kind='scale+flare', scale=0.66, bushes=[51, 52, 53, 54, 55], canes=3, pushes=3, style='time',
               E_stated=4.8e9, write_material=True, dmed=21.0, noise=(1.0, 2.4), loc='mixed'),
}
SEEDS = {k: 14000 + 37 * int(k) for k in SETS}


# ----------------------------------------------------------------------------------------------
def photo_curve(rng, L, lean_sign):
    """angle from vertical (toward -x, the aisle, when lean_sign > 0): theta0 + dtheta (s/L)^p + wiggle."""
    th0 = np.radians(rng.uniform(4, 20)) * lean_sign
    dth = np.radians(rng.uniform(4, 26)) * lean_sign
    p = rng.uniform(1.4, 3.0)
    aw = np.radians(rng.uniform(0.5, 2.0)); lw = rng.uniform(0.35, 0.8); pw = rng.uniform(0, 2 * np.pi)
    phig = lambda s: np.pi / 2 + th0 + dth * (np.asarray(s) / L) ** p + aw * (np.sin(2 * np.pi * np.asarray(s) / lw + pw) - np.sin(pw))
    phigp = lambda s: dth * p * np.maximum(np.asarray(s), 0) ** (p - 1) / L ** p + aw * 2 * np.pi / lw * np.cos(2 * np.pi * np.asarray(s) / lw + pw)
    return phig, phigp, dict(theta0_deg=float(np.degrees(th0)), dtheta_deg=float(np.degrees(dth)), p=p)


def make_cane(rng, cfg, bush, cane):
    while True:
        L = rng.uniform(1.35, 1.95)
        lean_sign = 1.0 if rng.uniform() < cfg.get('lean_toward', 0.8) else -1.0
        phig, phigp, shape = photo_curve(rng, L, lean_sign)
        sf = np.linspace(0, L, 4001)
        ph = phig(sf)
        xf = np.concatenate([[0], np.cumsum(0.5 * (np.cos(ph[1:]) + np.cos(ph[:-1])) * np.diff(sf))])
        zf = np.concatenate([[0], np.cumsum(0.5 * (np.sin(ph[1:]) + np.sin(ph[:-1])) * np.diff(sf))])
        npush = cfg['pushes']
        sp_in = cfg.get('spacing_in', 4.0)
        h_top = rng.uniform(*cfg.get('h_top', (0.76, 0.98))) if npush == 3 else rng.uniform(0.80, 0.98)
        heights = [h_top - j * sp_in * INCH + rng.normal(0, 0.003) for j in range(npush)]
        if zf[-1] < h_top + 0.30:
            continue
        s_push = [float(np.interp(h, zf, sf)) for h in heights]
        break
    # diameter (m): near-linear taper with a random-sign bow, bud swellings
    d_b = float(np.clip(cfg['dmed'] * 1e-3 * np.exp(rng.normal(0, cfg.get('dsd', 0.24))), 11e-3, 34e-3))
    d_t = rng.uniform(2.5e-3, 4.0e-3)
    bow = rng.uniform(-0.3, 0.3)
    nb = rng.integers(3, 6)
    bumps = [(rng.uniform(0.1, L - 0.1), rng.uniform(-0.03, 0.06), rng.uniform(0.012, 0.025)) for _ in range(nb)]
    flare = None
    if 'flare' in cfg['kind']:
        flare = (rng.uniform(16e-3, 28e-3), rng.uniform(0.20, 0.27))

    def diam(s, with_flare=True):
        s = np.asarray(s, float)
        u = s / L
        d = d_t + (d_b - d_t) * (1 - u) + bow * (d_b - d_t) * u * (1 - u)
        f = np.ones_like(s)
        for c, a, w in bumps:
            f = f + a * np.exp(-0.5 * ((s - c) / w) ** 2)
        d = d * f
        if flare is not None and with_flare:
            D, ell = flare
            d = d + D * np.clip(1 - s / ell, 0, None) ** 2
        return d
    return dict(bush=bush, cane=cane, L=L, phig=phig, phigp=phigp, shape=shape, sf=sf, xf=xf, zf=zf,
                heights=heights, s_push=s_push, diam=diam, d_b=d_b, d_t=d_t, bow=bow, flare=flare,
                lean_sign=lean_sign)


def probe_axis(cn, s_p, pitch_deg):
    """perpendicular to the +-150 mm chord of the photo curve, pushing toward +x (the bush), pitched
    toward +z by pitch_deg (d = cos a n + sin a t_up)."""
    sa, sb = max(s_p - 0.15, 0.0), min(s_p + 0.15, cn['L'])
    pa = np.array([np.interp(sa, cn['sf'], cn['xf']), np.interp(sa, cn['sf'], cn['zf'])])
    pb = np.array([np.interp(sb, cn['sf'], cn['xf']), np.interp(sb, cn['sf'], cn['zf'])])
    t = (pb - pa) / np.linalg.norm(pb - pa)
    n = np.array([t[1], -t[0]])
    if n[0] < 0:
        n = -n
    a = np.radians(pitch_deg)
    d = np.cos(a) * n + np.sin(a) * t
    return d / np.linalg.norm(d), n, t


# ----------------------------------------------------------------------------------------------
def run_push(lanes, u_grid):
    b = RodBatch(lanes)
    F, Gf, eo, err = b.push(u_grid)
    return F, Gf, eo, err


def lane_for(cn, tr, E, *, c_root=0.0, play=(0.0, 1.0), flare=True, d_axis=None, obstruction=None, diam=None):
    L = cn['L']
    dfun = diam if diam is not None else (lambda s: cn['diam'](s, flare))
    EI = lambda s: E * np.pi * dfun(s) ** 4 / 64
    q = lambda s: RHO * G * np.pi * dfun(s) ** 2 / 4
    p0p, p00, _ = natural_from_photo(cn['phig'], cn['phigp'], L, EI, q, c_root, play)
    return dict(L=L, s_p=tr['s_true'], EI=EI, phi0p=p0p, phi00=p00, q=q, d=tr['d'] if d_axis is None else d_axis,
                c_root=c_root, play=play, obstruction=obstruction)


def rig_slope(u_rig_mm, F_N, tare, dz, row0):
    """rig-style slope (N/mm) of a noise-free trace sampled like the CSV: net > 20 gf, until the stop."""
    Fg = F_N / GF
    t = np.arange(0, 88) * 0.5                       # probe travel from the first sample
    uc = t - dz
    f = np.where(uc > 0, np.interp(uc, u_rig_mm, Fg), 0.0)
    raw = tare + f
    stop = np.argmax(raw >= 1000) if np.any(raw >= 1000) else len(raw) - 1
    nrow = min(stop + 1, 88 - (row0 - 2))
    m = (f[:nrow] > 20) & (uc[:nrow] <= 45)
    if m.sum() < 3:
        return np.nan
    return np.polyfit(t[:nrow][m], f[:nrow][m] * GF, 1)[0]


def trace_shape(u_rig_mm, F_N, tare, dz, row0):
    """RMS (gf) of a noise-free trace about its rig-style line (net > 20 gf), and late/early slope ratio."""
    Fg = F_N / GF
    t = np.arange(0, 88) * 0.5
    uc = t - dz
    f = np.where(uc > 0, np.interp(uc, u_rig_mm, Fg), 0.0)
    raw = tare + f
    stop = np.argmax(raw >= 1000) if np.any(raw >= 1000) else len(raw) - 1
    nrow = min(stop + 1, 88 - (row0 - 2))
    m = (f[:nrow] > 20)
    if m.sum() < 6:
        return None
    tt, ff = t[:nrow][m], f[:nrow][m]
    A = np.polyfit(tt, ff, 1)
    k3 = len(tt) // 3
    r = np.polyfit(tt[-k3:], ff[-k3:], 1)[0] / np.polyfit(tt[:k3], ff[:k3], 1)[0] if k3 >= 2 else None
    return dict(rms=float(np.sqrt(np.mean((ff - np.polyval(A, tt)) ** 2))), late_over_early=r)


def fmt(v):
    r = round(float(v), 2)
    if r == 0:
        r = 0.0
    return repr(r)


def file_name(style, bush, cane, trial, h_in, clock):
    if style == 'field':
        return f"trials/bush_{bush}_branch_{cane}_trial_{trial}.csv"
    if style == 'row':
        return f"trials/row2-plant{bush:03d}-cane{cane}-{h_in:g}in.csv"
    if style == 'dots':
        return f"rig/{bush}.{cane}.{trial}.csv"
    if style == 'time':
        hh, mm, ss = clock
        return f"logs/2024-03-{12 + bush % 3:02d}/push_{hh:02d}{mm:02d}{ss:02d}.csv"
    raise ValueError(style)


# ----------------------------------------------------------------------------------------------
def build(key):
    cfg = SETS[key]
    rng = np.random.default_rng(SEEDS[key])
    t0 = time.time()
    kind = cfg['kind']
    canes, trials = [], []
    for bi, bush in enumerate(cfg['bushes']):
        for c in range(1, cfg['canes'] + 1):
            cn = make_cane(rng, cfg, bush, c)
            cn['lnE_z'] = rng.normal(0, 0.15)
            cn['E_true'] = cfg['E_stated'] * np.exp(cn['lnE_z']) * cfg.get('scale', 1.0)
            canes.append(cn)
    if kind == 'ool_thick':
        d30 = np.array([float(cn['diam'](np.interp(0.30, cn['zf'], cn['sf']))) for cn in canes])
        ref = np.exp(np.mean(np.log(d30)))
        for cn, d in zip(canes, d30):
            cn['E_base'] = cn['E_true']
            cn['E_true'] = cn['E_true'] * (d / ref) ** cfg['beta']
            cn['d30_mm'] = d * 1e3
    if kind == 'ool_play':
        for cn in canes:
            cn['play'] = (rng.uniform(0.004, 0.008), rng.uniform(0.03, 0.06))
            cn['k_stiff'] = rng.uniform(350, 700)
    for ci, cn in enumerate(canes):
        bi = cfg['bushes'].index(cn['bush'])
        if kind == 'root_plant':
            cn['k_root'] = cfg['k_root_bush'][bi] * np.exp(rng.normal(0, 0.08))
        for j, (h, s) in enumerate(zip(cn['heights'], cn['s_push'])):
            pitch_true = cfg.get('angle', 0.0) + rng.normal(0, 1.5)
            d, nperp, tch = probe_axis(cn, s, pitch_true)
            trials.append(dict(ci=ci, bush=cn['bush'], cane=cn['cane'], trial=j + 1, h_true=h, s_true=s,
                               pitch_true=pitch_true, d=d, n=nperp))

    # obstruction draws
    obs_kind = 'obstruction' in kind
    for tr in trials:
        tr['obs'] = None
        if obs_kind and rng.uniform() < cfg['p_obs']:
            cn = canes[tr['ci']]
            so = tr['s_true'] + rng.uniform(0.12, 0.32)
            if so < cn['L'] - 0.05:
                tr['obs'] = dict(s_o=so, e=np.array([1.0, 0.0]), k_ratio=rng.uniform(1.2, 3.0), w=2e-4,
                                 onset_frac=rng.uniform(0.25, 0.6))

    u_grid = np.arange(0.5, 46.01, 0.5) * 1e-3

    def lanes_variant(variant):
        out = []
        for tr in trials:
            cn = canes[tr['ci']]
            E = cn['E_true']
            c_root, play, flare = 0.0, (0.0, 1.0), True
            obstruction = None
            if variant == 'with':
                if kind == 'root_plant':
                    c_root = 1 / cn['k_root']
                if kind == 'ool_play':
                    c_root, play = 1 / cn['k_stiff'], cn['play']
                if tr['obs'] is not None:
                    obstruction = dict(tr['obs'], k_o=tr['obs']['k_o'], gap=tr['obs']['gap'])
                d_axis = tr['d']
            elif variant == 'partial':     # scale+flare: flare only
                E = E / cfg['scale']
                d_axis = tr['d']
            elif variant == 'without':
                flare = False
                if kind == 'ool_thick':
                    E = cn['E_base']
                if kind in ('scale', 'scale+flare'):
                    E = E / cfg['scale']
                d_axis = tr['d'] if kind not in ('pitch',) else probe_axis(cn, tr['s_true'], tr['pitch_true'] - cfg['angle'])[0]
                if tr['obs'] is not None:   # probe the obstruction point with a zero-stiffness body
                    obstruction = dict(tr['obs'], k_o=0.0, gap=0.0)
            if variant == 'files':
                out.append(files_lane(cn, tr))
                continue
            out.append(lane_for(cn, tr, E, c_root=c_root, play=play, flare=flare, d_axis=d_axis,
                                obstruction=obstruction))
        return out

    def files_lane(cn, tr):
        # what the files describe: stated E, linear caliper taper, perpendicular probe at the taped height,
        # clamped base (geometry: the true photo, i.e. without polyline click noise)
        sc = np.array([c['s'] for c in cn['cal']]); dc = np.array([c['d'] for c in cn['cal']])
        A = np.polyfit(sc, dc, 1)
        dl = lambda s: np.maximum(np.polyval(A, np.asarray(s, float)), 1e-3)
        s_rec = float(np.interp(tr['h_rec'], cn['zf'], cn['sf']))
        d_ax = probe_axis(cn, s_rec, 0.0)[0]
        tr2 = dict(tr, s_true=s_rec)
        return lane_for(cn, tr2, cfg['E_stated'], d_axis=d_ax, diam=dl)

    # --- records written to the files (tape heights, calipers) before the 'files' variant needs them
    for cn in canes:
        write_calipers(rng, cfg, cn)
    for tr in trials:
        cn = canes[tr['ci']]
        h_in = np.round((tr['h_true'] + rng.normal(0, 0.002)) / INCH * 4) / 4
        tr['h_in'] = float(h_in)
        tr['h_rec'] = float(h_in * INCH)

    Fw0, _, eo0, e0 = run_push(lanes_variant('without'), u_grid)
    # obstruction gap and stiffness from the unobstructed push
    for i, tr in enumerate(trials):
        if tr['obs'] is not None:
            kt = Fw0[i, 1] / u_grid[1]        # N/m at the probe, initial
            tr['obs']['k_o'] = tr['obs']['k_ratio'] * kt
            tr['_k0'] = kt
    # dead zone, tare etc. are drawn now so the onset can be placed inside the recorded trace
    for tr in trials:
        tr['dz'] = rng.uniform(0.6, 8.0) if rng.uniform() > 0.15 else rng.uniform(0.05, 0.6)
    bush_tare = {b: rng.uniform(-95, 45) for b in cfg['bushes']}
    for tr in trials:
        tr['tare'] = bush_tare[tr['bush']] + rng.normal(0, 3.0)
        tr['row0'] = 3 if rng.uniform() < 0.12 else 2
    k_rig = cfg.get('k_rig')
    for i, tr in enumerate(trials):
        if tr['obs'] is not None:
            # contact range recorded (without obstruction) in rig travel
            Fg = Fw0[i] / GF
            urig = u_grid * 1e3 + (Fw0[i] / k_rig * 1e3 if k_rig else 0)
            avail = 43.5 - (tr['row0'] - 2) * 0.5 - tr['dz']
            reach = urig[np.argmax(tr['tare'] + Fg >= 1000)] if np.any(tr['tare'] + Fg >= 1000) else urig[-1]
            span = min(avail, reach)
            target = max(5.0, tr['obs']['onset_frac'] * span)
            if span - target < 7:
                tr['obs'] = None
                continue
            # cane displacement at the probe for that rig travel, then the approach at s_o
            u_on = np.interp(target, urig, u_grid)
            tr['obs']['gap'] = float(np.interp(u_on, u_grid, eo0[i]))
            tr['obs']['onset_target_mm'] = target

    Fw, Gw, eow, ew = run_push(lanes_variant('with'), u_grid)
    Ff, _, _, ef = run_push(lanes_variant('files'), u_grid)
    cfg['_Fpartial'] = run_push(lanes_variant('partial'), u_grid)[0] if kind == 'scale+flare' else None
    print(f"ds{key}: solved {len(trials)} trials x 3 variants in {time.time()-t0:.0f}s; "
          f"max residual {max(e0.max(), ew.max(), ef.max()):.1e}", flush=True)

    # ---- write files
    write_set(key, cfg, rng, canes, trials, u_grid, Fw, Gw, eow, Fw0, Ff)


def write_calipers(rng, cfg, cn):
    """three calipers: low (0.28-0.42 m), at the middle push +-20 mm, 120-240 mm above the top push."""
    hs = [rng.uniform(0.28, 0.42), cn['heights'][len(cn['heights']) // 2] + rng.uniform(-0.02, 0.02),
          cn['heights'][0] + rng.uniform(0.12, 0.24)]
    cal = []
    for h in hs:
        s = float(np.interp(h, cn['zf'], cn['sf']))
        s = min(s, cn['L'] - 0.1)
        h = float(np.interp(s, cn['sf'], cn['zf']))
        dtrue = float(cn['diam'](s))
        dread = round((dtrue + rng.normal(0, 0.12e-3)) * 1e3, 2) * 1e-3
        loc = cfg['loc']
        by = 's' if loc == 's' or (loc == 'mixed' and rng.uniform() < 0.5) else 'height'
        if by == 's':
            val = round((s + rng.normal(0, 0.003)) / 0.005) * 0.005       # tape along the cane, 5 mm
        else:
            val = round(h + rng.normal(0, 0.002), 3)
        cal.append(dict(by=by, val=val, s=s, h=h, d=dread, d_true=dtrue))
    cn['cal'] = cal


def yaml_num(v, nd=5):
    s = f"{v:.{nd}f}".rstrip('0')
    return s + '0' if s.endswith('.') else s


def write_set(key, cfg, rng, canes, trials, u_grid, Fw, Gw, eow, Fw0, Ff):
    root = os.path.join(HERE, 'data', f'ds{key}')
    if os.path.exists(root):
        import shutil
        shutil.rmtree(root)
    os.makedirs(os.path.join(root, 'canes'))
    k_rig = cfg.get('k_rig')
    noise_lo, noise_hi = cfg['noise']
    # recording order: bush by bush, canes in order, pushes top-down or bottom-up per bush
    order = []
    for bush in cfg['bushes']:
        idx = [i for i, t in enumerate(trials) if t['bush'] == bush]
        updown = rng.uniform() < 0.5
        idx.sort(key=lambda i: (trials[i]['cane'], trials[i]['trial'] if updown else -trials[i]['trial']))
        order.append(idx)
    clock_s = 8 * 3600 + rng.uniform(0, 3600)
    ts = int(rng.integers(-32768, 32767))
    rows_pp = []
    truth_trials = []
    for bidx, idx in enumerate(order):
        pos = round(rng.uniform(0, 30) * 2) / 2
        clock_s += rng.uniform(300, 900)
        for i in idx:
            tr = trials[i]
            cn = canes[tr['ci']]
            u_rig_mm = u_grid * 1e3 + (Fw[i] / k_rig * 1e3 if k_rig else 0)
            u_rig0_mm = u_grid * 1e3 + (Fw0[i] / k_rig * 1e3 if k_rig else 0)
            nrow_max = 88 - (tr['row0'] - 2)
            it = np.arange(nrow_max) + tr['row0']
            travel = np.arange(nrow_max) * 0.5
            uc = travel - tr['dz']
            Fi = np.where(uc > 0, np.interp(uc, np.concatenate([[0], u_rig_mm]), np.concatenate([[0], Fw[i]])), 0.0)
            Fi = np.where(uc > 0, Fi, 0.0)
            sig = rng.uniform(noise_lo, noise_hi)
            noise = sig * rng.standard_t(5, nrow_max) / np.sqrt(5 / 3)
            lf = np.cumsum(rng.normal(0, 0.25, nrow_max)); lf -= lf.mean()
            reading = tr['tare'] + Fi / GF + noise + lf + 0.006 * Fi / GF * rng.normal(0, 1, nrow_max)
            stop = int(np.argmax(reading >= 1000)) if np.any(reading >= 1000) else nrow_max - 1
            n = stop + 1
            hmm = int(round(tr['h_in'] * 25.4))
            clock_s += rng.uniform(25, 80)
            hh, mm_, ss = int(clock_s // 3600) % 24, int(clock_s // 60) % 60, int(clock_s) % 60
            fname = file_name(cfg['style'], tr['bush'], tr['cane'], tr['trial'], tr['h_in'], (hh, mm_, ss))
            while any(r[-1] == fname for r in rows_pp):
                clock_s += 1
                hh, mm_, ss = int(clock_s // 3600) % 24, int(clock_s // 60) % 60, int(clock_s) % 60
                fname = file_name(cfg['style'], tr['bush'], tr['cane'], tr['trial'], tr['h_in'], (hh, mm_, ss))
            clock_s += n * 0.5
            path = os.path.join(root, fname)
            os.makedirs(os.path.dirname(path), exist_ok=True)
            lines = ["Iteration,Time Stamp,Load Cell Reading (gf),Displacement (mm),Height (mm)"]
            for r in range(n):
                lines.append(f"{float(it[r])!r},{float(ts)!r},{fmt(reading[r])},{float(pos)!r},{hmm}")
                ts += 500
                if ts > 32767:
                    ts -= 65536
                pos += 0.5
            with open(path, 'w', newline='') as fh:
                fh.write('\r\n'.join(lines) + '\r\n')
            ts += int(rng.integers(20000, 70000))
            while ts > 32767:
                ts -= 65536
            tr['file'] = fname
            diam_push = cn['diam'](tr['s_true'])
            d_mm = round((diam_push + rng.normal(0, 0.12e-3)) * 1e3, 2)
            rows_pp.append((tr['bush'], tr['cane'], tr['trial'], f"{tr['h_in'] * 25.4:.1f}", f"{d_mm:g}", fname))
            # truth record
            k_with = rig_slope(np.concatenate([[0], u_rig_mm]), np.concatenate([[0], Fw[i]]), tr['tare'], tr['dz'], tr['row0'])
            k_without = rig_slope(np.concatenate([[0], u_rig0_mm if not k_rig else u_grid * 1e3]),
                                  np.concatenate([[0], Fw0[i]]), tr['tare'], tr['dz'], tr['row0'])
            k_files = rig_slope(np.concatenate([[0], u_grid * 1e3]), np.concatenate([[0], Ff[i]]), tr['tare'], tr['dz'], tr['row0'])
            shape_resid = trace_shape(np.concatenate([[0], u_rig_mm]), np.concatenate([[0], Fw[i]]), tr['tare'], tr['dz'], tr['row0'])
            k_rig_only = rig_slope(np.concatenate([[0], u_rig0_mm]), np.concatenate([[0], Fw0[i]]), tr['tare'], tr['dz'], tr['row0']) if k_rig else None
            k_partial = rig_slope(np.concatenate([[0], u_grid * 1e3]), np.concatenate([[0], cfg['_Fpartial'][i]]), tr['tare'], tr['dz'], tr['row0']) if cfg.get('_Fpartial') is not None else None
            onset = None
            if tr['obs'] is not None:
                # rig travel at which the second body starts to engage (approach crosses zero)
                eo = eow[i]
                j = int(np.argmax(eo >= 0)) if np.any(eo >= 0) else None
                if j is not None and j > 0:
                    f = -eo[j - 1] / (eo[j] - eo[j - 1])
                    onset = float(u_rig_mm[j - 1] + f * (u_rig_mm[j] - u_rig_mm[j - 1]))
                contact_end = (n - 1) * 0.5 - tr['dz']
                tr['obs']['recorded'] = onset is not None and onset < contact_end
            truth_trials.append(dict(
                id=f"b{tr['bush']}c{tr['cane']}t{tr['trial']}", bush=tr['bush'], cane=tr['cane'], trial=tr['trial'],
                file=fname, height_true_m=tr['h_true'], height_recorded_m=tr['h_rec'], s_true_m=tr['s_true'],
                probe_pitch_true_deg=tr['pitch_true'], probe_axis_plane=list(map(float, tr['d'])),
                dead_zone_mm=tr['dz'], tare_gf=tr['tare'], first_iteration=int(tr['row0']), rows=n,
                noise_gf=sig, stopped_at_1000gf=bool(stop < nrow_max - 1),
                k_with_N_per_mm=k_with, shape_resid_gf=shape_resid, k_rig_only_N_per_mm=k_rig_only, k_flare_only_N_per_mm=k_partial, k_without_N_per_mm=k_without, k_files_N_per_mm=k_files,
                obstruction=None if tr['obs'] is None else dict(
                    s_o_m=tr['obs']['s_o'], above_push_m=tr['obs']['s_o'] - tr['s_true'], k_o_N_per_m=tr['obs']['k_o'],
                    k_ratio=tr['obs']['k_ratio'], gap_m=tr['obs']['gap']),
                obstruction_onset_mm=onset if (tr['obs'] is not None and tr['obs'].get('recorded')) else None,
            ))
            pos += rng.choice([0.0, 0.5])
    # push_points.csv (sorted like the field: bush, cane, trial)
    rows_pp.sort(key=lambda r: (r[0], r[1], r[2]))
    with open(os.path.join(root, 'push_points.csv'), 'w', newline='') as fh:
        fh.write('bush,cane,trial,height_mm,diameter_mm,file\r\n')
        for r in rows_pp:
            fh.write(','.join(str(x) for x in r) + '\r\n')
    # cane YAMLs
    for cn in canes:
        write_yaml(root, cfg, rng, cn, [t for t in trials if t['ci'] == canes.index(cn)])
    write_truth(key, cfg, canes, trials, truth_trials)


def write_yaml(root, cfg, rng, cn, trs):
    # bush layout: canes emerge from a crown; azimuth of the row normal per bush
    az = np.radians(cfg.setdefault('_az', {}).setdefault(cn['bush'], float(rng.uniform(-25, 25)) + 90.0))
    eh = np.array([np.cos(az), np.sin(az), 0.0])            # push azimuth (toward the bush centre)
    base = np.array([rng.uniform(-0.12, 0.12), rng.uniform(-0.12, 0.12), 0.0])
    cn['eh'] = eh; cn['base'] = base
    # clicks: 18-26 points, denser where the cane bends, 1.5 mm 3D noise (none in z at the base)
    ncl = int(rng.integers(18, 27))
    w = np.abs(cn['phigp'](cn['sf'])) + 0.6 / cn['L']
    cw = np.cumsum(w); cw /= cw[-1]
    targets = (np.arange(ncl - 2) + 0.5 + rng.uniform(-0.35, 0.35, ncl - 2)) / (ncl - 2)
    s_cl = np.concatenate([[0], np.interp(targets, cw, cn['sf']), [cn['L']]])
    s_cl = np.unique(np.round(s_cl, 4))
    pts = []
    for k, s in enumerate(s_cl):
        x = np.interp(s, cn['sf'], cn['xf']); z = np.interp(s, cn['sf'], cn['zf'])
        p = base + x * eh + np.array([0, 0, z])
        nz = rng.normal(0, 0.0015, 3)
        if k == 0:
            nz[2] = 0.0
        p = p + nz
        pts.append([round(v, 4) for v in p])
    # drop near-duplicate clicks
    clean = [pts[0]]
    for p in pts[1:]:
        if np.linalg.norm(np.subtract(p, clean[-1])) > 0.01:
            clean.append(p)
    if clean[-1] != pts[-1]:
        clean[-1] = pts[-1]
    lines = [f"id: b{cn['bush']}c{cn['cane']}", "polyline:", "  raw: true", "  points:"]
    for p in clean:
        lines.append(f"    - [{p[0]:.4f}, {p[1]:.4f}, {p[2]:.4f}]")
    lines.append("calipers:")
    for c in cn['cal']:
        if c['by'] == 's':
            lines.append(f"  - {{s: {c['val']:.3f}, diameter: {yaml_num(c['d'], 5)}}}")
        else:
            lines.append(f"  - {{height: {c['val']:.3f}, diameter: {yaml_num(c['d'], 5)}}}")
    lines.append("push_points:")
    dirv = eh.copy()
    for t in sorted(trs, key=lambda t: t['trial']):
        lines.append(f"  - id: \"{t['trial']}\"")
        if cfg['loc'] == 's':
            s_rec = round((t['s_true'] + rng.normal(0, 0.003)) / 0.005) * 0.005
            lines.append(f"    s: {s_rec:.3f}")
            t['s_rec_yaml'] = s_rec
        else:
            lines.append(f"    height: {t['h_rec']:.4f}")
        lines.append(f"    direction: [{dirv[0]:.3f}, {dirv[1]:.3f}, 0.0]")
        lines.append(f"    trial: ../{t['file']}")
    if cfg['write_material']:
        lines += ["material:", f"  flexural_modulus: {cfg['E_stated']:.1f}", "  density: 580.0"]
    lines += ["provenance:", "  synthetic: true",
              "  assumptions: [\"polyline clicked on the photo point cloud\", \"push heights taped in inches\"]"]
    with open(os.path.join(root, 'canes', f"b{cn['bush']}c{cn['cane']}.yaml"), 'w') as fh:
        fh.write('\n'.join(lines) + '\n')


def write_truth(key, cfg, canes, trials, tt):
    kind = cfg['kind']
    kw = np.array([t['k_with_N_per_mm'] for t in tt]); k0 = np.array([t['k_without_N_per_mm'] for t in tt])
    kf = np.array([t['k_files_N_per_mm'] for t in tt])
    ci = np.array([t['ci'] for t in trials])
    eff = np.log(kw / k0)
    # affected trials
    if 'obstruction' in kind and kind != 'rig+obstruction':
        aff = np.array([t['obstruction_onset_mm'] is not None for t in tt])
    else:
        aff = np.ones(len(tt), bool)
    size = float(np.nanmedian(np.abs(eff[aff]))) if aff.any() else 0.0
    lnf = np.log(k0 / kf)
    cane_mean = [np.nanmean(lnf[ci == c]) for c in range(len(canes))]
    noise = float(np.nanstd(cane_mean, ddof=1))
    apparent = float(np.nanmedian(np.log(kw / kf)[aff]))
    extra = {}
    if 'rig' in kind:
        kr = np.array([t['k_rig_only_N_per_mm'] for t in tt], float)
        extra['size_rig_only'] = float(np.nanmedian(np.abs(np.log(kr / k0))))
        if 'obstruction' in kind:
            ob = np.array([t['obstruction_onset_mm'] is not None for t in tt])
            extra['size_obstruction_only_obstructed_trials'] = float(np.nanmedian(np.abs(np.log(kw / kr))[ob]))
    if kind == 'scale+flare':
        kp = np.array([t['k_flare_only_N_per_mm'] for t in tt], float)
        extra['size_flare_only'] = float(np.nanmedian(np.abs(np.log(kp / k0))))
        extra['size_scale_only'] = float(abs(np.log(cfg['scale'])))
    sh = [t['shape_resid_gf'] for t in tt if t['shape_resid_gf']]
    extra['shape_rms_gf_median'] = float(np.median([x['rms'] for x in sh]))
    extra['late_over_early_median'] = float(np.median([x['late_over_early'] for x in sh if x['late_over_early']]))
    extra['noise_gf_median'] = float(np.median([t['noise_gf'] for t in tt]))
    hidden, named, unexpl = [], [], False
    if kind in ('scale', 'scale+flare'):
        hidden.append(dict(effect='modulus_scale', scope='global', params=dict(scale=cfg['scale']), in_library=True,
                           realised_geomean=float(np.exp(np.mean([np.log(c['E_true'] / cfg['E_stated']) for c in canes])))))
    if kind == 'root_plant':
        hidden.append(dict(effect='root_compliance', scope='per_plant', in_library=True,
                           params=dict(k_root_by_bush={str(b): v for b, v in zip(cfg['bushes'], cfg['k_root_bush'])},
                                       k_root_geomean=float(np.exp(np.mean(np.log([c['k_root'] for c in canes]))))),
                           per_cane={f"b{c['bush']}c{c['cane']}": c['k_root'] for c in canes}))
    if 'rig' in kind:
        hidden.append(dict(effect='rig_compliance', scope='global', params=dict(k_rig=cfg['k_rig']), in_library=True))
    if kind == 'pitch':
        hidden.append(dict(effect='probe_misalignment', scope='global', params=dict(angle_deg=cfg['angle']),
                           in_library=True, note='plus N(0, 1.5 deg) operator error per trial in every set'))
    if 'flare' in kind:
        hidden.append(dict(effect='base_flare', scope='per_cane', in_library=True,
                           params=dict(form='d + D (1 - s/ell)^2 for s < ell'),
                           per_cane={f"b{c['bush']}c{c['cane']}": dict(D_mm=c['flare'][0] * 1e3, ell_m=c['flare'][1]) for c in canes}))
    if 'obstruction' in kind:
        hidden.append(dict(effect='obstruction', scope='per_trial', in_library=True,
                           n_trials=int(sum(t['obstruction_onset_mm'] is not None for t in tt))))
    if kind == 'ool_thick':
        hidden.append(dict(effect='OOL_modulus_grows_with_cane_thickness', in_library=False,
                           params=dict(beta=cfg['beta'], law='E = E0 exp(0.15 z) (d30/geomean d30)^beta, d30 = diameter at 0.30 m height'),
                           per_cane={f"b{c['bush']}c{c['cane']}": dict(d30_mm=c['d30_mm'], E_true=c['E_true'], E_without=c['E_base']) for c in canes}))
        unexpl = True
    if kind == 'ool_play':
        hidden.append(dict(effect='OOL_root_socket_play', in_library=False,
                           params=dict(law='theta = M/k_stiff + theta_g tanh(M/M_g); weight preloads the socket, the push reverses the base moment'),
                           per_cane={f"b{c['bush']}c{c['cane']}": dict(theta_g_rad=c['play'][0], M_g_Nm=c['play'][1], k_stiff=c['k_stiff']) for c in canes}))
        unexpl = True
    for h in hidden:
        if h['in_library']:
            named.append(h['effect'])
    per_cane = []
    for c in canes:
        sc = np.array([x['s'] for x in c['cal']]); dc = np.array([x['d'] for x in c['cal']])
        A = np.polyfit(sc, dc, 1)
        per_cane.append(dict(id=f"b{c['bush']}c{c['cane']}", L_m=c['L'], E_true=c['E_true'], lean=c['shape'],
                             d_base_mm=float(c['diam'](0.0)) * 1e3, d_base_taper_mm=c['d_b'] * 1e3,
                             excess_vs_caliper_line_mm=float(c['diam'](0.0) - np.polyval(A, 0.0)) * 1e3,
                             calipers=[dict(by=x['by'], value=x['val'], d_read=x['d'], d_true=x['d_true']) for x in c['cal']],
                             k_root=c.get('k_root'), play=c.get('play')))
    truth = dict(set=f"ds{key}", kind=kind, stated_modulus=cfg['E_stated'],
                 expected=dict(named=named, unexplained=unexpl),
                 hidden_effects=hidden, size=size, noise=noise, size_over_noise=size / noise if noise else None,
                 apparent=apparent, **extra, n_trials=len(tt), n_canes=len(canes),
                 median_k_with=float(np.nanmedian(kw)), k_range=[float(np.nanmin(kw)), float(np.nanmax(kw))],
                 canes=per_cane, trials=tt)
    os.makedirs(os.path.join(HERE, 'truth'), exist_ok=True)
    with open(os.path.join(HERE, 'truth', f'ds{key}.json'), 'w') as fh:
        json.dump(truth, fh, indent=1, default=lambda o: o.tolist() if hasattr(o, 'tolist') else str(o))
    print(f"ds{key}: {kind}: size {size:.3f} noise {noise:.3f} apparent {apparent:+.3f} "
          f"median k {np.nanmedian(kw):.3f} N/mm range {np.nanmin(kw):.3f}-{np.nanmax(kw):.3f} {extra}", flush=True)


if __name__ == '__main__':
    keys = sys.argv[1:] or sorted(SETS)
    for k in keys:
        build(k)
