"""check_files.py [data/dsNN ...]: every file parses and looks like the rig's / the format documents'."""
import csv
import glob
import os
import re
import sys

import numpy as np
import yaml

HEADER = "Iteration,Time Stamp,Load Cell Reading (gf),Displacement (mm),Height (mm)"
HERE = os.path.dirname(os.path.abspath(__file__))


def chaikin(P, it=5, q=0.25):
    P = np.asarray(P, float)
    for _ in range(it):
        Q = [P[0]]
        for a, b in zip(P[:-1], P[1:]):
            Q += [(1 - q) * a + q * b, q * a + (1 - q) * b]
        Q.append(P[-1])
        P = np.array(Q)
    return P


def check_set(d):
    errs = []
    pp = os.path.join(d, 'push_points.csv')
    raw = open(pp, 'rb').read()
    rows = list(csv.DictReader(raw.decode().splitlines()))
    if list(rows[0].keys()) != ['bush', 'cane', 'trial', 'height_mm', 'diameter_mm', 'file']:
        errs.append(f"{pp}: columns {list(rows[0].keys())}")
    seen = set()
    for r in rows:
        k = (int(r['bush']), int(r['cane']), int(r['trial']))
        if k in seen:
            errs.append(f"{pp}: duplicate {k}")
        seen.add(k)
        float(r['height_mm']); float(r['diameter_mm'])
        f = os.path.join(d, r['file'])
        if not os.path.exists(f):
            errs.append(f"missing {f}")
            continue
        b = open(f, 'rb').read()
        if b'\r\n' not in b or b.count(b'\n') != b.count(b'\r\n'):
            errs.append(f"{f}: not CRLF")
        lines = b.decode().split('\r\n')
        if lines[-1] == '':
            lines = lines[:-1]
        if lines[0] != HEADER:
            errs.append(f"{f}: header")
        A = np.array([[float(x) for x in ln.split(',')] for ln in lines[1:]])
        n = len(A)
        if not (5 <= n <= 88):
            errs.append(f"{f}: {n} rows")
        if A[0, 0] not in (2.0, 3.0) or np.any(np.diff(A[:, 0]) != 1):
            errs.append(f"{f}: iteration")
        if A[:, 0].max() > 89:
            errs.append(f"{f}: iteration > 89")
        ts = A[:, 1]
        if ts.min() < -32768 or ts.max() > 32767:
            errs.append(f"{f}: time stamp out of 16-bit range")
        dts = np.mod(np.diff(ts), 65536)
        if np.any(dts != 500):
            errs.append(f"{f}: time steps {set(dts)}")
        if np.any(np.abs(np.diff(A[:, 3]) - 0.5) > 1e-9):
            errs.append(f"{f}: displacement steps")
        if len(set(A[:, 4])) != 1 or A[0, 4] != int(A[0, 4]):
            errs.append(f"{f}: height column")
        if abs(A[0, 4] - float(r['height_mm'])) > 1:
            errs.append(f"{f}: height {A[0, 4]} vs push_points {r['height_mm']}")
        F = A[:, 2]
        if np.any(F[:-1] >= 1000):
            errs.append(f"{f}: reading >= 1000 before the last row")
        if n < 88 - (A[0, 0] - 2) and F[-1] < 1000:
            errs.append(f"{f}: ended early without the 1000 gf stop")
        for ln in lines[1:]:
            p = ln.split(',')
            if not re.fullmatch(r'-?\d+\.\d', p[0]) or not re.fullmatch(r'-?\d+\.0', p[1]) or \
                    not re.fullmatch(r'-?\d+\.\d{1,2}', p[2]) or not re.fullmatch(r'-?\d+\.[05]', p[3]) or \
                    not re.fullmatch(r'\d+', p[4]):
                errs.append(f"{f}: number format {ln}")
                break
    # YAML
    ycount = 0
    for y in sorted(glob.glob(os.path.join(d, 'canes', '*.yaml'))):
        ycount += 1
        c = yaml.safe_load(open(y))
        name = os.path.splitext(os.path.basename(y))[0]
        if c.get('id') != name or not re.fullmatch(r'b\d+c\d+', name):
            errs.append(f"{y}: id")
        P = np.array(c['polyline']['points'], float)
        if P.shape[1] != 3 or len(P) < 2 or np.any(np.linalg.norm(np.diff(P, axis=0), axis=1) == 0):
            errs.append(f"{y}: polyline")
        if P[0, 2] != P[:, 2].min():
            errs.append(f"{y}: base not first / lowest")
        S = chaikin(P) if c['polyline'].get('raw') else P
        sarc = np.concatenate([[0], np.cumsum(np.linalg.norm(np.diff(S, axis=0), axis=1))])
        zmax, Ls = S[:, 2].max(), sarc[-1]
        if not c.get('calipers'):
            errs.append(f"{y}: calipers")
        for i, cal in enumerate(c['calipers']):
            if ('s' in cal) == ('height' in cal):
                errs.append(f"{y}: calipers[{i}] needs exactly one of s/height")
            v = cal.get('s', cal.get('height'))
            if not isinstance(cal['diameter'], float) or not cal['diameter'] > 0:
                errs.append(f"{y}: calipers[{i}].diameter")
            if not (0 < v < (Ls if 's' in cal else zmax) - 0.05):
                errs.append(f"{y}: calipers[{i}] off the cane")
        ids = set()
        b, cn = map(int, re.findall(r'\d+', name))
        for i, p in enumerate(c['push_points']):
            if p['id'] in ids:
                errs.append(f"{y}: push id dup")
            ids.add(p['id'])
            if ('s' in p) == ('height' in p):
                errs.append(f"{y}: push_points[{i}] s/height")
            v = p.get('s', p.get('height'))
            if not (0.1 < v < (Ls if 's' in p else zmax) - 0.1):
                errs.append(f"{y}: push_points[{i}] off the cane ({v} vs {zmax:.3f})")
            if 'trial' in p:
                t = os.path.normpath(os.path.join(os.path.dirname(y), p['trial']))
                if not os.path.exists(t):
                    errs.append(f"{y}: trial link {p['trial']}")
                rel = os.path.relpath(t, d).replace(os.sep, '/')
                if not any(r['file'] == rel and int(r['bush']) == b and int(r['cane']) == cn for r in rows):
                    errs.append(f"{y}: trial {rel} not a push_points row of this cane")
            dv = p['direction']
            if len(dv) != 3 or np.hypot(dv[0], dv[1]) == 0:
                errs.append(f"{y}: direction")
        m = c.get('material')
        if m is not None and not isinstance(m.get('flexural_modulus'), float):
            errs.append(f"{y}: modulus not a float")
        npp = sum(1 for r in rows if int(r['bush']) == b and int(r['cane']) == cn)
        if npp != len(c['push_points']):
            errs.append(f"{y}: {len(c['push_points'])} push points vs {npp} rows")
    # no truth inside data
    for f in glob.glob(os.path.join(d, '**', '*'), recursive=True):
        if os.path.isfile(f) and re.search(r'truth|hidden|k_root|k_rig|obstruct', open(f, errors='ignore').read(), re.I):
            errs.append(f"{f}: mentions the truth")
    canes_csv = {(int(r['bush']), int(r['cane'])) for r in rows}
    if ycount != len(canes_csv):
        errs.append(f"{d}: {ycount} YAMLs for {len(canes_csv)} canes")
    return rows, errs


if __name__ == '__main__':
    sets = sys.argv[1:] or sorted(glob.glob(os.path.join(HERE, 'data', 'ds*')))
    bad = 0
    for d in sets:
        rows, errs = check_set(d)
        print(f"{os.path.basename(d)}: {len(rows)} trials, {len({(r['bush'], r['cane']) for r in rows})} canes: "
              f"{'OK' if not errs else str(len(errs)) + ' problems'}")
        for e in errs[:10]:
            print("   ", e)
        bad += bool(errs)
    sys.exit(1 if bad else 0)
