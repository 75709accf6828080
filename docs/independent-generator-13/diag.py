"""Diagnostics of the written rig CSVs (reads only data/, like a user would)."""
import csv, glob, os, sys
import numpy as np

def read(f):
    rows = list(csv.reader(open(f, newline='')))
    a = np.array([[float(x) for x in r] for r in rows[1:]])
    return a

def trial_stats(a, noise=None):
    F = a[:, 2]; u = a[:, 3] - a[0, 3]
    base = F[0]
    # contact: first sample where F rises > 6 gf above the first reading and keeps rising
    d = F - base
    i0 = int(np.argmax(d > 8)) if np.any(d > 8) else len(F) - 1
    seg = slice(max(i0 - 1, 0), len(F))
    uu, FF = u[seg], F[seg]
    n = len(uu)
    res = {}
    res['rows'] = len(F)
    m = F > 20
    res['k'] = np.polyfit(u[m], F[m], 1)[0] * 9.80665e-3 if m.sum() > 3 else np.nan
    # drops: successive decrease larger than 8 gf
    dF = np.diff(F)
    res['drops'] = int(np.sum(dF < -8))
    # curvature: slope of last third / slope of first third of the contact part
    if n >= 12:
        t = n // 3
        s1 = np.polyfit(uu[:t], FF[:t], 1)[0]
        s3 = np.polyfit(uu[-t:], FF[-t:], 1)[0]
        res['curv'] = s3 / s1 if s1 > 0 else np.nan
        # linear fit residual rms
        p = np.polyfit(uu, FF, 1)
        res['lin_rms'] = float(np.sqrt(np.mean((FF - np.polyval(p, uu)) ** 2)))
    else:
        res['curv'] = np.nan; res['lin_rms'] = np.nan
    return res

for ds in sys.argv[1:]:
    fs = sorted(glob.glob(os.path.join('data', ds, 'trials', '*.csv')))
    S = [trial_stats(read(f)) for f in fs]
    k = np.array([s['k'] for s in S]); cv = np.array([s['curv'] for s in S])
    dr = np.array([s['drops'] for s in S]); lr = np.array([s['lin_rms'] for s in S])
    print('%s n=%d k(N/mm) p5/50/95 %s  curv p10/50/90 %s  drops>0 %.2f (med %d)  lin_rms med %.1f gf  rows med %d  stop %.2f' % (
        ds, len(S), np.round(np.nanpercentile(k, [5, 50, 95]), 3), np.round(np.nanpercentile(cv, [10, 50, 90]), 2),
        np.mean(dr > 0), np.median(dr), np.nanmedian(lr), np.median([s['rows'] for s in S]),
        np.mean([read(f)[-1, 2] >= 1000 for f in fs])))
