"""Score a canebench discovery output against this test bed's truth.
Usage: python score.py truth/dsNN.json OUT_DIR      (reads OUT_DIR/discovery.json)
Exit code 0 when the set is right, 1 when not."""
import json, math, os, re, sys

LIBRARY = ['modulus_scale', 'root_compliance', 'rig_compliance', 'base_flare', 'probe_misalignment', 'obstruction']
PARAM = {'modulus_scale': 'scale', 'root_compliance': 'k_root', 'rig_compliance': 'k_rig', 'probe_misalignment': 'angle_deg'}
TOL = {'scale': ('ln', 0.15), 'k_root': ('ln', 0.40), 'k_rig': ('ln', 0.40), 'angle_deg': ('abs', 6.0)}
ONSET_TOL_MM = 3.0


def num(v):
    """A parameter value as one number: a number, or the median of a per-cane dict/list."""
    if isinstance(v, (int, float)) and not isinstance(v, bool):
        return float(v)
    if isinstance(v, dict):
        for k in ('value', 'median', 'global', 'estimate'):
            if k in v:
                return num(v[k])
        v = list(v.values())
    if isinstance(v, (list, tuple)):
        xs = sorted(x for x in (num(u) for u in v) if x is not None and math.isfinite(x))
        if xs:
            n = len(xs); return xs[n // 2] if n % 2 else 0.5 * (xs[n // 2 - 1] + xs[n // 2])
    return None


def trial_matcher(truth):
    keys = {}
    for r in truth['trials']:
        b, c, t = r['bush'], r['cane'], r['trial']
        for k in (r['stem'], r['file'], os.path.basename(r['file']), 'b%dc%dt%d' % (b, c, t), 'b%dc%d_%d' % (b, c, t),
                  'b%dc%dp%d' % (b, c, t), 'b%dc%d/%d' % (b, c, t), 'b%dc%d:%d' % (b, c, t),
                  'bush_%d_branch_%d_trial_%d' % (b, c, t)):
            keys[str(k).lower()] = r

    def match(tid):
        s = str(tid).lower().strip()
        if s in keys:
            return keys[s]
        best = None
        for r in truth['trials']:        # the stem inside a longer id (path, prefix)
            st = r['stem'].lower()
            if re.search(r'(^|[^0-9a-z])' + re.escape(st) + r'($|[^0-9a-z])', s):
                if best is None or len(st) > len(best['stem']):
                    best = r
        if best is not None:
            return best
        if isinstance(tid, dict):
            try:
                b, c, t = int(tid['bush']), int(tid['cane']), int(tid['trial'])
                return next(r for r in truth['trials'] if (r['bush'], r['cane'], r['trial']) == (b, c, t))
            except Exception:
                return None
        m = re.findall(r'\d+', s)
        if len(m) >= 3 and not any(r['stem'].startswith('run_') for r in truth['trials']):
            b, c, t = map(int, m[-3:])
            for r in truth['trials']:
                if (r['bush'], r['cane'], r['trial']) == (b, c, t):
                    return r
        return None
    return match


def main(truth_path, out_dir):
    truth = json.load(open(truth_path))
    path = out_dir if out_dir.endswith('.json') else os.path.join(out_dir, 'discovery.json')
    disc = json.load(open(path))
    exp = set(truth['expected']['named']); ool = truth['out_of_library']
    named = disc.get('named') or []
    names = [n.get('effect') for n in named]
    lib_named = set(x for x in names if x in LIBRARY)
    other = [x for x in names if x not in LIBRARY]
    unexpl = bool(disc.get('unexplained'))
    ok = True
    print('set %s: %s' % (truth['set'], truth['description']))
    print('  expected named: %s   unexplained expected: %s' % (sorted(exp) or '[]', ool))
    print('  tool named:     %s   unexplained: %s%s' % (names or '[]', unexpl,
                                                        ('   (names outside the library: %s)' % other) if other else ''))
    missing = exp - lib_named; false = lib_named - exp
    if missing:
        ok = False; print('  MISSING: %s' % sorted(missing))
    if false:
        ok = False; print('  FALSELY NAMED: %s' % sorted(false))
    if unexpl != ool:
        ok = False; print('  WRONG unexplained flag (should be %s)' % ool)
    # parameters
    for n in named:
        eff = n.get('effect'); key = PARAM.get(eff)
        if eff not in exp or key is None or key not in truth['params']:
            continue
        params = n.get('params') or {}
        v = num(params.get(key)); tv = truth['params'][key]
        if v is None:
            ok = False; print('  %s: no numeric %s in params %s' % (eff, key, params)); continue
        kind, tol = TOL[key]
        if kind == 'ln':
            err = math.log(v / tv) if v > 0 else float('inf'); txt = 'ln error %+.3f (tol %.2f)' % (err, tol)
        else:
            err = v - tv
            txt = 'error %+.2f deg (tol %.1f)' % (err, tol)
        ci = (n.get('ci95') or {}).get(key)
        cover = ''
        if isinstance(ci, (list, tuple)) and len(ci) == 2 and all(isinstance(x, (int, float)) for x in ci):
            cover = '  ci95 [%.4g, %.4g] %s truth' % (ci[0], ci[1], 'covers' if ci[0] <= tv <= ci[1] else 'MISSES')
        good = abs(err) <= tol
        ok &= good
        print('  %-18s %s = %.4g  truth %.4g  %s  %s%s' % (eff, key, v, tv, txt, 'ok' if good else 'BAD', cover))
    # obstruction onsets
    match = trial_matcher(truth)
    pred = {}
    unmatched = 0
    for r in disc.get('trials') or []:
        tr = match(r.get('trial'))
        if tr is None:
            unmatched += 1; continue
        pred[tr['file']] = r.get('obstruction_onset_mm')
    if unmatched:
        print('  note: %d discovery trial ids not matched to truth trials' % unmatched)
    tp = fp = fn = 0; errs = []
    for tr in truth['trials']:
        p = pred.get(tr['file']); t = tr['obstruction_onset_mm']
        if t is not None and p is not None:
            tp += 1; errs.append(abs(p - t))
        elif t is not None:
            fn += 1
        elif p is not None:
            fp += 1
    n_obs = sum(1 for tr in truth['trials'] if tr['obstruction_onset_mm'] is not None)
    n_clean = len(truth['trials']) - n_obs
    if 'obstruction' in exp:
        errs.sort(); med = errs[len(errs) // 2] if errs else float('nan')
        within = sum(e <= ONSET_TOL_MM for e in errs)
        good = (n_obs > 0 and within >= 0.7 * n_obs and fp <= max(1, 0.1 * n_clean))
        ok &= good
        print('  obstruction onsets: %d/%d truth trials flagged, %d within %.0f mm (median |err| %.2f mm), '
              '%d false flags of %d clean  %s' % (tp, n_obs, within, ONSET_TOL_MM, med, fp, n_clean, 'ok' if good else 'BAD'))
    elif fp:
        print('  info: %d trials flagged with an obstruction onset (none hidden in this set)' % fp)
    print('RESULT %s: %s' % (truth['set'], 'RIGHT' if ok else 'WRONG'))
    return 0 if ok else 1


if __name__ == '__main__':
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    sys.exit(main(sys.argv[1], sys.argv[2]))
