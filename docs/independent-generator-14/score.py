"""score.py truth/dsNN.json OUTDIR  -- compare OUTDIR/discovery.json with the hidden truth.

Verdict: right / misnamed / missed / not flagged / false name / false flag (exit 0 only for right).
Tolerances: scale |ln err| <= 0.15; k_root, k_rig |ln err| <= 0.40; angle_deg |err| <= 6 deg;
obstruction: >= 70 % of recorded hidden onsets found within 3 mm, flags on clean trials <= 10 %.
"""
import json
import math
import os
import re
import sys

LIB = {'modulus_scale', 'root_compliance', 'rig_compliance', 'base_flare', 'probe_misalignment', 'obstruction'}
PARAM = {'modulus_scale': 'scale', 'root_compliance': 'k_root', 'rig_compliance': 'k_rig',
         'probe_misalignment': 'angle_deg'}


def numbers(v):
    """all numbers in a (possibly nested) param value"""
    if isinstance(v, (int, float)) and not isinstance(v, bool):
        return [float(v)]
    if isinstance(v, dict):
        return [x for vv in v.values() for x in numbers(vv)]
    if isinstance(v, (list, tuple)):
        return [x for vv in v for x in numbers(vv)]
    return []


def find_param(params, key):
    if not isinstance(params, dict):
        return None
    if key in params:
        return params[key]
    for k, v in params.items():
        if key in k:
            return v
    for v in params.values():
        if isinstance(v, dict):
            r = find_param(v, key)
            if r is not None:
                return r
    return None


def median(xs):
    xs = sorted(xs)
    n = len(xs)
    return None if n == 0 else (xs[n // 2] if n % 2 else 0.5 * (xs[n // 2 - 1] + xs[n // 2]))


def trial_key(rec, by_file, by_id):
    for k in ('file', 'path', 'csv', 'trial_file', 'source'):
        v = rec.get(k)
        if isinstance(v, str):
            v2 = v.replace('\\', '/')
            for f, tid in by_file.items():
                if v2.endswith(f) or f.endswith(v2) or os.path.basename(v2) == os.path.basename(f) and \
                        v2.split('/')[-2:] == f.split('/')[-2:]:
                    return tid
    if all(k in rec for k in ('bush', 'cane', 'trial')):
        try:
            tid = f"b{int(rec['bush'])}c{int(rec['cane'])}t{int(rec['trial'])}"
            if tid in by_id:
                return tid
        except (TypeError, ValueError):
            pass
    for k in ('id', 'trial_id', 'name', 'trial'):
        v = rec.get(k)
        if isinstance(v, str):
            if v in by_id:
                return v
            v2 = v.replace('\\', '/')
            for f, tid in by_file.items():
                stem = os.path.splitext(f)[0]
                if v2.endswith(stem) or v2.endswith(f) or stem.endswith(v2):
                    return tid
            m = re.findall(r'\d+', v)
            if len(m) >= 3:
                tid = f"b{int(m[-3])}c{int(m[-2])}t{int(m[-1])}"
                if tid in by_id:
                    return tid
    return None


def main():
    truth = json.load(open(sys.argv[1]))
    out = sys.argv[2]
    path = out if out.endswith('.json') else os.path.join(out, 'discovery.json')
    print(f"== {truth['set']}  ({truth['kind']})  score of {path}")
    try:
        disc = json.load(open(path))
    except Exception as e:  # noqa
        print(f"UNREADABLE: {e}")
        print(f"VERDICT {truth['set']}: no output")
        sys.exit(2)
    exp = set(truth['expected']['named'])
    exp_unexpl = truth['expected']['unexplained']
    named_recs = disc.get('named') or []
    named = []
    for r in named_recs:
        eff = r.get('effect', r.get('name'))
        if eff in LIB:
            named.append((eff, r))
        else:
            print(f"  note: non-library name ignored: {eff}")
    nset = {e for e, _ in named}
    unexpl = bool(disc.get('unexplained'))
    print(f"  truth: named {sorted(exp) or '[]'}, unexplained {exp_unexpl}; size {truth['size']:.3f}, "
          f"noise {truth['noise']:.3f}, size/noise {truth['size'] / truth['noise']:.1f}")
    for e, r in named:
        print(f"  tool named: {e} scope={r.get('scope')} params={json.dumps(r.get('params'))[:300]} "
              f"ci95={json.dumps(r.get('ci95'))[:200]}")
    if not named:
        print("  tool named: nothing")
    print(f"  tool unexplained: {unexpl}   gap: {json.dumps(disc.get('gap'))[:300]}")

    # parameters
    param_ok = True
    hid = {h['effect']: h for h in truth['hidden_effects'] if h.get('in_library')}
    for e, r in named:
        if e not in hid or e not in PARAM:
            continue
        key = PARAM[e]
        got = find_param(r.get('params') or {}, key)
        vals = numbers(got) if got is not None else []
        if not vals:
            print(f"  param {key}: not reported")
            continue
        h = hid[e]
        if e == 'root_compliance':
            pc = h.get('per_cane') or {}
            loc = r.get('local')
            if isinstance(loc, dict) and any(k in pc for k in loc):
                errs = [math.log(float(numbers(v)[0]) / pc[k]) for k, v in loc.items() if k in pc and numbers(v) and numbers(v)[0] > 0]
                me = median([abs(x) for x in errs])
                print(f"  param k_root per cane ('local'): median |ln err| {me:.3f}, worst {max(abs(x) for x in errs):.3f} "
                      f"over {len(errs)} canes (signed median {median(errs):+.3f}); global value {median(vals):.4g} "
                      f"vs truth geomean {h['params']['k_root_geomean']:.4g}")
                param_ok &= me <= 0.40
                continue
            if isinstance(got, dict) and any(k in pc for k in got):
                errs = [math.log(float(v) / pc[k]) for k, v in got.items() if k in pc and isinstance(v, (int, float)) and v > 0]
                me = median([abs(x) for x in errs])
                print(f"  param k_root per cane: median |ln err| {me:.3f} over {len(errs)} canes "
                      f"(signed median {median(errs):+.3f})")
                param_ok &= me <= 0.40
                continue
            ref = h['params']['k_root_geomean']
            v = median(vals)
            err = math.log(v / ref) if v > 0 else float('inf')
            print(f"  param k_root: {v:.4g} vs truth geometric mean {ref:.4g} (per plant "
                  f"{h['params']['k_root_by_bush']}): ln err {err:+.3f}  (truth scope per plant; tool scope {r.get('scope')})")
            param_ok &= abs(err) <= 0.40
        elif e == 'probe_misalignment':
            v = median(vals)
            err = v - h['params']['angle_deg']
            print(f"  param angle_deg: {v:.3g} vs {h['params']['angle_deg']:.3g}: err {err:+.2f} deg")
            param_ok &= abs(err) <= 6
        else:
            ref = h['params'][key]
            v = median(vals)
            err = math.log(v / ref) if v > 0 else float('inf')
            if abs(err) > 5:
                print("  WARNING: factor ~1000 off: unit slip?")
            print(f"  param {key}: {v:.4g} vs {ref:.4g}: ln err {err:+.3f}")
            param_ok &= abs(err) <= (0.15 if key == 'scale' else 0.40)
        ci = r.get('ci95')
        if ci is not None:
            c = find_param(ci, key) if isinstance(ci, dict) else ci
            cv = numbers(c) if c is not None else []
            if len(cv) == 2:
                ref = (h['params'].get(key) if key in h['params'] else h['params'].get('k_root_geomean'))
                if ref is not None:
                    print(f"  ci95 {cv} covers truth {ref:.4g}: {min(cv) <= ref <= max(cv)}")
    # obstruction onsets
    obs_ok = True
    tt = truth['trials']
    by_file = {t['file']: t['id'] for t in tt}
    by_id = {t['id']: t for t in tt}
    recs = disc.get('trials') or []
    if isinstance(recs, dict):
        recs = [dict(v, id=k) if isinstance(v, dict) else {'id': k, 'obstruction_onset_mm': v} for k, v in recs.items()]
    found = {}
    unmatched = 0
    for r in recs:
        if not isinstance(r, dict):
            continue
        tid = trial_key(r, by_file, by_id)
        if tid is None:
            unmatched += 1
            continue
        found[tid] = r.get('obstruction_onset_mm')
    hidden_on = {t['id']: t['obstruction_onset_mm'] for t in tt if t['obstruction_onset_mm'] is not None}
    clean = [t['id'] for t in tt if t.get('obstruction') is None]
    hits, errs = 0, []
    for tid, on in hidden_on.items():
        g = found.get(tid)
        if isinstance(g, (int, float)):
            errs.append(g - on)
            hits += abs(g - on) <= 3
    false = [tid for tid in clean if isinstance(found.get(tid), (int, float))]
    print(f"  trials matched {len(found)}/{len(tt)} (unmatched records {unmatched})")
    if hidden_on:
        print(f"  onsets: {hits}/{len(hidden_on)} hidden onsets found within 3 mm; flagged {len(errs)}; "
              f"median |err| {median([abs(e) for e in errs]) if errs else float('nan'):.2f} mm; "
              f"errors {[round(e, 1) for e in errs]}")
        obs_ok &= hits >= 0.7 * len(hidden_on)
    print(f"  onsets flagged on clean trials: {len(false)}/{len(clean)} {false[:8]}")
    obs_ok &= len(false) <= 0.10 * max(len(clean), 1)

    # verdict
    if exp:
        if nset == exp and not unexpl:
            verdict = 'right' if (param_ok and ('obstruction' not in exp or obs_ok)) else 'right name, params/onsets off'
        elif not nset:
            verdict = 'missed' + (' (flagged unexplained)' if unexpl else '')
        elif nset & exp and nset != exp:
            verdict = 'partly right: ' + ', '.join([f"missed {sorted(exp - nset)}"] * bool(exp - nset) +
                                                     [f"extra {sorted(nset - exp)}"] * bool(nset - exp))
        elif nset == exp and unexpl:
            verdict = 'right name but flagged unexplained'
        else:
            verdict = 'misnamed'
    elif exp_unexpl:
        if unexpl and not nset:
            verdict = 'right'
        elif unexpl:
            verdict = f'flagged but false name {sorted(nset)}'
        elif nset:
            verdict = f'false name {sorted(nset)} (not flagged)'
        else:
            verdict = 'not flagged'
    else:
        if nset:
            verdict = f'false name {sorted(nset)}'
        elif unexpl:
            verdict = 'false flag (unexplained on a null)'
        else:
            verdict = 'right'
    if not exp and 'obstruction' not in nset and not obs_ok:
        verdict += ' (+ onset false alarms)'
    print(f"VERDICT {truth['set']}: {verdict}")
    sys.exit(0 if verdict == 'right' else 1)


if __name__ == '__main__':
    main()
