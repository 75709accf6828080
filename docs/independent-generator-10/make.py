"""Independent synthetic generator (indep10): 12 datasets of 6 bushes x 3 canes
x 3 pushes, with hidden effects whose values vary between canes or plants.

    /work/venv/bin/python make.py            # all 12
    /work/venv/bin/python make.py 3 6        # only ds03 and ds06

Data -> data/dsNN/ (push_points.csv, trials/*.csv, canes/*.yaml)
Truth -> truth/dsNN.json (never inside data/)
"""
import os
for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")
import json
import os
import sys
import time

import numpy as np

from rod import Rod2D

HERE = os.path.dirname(os.path.abspath(__file__))
E_STATED = 4.57e9
RHO = 580.0
GF = 9.80665e-3          # N per gram-force
NEL = 160                # rod elements
STEP = 0.5e-3            # rig step (m)
MAX_ROWS = 88            # rig rows per trial (iterations 2..89)
STOP_GF = 1000.0         # rig stop (raw reading)
TAPE_WIN = 0.15          # probe perpendicular: chord over +-150 mm
OPERATOR_SD_DEG = 2.0    # probe set perpendicular by eye: operator error

DESIGN = {
    1: dict(kind="null"),
    2: dict(kind="root_global"),
    3: dict(kind="root_bush"),
    4: dict(kind="root_cane", ln_sd=0.7, k0=(15, 60)),
    5: dict(kind="root_cane", ln_sd=0.4, k0=(80, 200)),
    6: dict(kind="flare"),
    7: dict(kind="null"),
    8: dict(kind="rig_bush"),
    9: dict(kind="modulus_bush"),
    10: dict(kind="root_cane_modulus", ln_sd=0.5, k0=(30, 80)),
    11: dict(kind="probe_bush"),
    12: dict(kind="neighbour"),
}


# ----------------------------------------------------------------------------- cane
def gmean(v):
    v = np.asarray(list(v), float)
    return float(np.exp(np.mean(np.log(v))))


class Cane:
    """Truth geometry of one cane (planar, in the vertical plane of azimuth phi)."""

    def __init__(self, rng):
        for _ in range(200):
            if self._draw(rng):
                return
        raise RuntimeError("could not draw a cane")

    def _draw(self, rng):
        L = self.L = rng.uniform(1.15, 1.75)
        # equilibrium (photographed) shape: angle from vertical vs s
        tb = rng.uniform(0.04, 0.30)
        dth = rng.uniform(0.15, 0.65)
        q = rng.uniform(1.2, 2.5)
        A = rng.uniform(0.0, 0.06)
        fr = rng.uniform(0.7, 1.5)
        ph = rng.uniform(0, 2 * np.pi)
        self.shape = dict(base_lean=tb, droop=dth, droop_exp=q, wiggle_amp=A,
                          wiggle_freq=fr, wiggle_phase=ph)
        self.theta_f = lambda t: (tb + dth * t ** q + A * (np.sin(2 * np.pi * fr * t + ph)
                                                         - np.sin(ph)))
        # taper: d = (d_tip + (d_base-d_tip) (1-s/L)^p) * (1 + bud bumps)
        self.d_base = float(np.clip(np.exp(rng.normal(np.log(0.022), 0.22)), 0.011, 0.030))
        self.d_tip = rng.uniform(0.0015, 0.0035)
        self.p = float(np.exp(rng.normal(np.log(1.05), 0.18)))
        nb = rng.integers(4, 9)
        self.bumps = [(rng.uniform(0.1, 1.0) * L, rng.uniform(0.02, 0.06) * rng.choice([1, 1, -1]),
                       rng.uniform(0.010, 0.025)) for _ in range(nb)]
        self.flare = None   # (f, decay m)
        # fine truth curve (for heights / clicks / chords)
        self.sf = np.linspace(0, L, 4001)
        thf = self.theta_f(self.sf / L)
        ds = np.diff(self.sf)
        thm = 0.5 * (thf[1:] + thf[:-1])
        self.xf = np.concatenate([[0], np.cumsum(ds * np.sin(thm))])
        self.zf = np.concatenate([[0], np.cumsum(ds * np.cos(thm))])
        # push points: top at 48-72 % of L, then 80-120 mm lower twice (tape heights)
        s1 = rng.uniform(0.48, 0.72) * L
        z1 = np.interp(s1, self.sf, self.zf)
        z2 = z1 - rng.uniform(0.080, 0.120)
        z3 = z2 - rng.uniform(0.080, 0.120)
        if not (0.50 <= z3 and z1 <= 1.10):
            return False
        self.z_true = np.array([z1, z2, z3])
        self.s_push = np.interp(self.z_true, self.zf, self.sf)
        return True

    def d(self, s, flare=True):
        s = np.asarray(s, float)
        L = self.L
        base = self.d_tip + (self.d_base - self.d_tip) * np.clip(1 - s / L, 0, 1) ** self.p
        b = np.ones_like(s)
        for c, a, w in self.bumps:
            b = b + a * np.exp(-0.5 * ((s - c) / w) ** 2)
        out = base * b
        if flare and self.flare is not None:
            f, lam = self.flare
            out = out * (1 + f * np.exp(-s / lam))
        return out

    def theta_el(self, N):
        return self.theta_f((np.arange(N) + 0.5) / N)

    def chord_dir(self, s):
        a, b = max(0.0, s - TAPE_WIN), min(self.L, s + TAPE_WIN)
        v = np.array([np.interp(b, self.sf, self.xf) - np.interp(a, self.sf, self.xf),
                      np.interp(b, self.sf, self.zf) - np.interp(a, self.sf, self.zf)])
        return v / np.linalg.norm(v)


def probe_dir(cane, s, sigma, alpha):
    """Perpendicular to the cane chord in the push plane, on the push side
    (sign sigma of x), pitched by alpha (rad) toward +z."""
    t = cane.chord_dir(s)
    n = np.array([t[1], -t[0]])
    if n[0] * sigma < 0:
        n = -n
    m = t if t[1] > 0 else -t
    return np.cos(alpha) * n + np.sin(alpha) * m


def build_rod(cane, E, k_root=None, flare=True, springs=()):
    return Rod2D(cane.L, NEL, lambda s: cane.d(s, flare), E, cane.theta_el(NEL), rho=RHO,
                 gravity=True, k_root=k_root, rest="equilibrium", springs=springs)


# ----------------------------------------------------------------------------- rig
def fmt(v):
    v = round(float(v), 2)
    if v == 0:
        v = 0.0
    return repr(v)


def wrap16(t):
    return ((int(t) + 32768) % 65536) - 32768


def rig_trace(rng, u_grid, F_grid, k_rig, habits, q_res):
    """Rig samples for one push.  u_grid/F_grid: cane force (N) vs probe-tip
    travel (m) from contact.  Returns list of (force_gf_raw, step) and info."""
    gap = habits["gap_mm"] * 1e-3
    s0 = habits["seat_mm"] * 1e-3

    def seat(x):     # probe seating in the U: quadratic start, then x - s0
        x = np.maximum(x, 0.0)
        return np.where(x < 2 * s0, x ** 2 / (4 * s0), x - s0)

    def force_at(x, shift):
        # tip travel u (after seating, slip shift) with rig spring: x = u + F(u)/k_rig
        ue = np.linspace(0, u_grid[-1], 2000)
        Fe = np.interp(np.maximum(seat(ue) - shift, 0), u_grid, F_grid)
        Fe = np.where(seat(ue) - shift > 0, Fe, 0.0)
        X = ue + (Fe / k_rig if k_rig else 0.0)
        X = np.maximum.accumulate(X)
        return np.interp(x, X, Fe)

    n = MAX_ROWS
    steps = np.arange(n)
    x = steps * STEP - gap           # motor travel since contact
    F = force_at(x, 0.0)
    if habits.get("slip_mm"):
        # slip at the first sample whose clean force passes the slip threshold
        j = np.argmax(F > habits["slip_at_N"]) if np.any(F > habits["slip_at_N"]) else None
        if j is not None and j > 0:
            F2 = force_at(x, habits["slip_mm"] * 1e-3)
            F = np.where(steps >= j, F2, F)
            habits["slip_step"] = int(j)
        else:
            habits["slip_mm"] = 0.0
    clean_gf = F / GF
    # load cell: tare + drift + white noise + force-proportional AR(1) jitter
    e = np.zeros(n)
    r = rng.normal(0, 1, n)
    for i in range(1, n):
        e[i] = 0.7 * e[i - 1] + np.sqrt(1 - 0.49) * r[i]
    raw = (habits["tare_gf"] + habits["drift_gf_per_step"] * steps + clean_gf
           + rng.normal(0, habits["noise_gf"], n) + habits["jitter_rel"] * clean_gf * e)
    raw = np.round(raw / q_res) * q_res
    stop = np.argmax(raw >= STOP_GF) if np.any(raw >= STOP_GF) else n - 1
    return raw[:stop + 1], clean_gf[:stop + 1], x[:stop + 1]


# ----------------------------------------------------------------------------- one dataset
def make_dataset(nn):
    t0 = time.time()
    des = DESIGN[nn]
    kind = des["kind"]
    rng = np.random.default_rng(20250000 + 7919 * nn)
    out = os.path.join(HERE, "data", f"ds{nn:02d}")
    for sub in ("trials", "canes"):
        os.makedirs(os.path.join(out, sub), exist_ok=True)
        for f in os.listdir(os.path.join(out, sub)):
            os.remove(os.path.join(out, sub, f))
    truth = dict(dataset=f"ds{nn:02d}", generator="indep10/make.py", seed=20250000 + 7919 * nn,
                 E_stated=E_STATED, per_cane_modulus_ln_sd=0.15)

    # ---- dataset-level hidden-effect parameters
    g = {}
    if kind == "root_global":
        g["k_root"] = float(rng.uniform(20, 150))
    elif kind == "root_bush":
        g["k0"] = float(rng.uniform(20, 100))
        g["k_bush"] = [float(np.exp(rng.normal(np.log(g["k0"]), 0.5))) for _ in range(6)]
    elif kind in ("root_cane", "root_cane_modulus"):
        g["k0"] = float(rng.uniform(*des["k0"]))
        g["ln_sd"] = des["ln_sd"]
    if kind == "root_cane_modulus":
        g["scale"] = float(rng.choice([0.7, 1.4]))
    if kind == "rig_bush":
        g["k0"] = float(rng.uniform(200, 600))
        g["k_bush"] = [float(np.exp(rng.normal(np.log(g["k0"]), 0.4))) for _ in range(6)]
    if kind == "modulus_bush":
        g["scale"] = float(rng.uniform(0.7, 0.8) if rng.random() < 0.5 else rng.uniform(1.3, 1.5))
        z = rng.normal(0, 0.2, 6)
        g["bush_factor"] = [float(np.exp(v)) for v in z - z.mean()]   # centred: geomean 1
    if kind == "probe_bush":
        g["mean_deg"] = float(rng.uniform(15, 30))
        g["angle_bush_deg"] = [float(rng.normal(g["mean_deg"], 5.0)) for _ in range(6)]
    if kind == "neighbour":
        g["affected"] = sorted(rng.choice(18, size=9, replace=False).tolist())

    q_res = float(rng.uniform(0.02, 0.06))   # load-cell count (gf)
    rig = dict(step_mm=0.5, sample_ms=500, max_rows=MAX_ROWS, stop_raw_gf=STOP_GF,
               loadcell_resolution_gf=q_res, operator_pitch_sd_deg=OPERATOR_SD_DEG)

    pp_rows, canes_t, trials_t = [], {}, []
    for b in range(1, 7):
        bush_xy = np.array([1.6 * (b - 1), rng.normal(0, 0.2)])
        disp_abs = float(np.round(rng.uniform(0, 1200) * 2) / 2)
        tstamp = int(rng.integers(-32768, 32767))
        order = [(c, t) for c in range(1, 4) for t in range(1, 4)]
        rng.shuffle(order)   # probing order within the bush
        trial_order = {ct: i for i, ct in enumerate(order)}
        for c in range(1, 4):
            cid = f"b{b}c{c}"
            ci = (b - 1) * 3 + (c - 1)
            cane = Cane(rng)
            ln_e = rng.normal(0, 0.15)
            E_base = E_STATED * np.exp(ln_e)     # per-cane scatter (present in all sets)
            E = E_base
            k_root = None
            springs = []
            info = {}
            if kind == "root_global":
                k_root = g["k_root"]
            elif kind == "root_bush":
                k_root = g["k_bush"][b - 1]
            elif kind in ("root_cane", "root_cane_modulus"):
                k_root = float(np.exp(rng.normal(np.log(g["k0"]), g["ln_sd"])))
            if kind == "root_cane_modulus":
                E = E_base * g["scale"]
            if kind == "modulus_bush":
                E = E_base * g["scale"] * g["bush_factor"][b - 1]
            if kind == "flare":
                cane.flare = (float(rng.uniform(0.10, 0.60)), float(rng.uniform(0.05, 0.20)))
            if kind == "neighbour" and ci in g["affected"]:
                sn = float(rng.uniform(0.2, 0.7) * cane.L)
                kn = float(np.exp(rng.uniform(np.log(30), np.log(200))))
                springs = [dict(s=sn, dir=[1.0, 0.0], k=kn)]
                info["neighbour"] = dict(s_m=sn, frac_of_length=sn / cane.L, k_N_per_m=kn,
                                         height_m=float(np.interp(sn, cane.sf, cane.zf)))
            k_rig = g["k_bush"][b - 1] if kind == "rig_bush" else None
            bush_pitch = np.radians(g["angle_bush_deg"][b - 1]) if kind == "probe_bush" else 0.0

            rod_true = build_rod(cane, E, k_root, True, springs)
            rod_wo = build_rod(cane, E_base, None, False, ())
            rod_nom = build_rod(cane, E_STATED, None, False, ())
            # stability (gravity) sanity
            np.linalg.cholesky(rod_true.grad_hess(rod_true.theta0)[1])
            np.linalg.cholesky(rod_wo.grad_hess(rod_wo.theta0)[1])

            phi = rng.uniform(0, 2 * np.pi)
            sigma = float(rng.choice([-1.0, 1.0]))
            axis = np.array([np.cos(phi), np.sin(phi)])
            base_xy = bush_xy + rng.uniform(0, 0.12) * np.array([np.cos(rng.uniform(0, 6.3)),
                                                                 np.sin(rng.uniform(0, 6.3))])

            # ---- recorded measurements
            h_rec = np.round(cane.z_true * 1000 / 5) * 5 / 1000          # tape, 5 mm
            cal_sd = rng.uniform(0.10, 0.20) * 1e-3
            cal_loc = cane.s_push + rng.uniform(-0.010, 0.010, 3)
            cal_read = np.round((cane.d(cal_loc) + rng.normal(0, cal_sd, 3)) * 1e4) / 1e4
            # linear caliper line (noise-free values at the true locations) vs truth at base
            lf = np.polyfit(cal_loc, cane.d(cal_loc), 1)
            excess_vs_line = float((cane.d(0.0) - np.polyval(lf, 0.0)) * 1e3)

            # ---- clicks along the photographed shape
            nclk = int(rng.integers(10, 15))
            gaps = np.full(nclk - 1, 1.0) * (1 + rng.uniform(-0.2, 0.2, nclk - 1))
            sc = np.concatenate([[0], np.cumsum(gaps)])
            sc = sc / sc[-1] * cane.L
            noise_mm = rng.uniform(1.5, 3.5)
            pts = []
            for k, s in enumerate(sc):
                xl = np.interp(s, cane.sf, cane.xf)
                zl = np.interp(s, cane.sf, cane.zf)
                p = np.array([base_xy[0] + xl * axis[0], base_xy[1] + xl * axis[1], zl])
                nz = rng.normal(0, noise_mm * 1e-3, 3)
                if k == 0:
                    nz[2] = 0.0
                pts.append(p + nz)
            pts = np.array(pts)

            cane_truth = dict(E_true=float(E), E_scale_true=float(E / E_STATED),
                              E_percane_factor=float(np.exp(ln_e)), length_m=cane.L,
                              d_base_mm=float(cane.d(0.0) * 1e3),
                              d_base_noflare_mm=float(cane.d(0.0, False) * 1e3),
                              d_tip_mm=cane.d_tip * 1e3, taper_exponent=cane.p,
                              bud_bumps=[dict(s_m=c_, rel_amp=a_, width_m=w_) for c_, a_, w_ in cane.bumps],
                              shape=cane.shape, azimuth_rad=float(phi), push_side=sigma,
                              excess_vs_caliper_line_mm=excess_vs_line,
                              k_root=k_root, k_rig=k_rig,
                              click_noise_mm=noise_mm, n_clicks=nclk,
                              caliper_true_s_m=cal_loc.tolist(),
                              caliper_true_mm=(cane.d(cal_loc) * 1e3).tolist(), **info)
            if cane.flare is not None:
                f, lam = cane.flare
                cane_truth.update(flare_frac=f, flare_decay_m=lam,
                                  excess_mm=float(f * cane.d(0.0, False) * 1e3))
            if kind == "probe_bush":
                cane_truth["angle_deg"] = g["angle_bush_deg"][b - 1]
            canes_t[cid] = cane_truth

            # ---- pushes
            yaml_pp = []
            for t in range(1, 4):
                s = float(cane.s_push[t - 1])
                op = np.radians(rng.normal(0, OPERATOR_SD_DEG))
                d_true = probe_dir(cane, s, sigma, bush_pitch + op)
                d_wo = probe_dir(cane, s, sigma, op)
                c_true = rod_true.compliance(s, d_true)
                k_true = 1.0 / (c_true + (1.0 / k_rig if k_rig else 0.0))
                k_wo = 1.0 / rod_wo.compliance(s, d_wo)
                k_nom = 1.0 / rod_nom.compliance(s, probe_dir(cane, s, sigma, 0.0))
                u_grid = np.arange(0, 46.01, 0.5) * 1e-3
                Fc, _ = rod_true.push(s, d_true, u_grid, Fmax=11.8)
                if len(Fc) < len(u_grid):     # stopped early: extend linearly (beyond the stop)
                    sl = (Fc[-1] - Fc[-2]) / STEP
                    Fc = np.concatenate([Fc, Fc[-1] + sl * (u_grid[len(Fc):] - u_grid[len(Fc) - 1])])
                # ---- rig habits for this trial
                hab = dict(gap_mm=float(rng.uniform(-0.5, 0.5) if rng.random() < 0.25
                                        else rng.uniform(0.5, 7.0)),
                           seat_mm=float(rng.uniform(0.2, 1.0)),
                           tare_gf=float(rng.uniform(-110, 60)),
                           drift_gf_per_step=float(rng.normal(0, 0.04)),
                           noise_gf=float(rng.uniform(0.4, 1.2)),
                           jitter_rel=float(rng.uniform(0.005, 0.02)))
                if rng.random() < 0.04:
                    hab.update(slip_mm=float(rng.uniform(0.8, 2.5)),
                               slip_at_N=float(rng.uniform(1.5, 6.0)))
                raw, clean, x = rig_trace(rng, u_grid, Fc, k_rig, hab, q_res)
                first_it = 2 if rng.random() < 0.85 else 3
                dup = int(rng.integers(5, len(raw))) if (rng.random() < 0.04 and len(raw) > 8) else None
                hab.update(first_iteration=first_it, duplicated_row_index=dup, n_rows=len(raw),
                           stopped_at_1000gf=bool(raw[-1] >= STOP_GF))
                # rig's own slope: clean force > 20 gf vs motor
                m = clean > 20
                k_fit = float(np.polyfit(x[m], clean[m] * GF, 1)[0]) if m.sum() >= 3 else None
                fname = f"bush_{b}_branch_{c}_trial_{t}.csv"
                # absolute positions/timestamps continue in probing order within the bush
                trials_t.append(dict(bush=b, cane=c, trial=t, cane_id=cid, file="trials/" + fname,
                                     s_m=s, height_true_m=float(cane.z_true[t - 1]),
                                     height_mm=int(round(h_rec[t - 1] * 1000)),
                                     probe_pitch_true_deg=float(np.degrees(bush_pitch + op)),
                                     operator_pitch_deg=float(np.degrees(op)),
                                     k_with_N_per_mm=k_true / 1000, k_without_N_per_mm=k_wo / 1000,
                                     k_nominal_N_per_mm=k_nom / 1000,
                                     k_rigfit_clean_N_per_mm=None if k_fit is None else k_fit / 1000,
                                     habits=hab, _raw=raw, _order=trial_order[(c, t)]))
                pp_rows.append((b, c, t, int(round(h_rec[t - 1] * 1000)),
                                round(cal_read[t - 1] * 1000, 1), "trials/" + fname))
                yaml_pp.append((t, h_rec[t - 1]))

            # ---- YAML
            dirv = sigma * axis
            lines = [f"id: {cid}", "polyline:", "  raw: true", "  points:"]
            for p in pts:
                lines.append(f"    - [{p[0]:.4f}, {p[1]:.4f}, {p[2]:.4f}]")
            lines.append("calipers:")
            for t in range(3):
                lines.append(f"  - {{height: {h_rec[t]:.3f}, diameter: {cal_read[t]:.4f}}}")
            lines.append("push_points:")
            for t, hh in yaml_pp:
                lines += [f'  - id: "{t}"', f"    height: {hh:.3f}",
                          f"    direction: [{dirv[0]:.3f}, {dirv[1]:.3f}, 0.0]",
                          f"    trial: ../trials/bush_{b}_branch_{c}_trial_{t}.csv"]
            lines += ["material:", f"  flexural_modulus: {E_STATED:.3g}", f"  density: {RHO}",
                      "provenance:", "  synthetic: true",
                      '  assumptions: ["polyline clicked on a photo of the standing cane",'
                      ' "three caliper readings at the push-point tape marks"]']
            with open(os.path.join(out, "canes", f"{cid}.yaml"), "w") as fh:
                fh.write("\n".join(lines) + "\n")

        # ---- write this bush's trials in probing order (positions/timestamps continue)
        bt = sorted([tr for tr in trials_t if tr["bush"] == b], key=lambda r: r["_order"])
        for tr in bt:
            raw = tr.pop("_raw")
            tr.pop("_order")
            hab = tr["habits"]
            it0 = hab["first_iteration"]
            if it0 == 3:
                tstamp += 500
                disp_abs += 0.5
            rows = []
            for i, v in enumerate(raw):
                rows.append(f"{float(it0 + i)},{float(wrap16(tstamp))},{fmt(v)},"
                            f"{disp_abs:.1f},{tr['height_mm']}")
                tstamp += 500
                disp_abs += 0.5
            if hab["duplicated_row_index"] is not None:
                j = hab["duplicated_row_index"]
                rows.insert(j, rows[j])
            with open(os.path.join(out, tr["file"]), "w", newline="") as fh:
                fh.write("Iteration,Time Stamp,Load Cell Reading (gf),Displacement (mm),Height (mm)\r\n")
                fh.write("\r\n".join(rows) + "\r\n")
            # next trial: one sample skipped, plus a pause when changing cane
            tstamp += 500 + int(rng.integers(0, 3)) * 500
            disp_abs += 0.5

    with open(os.path.join(out, "push_points.csv"), "w") as fh:
        fh.write("bush,cane,trial,height_mm,diameter_mm,file\n")
        for r in pp_rows:
            fh.write(f"{r[0]},{r[1]},{r[2]},{r[3]},{r[4]},{r[5]}\n")

    # ---- expected answer
    cids = list(canes_t)
    eff = []
    if kind in ("root_global", "root_bush", "root_cane", "root_cane_modulus"):
        vals = {c: canes_t[c]["k_root"] for c in cids}
        e = dict(effect="root_compliance", param="k_root", units="N m/rad",
                 varies_per_cane=kind != "root_global",
                 varies_by={"root_global": "none", "root_bush": "bush"}.get(kind, "cane"),
                 global_value={"k_root": gmean(vals.values())},
                 per_cane={c: {"k_root": v} for c, v in vals.items()})
        if "k0" in g:
            e["k0_design"] = g["k0"]
        if "ln_sd" in g:
            e["ln_sd_design"] = g["ln_sd"]
        if kind == "root_bush":
            e["k_bush"] = g["k_bush"]
            e["ln_sd_design"] = 0.5
        eff.append(e)
    if kind in ("root_cane_modulus", "modulus_bush"):
        vals = {c: canes_t[c]["E_scale_true"] for c in cids}
        e = dict(effect="modulus_scale", param="scale", units="E_true/E_stated",
                 varies_per_cane=kind == "modulus_bush",
                 varies_by="bush (+ per-cane scatter)" if kind == "modulus_bush" else "none (per-cane scatter only)",
                 global_value={"scale": g["scale"]},
                 realized_geomean_scale=gmean(vals.values()),
                 per_cane={c: {"scale": v} for c, v in vals.items()})
        if kind == "modulus_bush":
            e["bush_factor"] = g["bush_factor"]
        eff.append(e)
    if kind == "flare":
        vals = {c: canes_t[c]["excess_mm"] for c in cids}
        eff.append(dict(effect="base_flare", param="excess_mm", units="mm (extra base diameter)",
                        varies_per_cane=True, varies_by="cane",
                        global_value={"excess_mm": float(np.median(list(vals.values())))},
                        global_value_geomean={"excess_mm": gmean(vals.values())},
                        per_cane={c: {"excess_mm": vals[c],
                                      "excess_vs_caliper_line_mm": canes_t[c]["excess_vs_caliper_line_mm"],
                                      "flare_frac": canes_t[c]["flare_frac"],
                                      "decay_m": canes_t[c]["flare_decay_m"]} for c in cids}))
    if kind == "rig_bush":
        vals = {c: canes_t[c]["k_rig"] for c in cids}
        eff.append(dict(effect="rig_compliance", param="k_rig", units="N/m", varies_per_cane=True,
                        varies_by="bush", global_value={"k_rig": gmean(g["k_bush"])},
                        k0_design=g["k0"], ln_sd_design=0.4, k_bush=g["k_bush"],
                        per_cane={c: {"k_rig": v} for c, v in vals.items()}))
    if kind == "probe_bush":
        eff.append(dict(effect="probe_misalignment", param="angle_deg", units="deg (up)",
                        varies_per_cane=True, varies_by="bush",
                        global_value={"angle_deg": float(np.mean(g["angle_bush_deg"]))},
                        mean_design_deg=g["mean_deg"], sd_design_deg=5.0,
                        angle_bush_deg=g["angle_bush_deg"],
                        per_cane={c: {"angle_deg": canes_t[c]["angle_deg"]} for c in cids}))
    if kind == "neighbour":
        aff = {c: canes_t[c]["neighbour"] for c in cids if "neighbour" in canes_t[c]}
        eff.append(dict(effect="neighbour_spring", in_library=False, varies_per_cane=True,
                        varies_by="cane (about half of the canes only)",
                        description="lateral linear spring (horizontal, in the push plane) at 20-70 % "
                                    "of the cane length, 30-200 N/m, engaged from the start",
                        global_value={"k_N_per_m": gmean(v["k_N_per_m"] for v in aff.values())},
                        per_cane={c: {"k_N_per_m": v["k_N_per_m"], "height_m": v["height_m"],
                                      "frac_of_length": v["frac_of_length"]} for c, v in aff.items()}))
    lr = [abs(np.log(t["k_with_N_per_mm"] / t["k_without_N_per_mm"])) for t in trials_t]
    lr_nom = [abs(np.log(t["k_with_N_per_mm"] / t["k_nominal_N_per_mm"])) for t in trials_t]
    truth.update(
        hidden_effects=eff,
        expected=dict(named=[dict(effect=e["effect"], varies_per_cane=e["varies_per_cane"],
                                  scope="per_cane" if e["varies_per_cane"] else "global",
                                  global_value=e["global_value"]) for e in eff
                             if e.get("in_library", True)],
                      unexplained=kind == "neighbour"),
        size=dict(median_abs_log_k_with_over_without=float(np.median(lr)),
                  max_abs_log_k_with_over_without=float(np.max(lr)),
                  median_abs_log_k_with_over_without_affected_only=float(np.median([v for v in lr if v > 1e-12] or [0.0])),
                  median_abs_log_k_true_over_nominal=float(np.median(lr_nom))),
        notes=("k_with: true small-deflection stiffness along the probe (rig spring in series where "
               "present), k_without: same cane without the hidden effect(s) (per-cane modulus "
               "scatter and operator pitch kept), k_nominal: stated modulus 4.57 GPa, true geometry "
               "without effects, probe exactly perpendicular. All N/mm."),
        rig_habits=dict(rig, habits=(
            "dead zone: contact gap U(0.5,7) mm, or U(-0.5,0.5) mm (already touching) in 25 % of "
            "trials; probe seating in the U over 0.2-1 mm (quadratic onset); tare U(-110,60) gf; "
            "slow tare drift N(0,0.04) gf/sample; white noise 0.4-1.2 gf; force-proportional AR(1) "
            "jitter 0.5-2 %; load-cell count quantisation (per dataset); a slip (force drop, "
            "0.8-2.5 mm of lost travel) in ~4 % of trials; an exactly duplicated row in ~4 % of "
            "trials; first sample missing (Iteration starts at 3.0) in ~15 %; stop at the first "
            "raw reading >= 1000 gf or after 88 rows; 16-bit ms time stamps, 500 ms per sample; "
            "absolute positions/time continue through each bush in a shuffled probing order; "
            "probe pitch by eye with 2 deg sd operator error in every set")),
        canes=canes_t, trials=trials_t, design=dict(kind=kind, **{k: v for k, v in g.items()}))
    os.makedirs(os.path.join(HERE, "truth"), exist_ok=True)
    with open(os.path.join(HERE, "truth", f"ds{nn:02d}.json"), "w") as fh:
        json.dump(truth, fh, indent=1, default=lambda o: o.tolist() if hasattr(o, "tolist") else float(o))
    n_stop = sum(t["habits"]["stopped_at_1000gf"] for t in trials_t)
    ks = [t["k_with_N_per_mm"] for t in trials_t]
    print(f"ds{nn:02d} {kind:18s} size {truth['size']['median_abs_log_k_with_over_without']:.3f} "
          f"k {min(ks):.3f}-{max(ks):.3f} N/mm, {n_stop}/54 hit 1000 gf, {time.time()-t0:.0f} s",
          flush=True)


if __name__ == "__main__":
    which = [int(a) for a in sys.argv[1:]] or list(range(1, 13))
    for nn in which:
        make_dataset(nn)
