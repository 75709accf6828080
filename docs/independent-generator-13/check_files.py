"""Check that every generated file parses and follows the documented layout and
the field rig's habits.  usage: python check_files.py [data/dsNN ...]"""
import csv
import glob
import os
import sys

import numpy as np
import yaml

HERE = os.path.dirname(os.path.abspath(__file__))
HEADER = 'Iteration,Time Stamp,Load Cell Reading (gf),Displacement (mm),Height (mm)'


def chaikin(P, it=5, q=0.25):
    for _ in range(it):
        Q = [P[0]]
        for a, b in zip(P[:-1], P[1:]):
            Q += [(1 - q) * a + q * b, q * a + (1 - q) * b]
        Q.append(P[-1])
        P = np.array(Q)
    return P


def check_set(d):
    errs = []
    name = os.path.basename(d.rstrip('/'))
    pp = list(csv.DictReader(open(os.path.join(d, 'push_points.csv'), newline='')))
    if list(pp[0].keys()) != ['bush', 'cane', 'trial', 'height_mm', 'diameter_mm', 'file']:
        errs.append('push_points.csv header')
    files = set()
    for r in pp:
        f = os.path.join(d, r['file'])
        if not os.path.isfile(f):
            errs.append('missing ' + r['file'])
        files.add(os.path.normpath(f))
        int(r['bush']), int(r['cane']), int(r['trial']), int(r['height_mm']), float(r['diameter_mm'])
    ncsv = 0
    rowsn, stops = [], 0
    for f in sorted(glob.glob(os.path.join(d, 'trials', '*.csv'))):
        ncsv += 1
        raw = open(f, 'rb').read()
        if b'\r\n' not in raw or raw.count(b'\n') != raw.count(b'\r\n'):
            errs.append('%s: not CRLF' % f)
        lines = raw.decode().split('\r\n')
        if lines[0] != HEADER:
            errs.append('%s: header' % f)
        a = np.array([[float(x) for x in ln.split(',')] for ln in lines[1:] if ln])
        rowsn.append(len(a))
        it = a[:, 0]
        if not (it[0] in (2, 3) and np.all(np.diff(it) == 1) and it[-1] <= 89):
            errs.append('%s: iterations' % f)
        dt = np.diff(a[:, 1])
        if not np.all((dt == 500) | (dt == 500 - 65536)):
            errs.append('%s: time stamps' % f)
        if a[:, 1].min() < -32768 or a[:, 1].max() > 32767:
            errs.append('%s: time stamp range' % f)
        if not np.allclose(np.diff(a[:, 3]), 0.5):
            errs.append('%s: displacement steps' % f)
        if len(set(a[:, 4])) != 1:
            errs.append('%s: height not constant' % f)
        if np.any(a[:-1, 2] >= 1000):
            errs.append('%s: reading >= 1000 before the last row' % f)
        if a[-1, 2] >= 1000:
            stops += 1
        elif it[-1] != 89:
            errs.append('%s: ended early without reaching 1000 gf' % f)
    if ncsv != len(pp):
        errs.append('csv count %d != push rows %d' % (ncsv, len(pp)))
    ny = 0
    for y in sorted(glob.glob(os.path.join(d, 'canes', '*.yaml'))):
        ny += 1
        doc = yaml.safe_load(open(y))
        cid = doc['id']
        if os.path.basename(y) != cid + '.yaml':
            errs.append('%s: id' % y)
        P = np.array(doc['polyline']['points'], float)
        if P.shape[1] != 3 or len(P) < 2 or np.any(np.all(np.diff(P, axis=0) == 0, axis=1)):
            errs.append('%s: polyline' % y)
        if doc['polyline'].get('raw') is not True:
            errs.append('%s: raw' % y)
        S = chaikin(P)
        Ls = np.sum(np.linalg.norm(np.diff(S, axis=0), axis=1))
        zmax = S[:, 2].max()
        cal = doc['calipers']
        if len(cal) != 3:
            errs.append('%s: %d calipers' % (y, len(cal)))
        for c in cal:
            if (('s' in c) + ('height' in c)) != 1 or not (c['diameter'] > 0):
                errs.append('%s: caliper %s' % (y, c))
            if c.get('s', 0) > Ls or c.get('height', 0) > zmax:
                errs.append('%s: caliper off the cane %s' % (y, c))
        for p in doc['push_points']:
            if (('s' in p) + ('height' in p)) != 1:
                errs.append('%s: push %s' % (y, p))
            if p.get('s', 0) > Ls or p.get('height', 0) > zmax:
                errs.append('%s: push off the cane %s' % (y, p))
            tf = os.path.normpath(os.path.join(os.path.dirname(y), p['trial']))
            if tf not in files:
                errs.append('%s: push trial %s not in push_points.csv' % (y, p['trial']))
        # linear caliper fit must stay above 1 mm between the base and the pushes
        ss = []
        for c in cal:
            if 's' in c:
                ss.append(c['s'])
            else:
                i = int(np.argmax(S[:, 2] >= c['height']))
                ss.append(np.sum(np.linalg.norm(np.diff(S[:i + 1], axis=0), axis=1)))
        fit = np.polyfit(ss, [c['diameter'] for c in cal], 1)
        if np.polyval(fit, 0) < 1e-3 or fit[0] > 0:
            errs.append('%s: caliper fit odd (slope %.4f, d0 %.4f)' % (y, fit[0], np.polyval(fit, 0)))
        mat = doc.get('material')
        if mat is not None and not mat.get('flexural_modulus', 0) > 0:
            errs.append('%s: material' % y)
    ids = {(int(r['bush']), int(r['cane'])) for r in pp}
    if ny != len(ids):
        errs.append('yaml count %d != canes %d' % (ny, len(ids)))
    print('%s: %d canes, %d trials, rows median %d (min %d), %d stopped at 1000 gf: %s' % (
        name, ny, ncsv, np.median(rowsn), min(rowsn), stops, 'OK' if not errs else '%d problems' % len(errs)))
    for e in errs[:20]:
        print('   ' + e)
    return not errs


def main():
    sets = sys.argv[1:] or sorted(glob.glob(os.path.join(HERE, 'data', 'ds*')))
    ok = all([check_set(d) for d in sets])
    leaks = [f for f in glob.glob(os.path.join(HERE, 'data', '**', '*'), recursive=True)
             if 'truth' in os.path.basename(f).lower() or f.endswith('.json')]
    if leaks:
        print('truth-like files inside data/: %s' % leaks[:5])
        ok = False
    for t in sorted(glob.glob(os.path.join(HERE, 'truth', 'ds*.json'))):
        import json
        json.load(open(t))
    print('all OK' if ok else 'PROBLEMS')
    return 0 if ok else 1


if __name__ == '__main__':
    sys.exit(main())
