"""Score a canebench discovery against one indep13 truth file.

usage: python score.py truth/dsNN.json OUT_DIR      (reads OUT_DIR/discovery.json)

Right = every expected library effect named, no other library effect named,
`unexplained` equal to the truth, parameters within tolerance, and the
obstruction rules met.  Prints RIGHT/WRONG with reasons; exit 0 if right,
1 if wrong, 2 if the inputs cannot be read.

Tolerances: scale |ln err| <= 0.15; k_root, k_rig |ln err| <= 0.40;
angle_deg |err| <= 6 deg.  Per-cane truths (ds03's k_root) are judged by the
median over canes of the per-cane error when the tool reports per-cane values,
else the reported single value is compared with the median of the truth.
Obstruction: when expected, >= 70 % of hidden onsets found within 3 mm; in
every set, onsets flagged on clean trials <= 10 % of the clean trials.
"""
import json
import math
import os
import re
import sys

LIBRARY = {'modulus_scale', 'root_compliance', 'rig_compliance', 'base_flare',
           'probe_misalignment', 'obstruction'}
PARAM = {'modulus_scale': ('scale', 'log', 0.15), 'root_compliance': ('k_root', 'log', 0.40),
         'rig_compliance': ('k_rig', 'log', 0.40), 'probe_misalignment': ('angle_deg', 'abs', 6.0)}
ONSET_TOL_MM, FOUND_FRAC, FALSE_FRAC = 3.0, 0.70, 0.10


def num(v):
    if isinstance(v, bool) or v is None:
        return None
    if isinstance(v, (int, float)):
        return float(v) if math.isfinite(float(v)) else None
    if isinstance(v, dict):
        for k in ('value', 'median', 'estimate', 'mean'):
            if k in v:
                return num(v[k])
    return None


def cane_key(k):
    m = re.search(r'b(?:ush)?[_ ]?(\d+)\D*c(?:ane)?[_ ]?(\d+)', str(k), re.I)
    return 'b%sc%s' % (m.group(1), m.group(2)) if m else str(k)


def reported(entry, key):
    """-> ('scalar', x) | ('per_cane', {cane: x}) | (None, None)"""
    params = entry.get('params') or {}
    v = params.get(key)
    x = num(v)
    if x is not None:
        return 'scalar', x
    per = {}
    if isinstance(v, dict):
        for k, vv in v.items():
            if num(vv) is not None:
                per[cane_key(k)] = num(vv)
    elif isinstance(v, list):
        for it in v:
            if isinstance(it, dict):
                cid = it.get('cane', it.get('id', it.get('cane_id')))
                vv = num(it.get(key, it.get('value')))
                if cid is not None and vv is not None:
                    per[cane_key(cid)] = vv
    for alt in ('per_cane', 'canes', 'by_cane'):
        src = entry.get(alt) or params.get(alt)
        if isinstance(src, dict):
            for k, vv in src.items():
                val = num(vv.get(key)) if isinstance(vv, dict) else num(vv)
                if val is not None:
                    per[cane_key(k)] = val
        elif isinstance(src, list):
            for it in src:
                if isinstance(it, dict):
                    cid = it.get('cane', it.get('id'))
                    val = num(it.get(key, (it.get('params') or {}).get(key)))
                    if cid is not None and val is not None:
                        per[cane_key(cid)] = val
    if per:
        return 'per_cane', per
    return None, None


def err_of(kind, got, want):
    if kind == 'log':
        if got is None or got <= 0 or want <= 0:
            return float('inf')
        return abs(math.log(got / want))
    return abs(got - want)


def median(xs):
    xs = sorted(xs)
    n = len(xs)
    return xs[n // 2] if n % 2 else 0.5 * (xs[n // 2 - 1] + xs[n // 2])


def main(argv):
    if len(argv) != 3:
        print(__doc__)
        return 2
    try:
        truth = json.load(open(argv[1]))
        disc = json.load(open(os.path.join(argv[2], 'discovery.json')))
    except (OSError, ValueError) as e:
        print('CANNOT SCORE: %s' % e)
        return 2
    reasons, notes = [], []
    exp = truth['expected']
    exp_names = {e['effect'] for e in exp['named']}
    named = [e for e in (disc.get('named') or []) if isinstance(e, dict)]
    got_names = [e.get('effect') for e in named]
    got_lib = {n for n in got_names if n in LIBRARY}
    for n in got_names:
        if n not in LIBRARY:
            notes.append('named effect %r is not in the library (ignored)' % n)
    for n in sorted(exp_names - got_lib):
        reasons.append('expected effect %s not named' % n)
    for n in sorted(got_lib - exp_names):
        reasons.append('effect %s named but not hidden' % n)

    # parameters
    for e in exp['named']:
        name = e['effect']
        if name not in got_lib or name not in PARAM:
            continue
        key, kind, tol = PARAM[name]
        entry = next(x for x in named if x.get('effect') == name)
        want = e['params'][key]
        gtype, got = reported(entry, key)
        scope = entry.get('scope')
        if scope != e.get('scope'):
            notes.append('%s: scope %r reported, truth %r' % (name, scope, e.get('scope')))
        if gtype is None:
            reasons.append('%s: no numeric %s reported' % (name, key))
            continue
        if isinstance(want, dict):                          # per-cane truth
            want_med = median(list(want.values()))
            if gtype == 'per_cane':
                errs = [err_of(kind, got[c], want[c]) for c in want if c in got]
                if not errs:
                    reasons.append('%s: per-cane %s reported for no known cane' % (name, key))
                    continue
                e_med = median(errs)
                msg = '%s: median per-cane error of %s %.3f over %d canes (tol %.2f)' % (
                    name, key, e_med, len(errs), tol)
            else:
                e_med = err_of(kind, got, want_med)
                msg = '%s: single %s %.4g vs truth median %.4g, error %.3f (tol %.2f)' % (
                    name, key, got, want_med, e_med, tol)
            (notes if e_med <= tol else reasons).append(msg)
        else:
            if gtype == 'per_cane':
                g = median(list(got.values()))
                msg_g = 'median of per-cane %s' % key
            else:
                g = got
                msg_g = key
            er = err_of(kind, g, want)
            msg = '%s: %s %.4g vs truth %.4g, error %.3f (tol %.2f)' % (name, msg_g, g, want, er, tol)
            (notes if er <= tol else reasons).append(msg)
        ci = (entry.get('ci95') or {}).get(key)
        if isinstance(ci, (list, tuple)) and len(ci) == 2 and not isinstance(want, dict):
            try:
                inside = float(ci[0]) <= want <= float(ci[1])
                notes.append('%s: truth %s %s the reported ci95 [%.4g, %.4g]' % (
                    name, key, 'inside' if inside else 'OUTSIDE', float(ci[0]), float(ci[1])))
            except (TypeError, ValueError):
                pass

    # unexplained
    une = disc.get('unexplained')
    if bool(une) != bool(exp['unexplained']):
        reasons.append('unexplained = %s, truth %s' % (une, exp['unexplained']))

    # obstruction onsets
    onsets = truth['obstruction_onsets_mm']
    files = {tid: tr['file'] for tid, tr in truth['trials'].items()}
    by_file = {os.path.basename(f): tid for tid, f in files.items()}
    flagged = {}
    for t in disc.get('trials') or []:
        if not isinstance(t, dict):
            continue
        key = str(t.get('trial', ''))
        tid = key if key in onsets else by_file.get(os.path.basename(key)) or by_file.get(
            os.path.basename(str(t.get('file', ''))))
        if tid is None:
            m = re.search(r'b(?:ush)?\D*(\d+)\D*(?:c|branch|cane)\D*(\d+)\D*t(?:rial)?\D*(\d+)', key, re.I)
            if m:
                tid = 'b%sc%st%s' % m.groups()
        if tid is None or tid not in onsets:
            notes.append('trial %r in discovery.json not in the truth' % key)
            continue
        flagged[tid] = num(t.get('obstruction_onset_mm'))
    hidden = [t for t, v in onsets.items() if v is not None]
    clean = [t for t, v in onsets.items() if v is None]
    false = [t for t in clean if flagged.get(t) is not None]
    if len(flagged) < len(onsets):
        notes.append('%d of %d trials absent from discovery.json trials (taken as no onset)' % (
            len(onsets) - len(flagged), len(onsets)))
    if clean:
        frac = len(false) / len(clean)
        msg = 'false obstruction flags on clean trials: %d of %d (%.0f %%, limit %.0f %%)' % (
            len(false), len(clean), 100 * frac, 100 * FALSE_FRAC)
        (reasons if frac > FALSE_FRAC + 1e-12 else notes).append(msg + (': ' + ', '.join(sorted(false)[:8])
                                                                       if false else ''))
    if 'obstruction' in exp_names and hidden:
        found = [t for t in hidden if flagged.get(t) is not None
                 and abs(flagged[t] - onsets[t]) <= ONSET_TOL_MM]
        frac = len(found) / len(hidden)
        msg = 'hidden onsets found within %.0f mm: %d of %d (%.0f %%, need %.0f %%)' % (
            ONSET_TOL_MM, len(found), len(hidden), 100 * frac, 100 * FOUND_FRAC)
        (notes if frac >= FOUND_FRAC else reasons).append(msg)
        miss = [t for t in hidden if t not in found]
        if miss:
            notes.append('missed or off by > %.0f mm: %s' % (ONSET_TOL_MM, ', '.join(
                '%s (truth %.1f, got %s)' % (t, onsets[t], 'none' if flagged.get(t) is None
                                             else '%.1f' % flagged[t]) for t in sorted(miss)[:10])))

    print('%s: %s' % (truth['set'], truth['description']))
    print('expected: %s, unexplained=%s' % (sorted(exp_names) or 'nothing', exp['unexplained']))
    print('got:      %s, unexplained=%s' % (sorted(got_lib) or 'nothing', une))
    for n in notes:
        print('  note: ' + n)
    for r in reasons:
        print('  WRONG: ' + r)
    print('RIGHT' if not reasons else 'WRONG')
    return 0 if not reasons else 1


if __name__ == '__main__':
    sys.exit(main(sys.argv))
