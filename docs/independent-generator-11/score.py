"""Score a `canebench discover` output against an indep11 truth file.

    /work/venv/bin/python score.py truth/dsNN.json OUT_DIR      (reads OUT_DIR/discovery.json)
    /work/venv/bin/python score.py truth/dsNN.json path/to/discovery.json

Prints hidden vs named effects, parameter errors for the global parameters,
whether the unexplained flag is right, the gap, and (obstruction) onsets per
trial.  Exit code 0 if the naming and the unexplained flag are right, 1 if not.
Robust to extra keys and small variations in the contract (effect/name keys,
params nested or flat, trial ids as strings or dicts)."""
import json
import math
import os
import re
import sys

LIBRARY = ['modulus_scale', 'root_compliance', 'rig_compliance', 'base_flare', 'probe_misalignment', 'obstruction']
ALIASES = {'modulus': 'modulus_scale', 'e_scale': 'modulus_scale', 'root': 'root_compliance',
           'root_spring': 'root_compliance', 'rig': 'rig_compliance', 'flare': 'base_flare',
           'misalignment': 'probe_misalignment', 'probe_angle': 'probe_misalignment',
           'obstructions': 'obstruction', 'contact': 'obstruction'}


def norm_name(n):
    n = str(n).strip().lower().replace('-', '_').replace(' ', '_')
    return ALIASES.get(n, n)


def find_num(d, keys):
    """First numeric value under any of keys (searching nested dicts)."""
    if not isinstance(d, dict):
        return None
    for k in keys:
        if k in d:
            v = d[k]
            if isinstance(v, (int, float)) and not isinstance(v, bool):
                return float(v)
            if isinstance(v, dict):
                for kk in ('value', 'estimate', 'median', 'mean'):
                    if isinstance(v.get(kk), (int, float)):
                        return float(v[kk])
            if isinstance(v, (list, tuple)) and len(v) == 1 and isinstance(v[0], (int, float)):
                return float(v[0])
    for v in d.values():
        if isinstance(v, dict):
            r = find_num(v, keys)
            if r is not None:
                return r
    return None


def find_ci(entry, keys):
    ci = entry.get('ci95') or entry.get('ci') or {}
    if isinstance(ci, dict):
        for k in keys:
            v = ci.get(k)
            if isinstance(v, (list, tuple)) and len(v) == 2 and all(isinstance(x, (int, float)) for x in v):
                return float(v[0]), float(v[1])
    if isinstance(ci, (list, tuple)) and len(ci) == 2 and all(isinstance(x, (int, float)) for x in ci):
        return float(ci[0]), float(ci[1])
    return None


def trial_key(t):
    """(bush, cane, trial) from a tool trial record or id, else a normalized string."""
    if isinstance(t, dict):
        if all(k in t for k in ('bush', 'cane', 'trial')):
            try:
                return (int(t['bush']), int(t['cane']), int(t['trial']))
            except (TypeError, ValueError):
                pass
        for k in ('trial', 'id', 'file', 'name', 'trial_id'):
            if k in t and not isinstance(t[k], (dict, list)):
                return trial_key(t[k])
        return None
    s = str(t)
    base = os.path.splitext(os.path.basename(s))[0]
    ints = re.findall(r'\d+', s.replace('\\', '/'))
    if len(ints) >= 3:
        return tuple(int(x) for x in ints[-3:])
    return base.lower()


def fmt(v, nd=4):
    if v is None:
        return 'n/a'
    if isinstance(v, float):
        return f'{v:.{nd}g}'
    return str(v)


def main():
    if len(sys.argv) != 3:
        print(__doc__)
        sys.exit(2)
    truth = json.load(open(sys.argv[1]))
    p = sys.argv[2]
    if os.path.isdir(p):
        p = os.path.join(p, 'discovery.json')
    disc = json.load(open(p))
    ok_all = True

    print(f"== {truth['dataset']}  (truth {sys.argv[1]}, output {p})")
    print('-- hidden effects (truth)')
    for h in truth['hidden_effects']:
        sz = h['size']
        print(f"   {h['effect']:20s} in_library={h['in_library']!s:5s} scope={h.get('scope')}  size median|ln k_with/k_without| "
              f"all={fmt(sz['median_abs_log_ratio_all_trials'], 3)} affected={fmt(sz['median_abs_log_ratio_affected'], 3)} "
              f"(n={sz['n_trials']}, per-cane noise sd {sz['noise_reference_sd_ln_E']})")
        if h.get('note'):
            print(f"      note: {h['note']}")
    if not truth['hidden_effects']:
        print('   (none: null set; only per-cane modulus scatter and rig habits)')

    named_raw = disc.get('named') or disc.get('effects') or []
    if isinstance(named_raw, dict):
        named_raw = [dict(v, effect=k) if isinstance(v, dict) else {'effect': k} for k, v in named_raw.items()]
    named = []
    for n in named_raw:
        if isinstance(n, str):
            named.append({'effect': norm_name(n)})
        elif isinstance(n, dict):
            nm = n.get('effect') or n.get('name') or n.get('id')
            d = dict(n); d['effect'] = norm_name(nm)
            named.append(d)
    named_set = {n['effect'] for n in named}
    expected = set(truth['expected']['named'])
    print('-- naming')
    print(f"   expected named : {sorted(expected) or '[] (nothing)'}")
    print(f"   tool named     : {sorted(named_set) or '[] (nothing)'}  (baseline: {disc.get('baseline')})")
    tp = expected & named_set
    fn = expected - named_set
    fp = named_set - expected
    print(f"   correct: {sorted(tp)}  missed: {sorted(fn)}  wrongly named: {sorted(fp)}")
    naming_ok = not fn and not fp
    ok_all &= naming_ok

    unexp = disc.get('unexplained')
    if isinstance(unexp, dict):
        unexp = unexp.get('flag', unexp.get('value'))
    exp_unexp = truth['expected']['unexplained']
    flag_ok = bool(unexp) == bool(exp_unexp)
    print(f"-- unexplained: truth {exp_unexp}, tool {unexp} -> {'RIGHT' if flag_ok else 'WRONG'}")
    ok_all &= flag_ok

    # ---- parameters
    print('-- parameters (global ones scored; base_flare by name only)')
    by = {n['effect']: n for n in named}
    for h in truth['hidden_effects']:
        e = h['effect']
        if e not in by:
            continue
        entry = by[e]
        prm = entry.get('params', entry)
        if e == 'modulus_scale':
            t = h['params']['scale']
            g = find_num(prm, ['scale', 'modulus_scale', 'E_scale', 'factor'])
            ci = find_ci(entry, ['scale', 'modulus_scale'])
            if g:
                print(f"   modulus_scale scale: truth {t:.4f} tool {g:.4f}  ln error {math.log(g / t):+.3f}"
                      + (f"  ci95 [{ci[0]:.4g}, {ci[1]:.4g}] covers: {ci[0] <= t <= ci[1]}" if ci else ''))
            else:
                print('   modulus_scale: no scale parameter found')
        elif e == 'rig_compliance':
            t = h['params']['k_rig']
            g = find_num(prm, ['k_rig', 'k', 'stiffness', 'k_rig_N_per_m'])
            ci = find_ci(entry, ['k_rig', 'k'])
            if g:
                msg = f"   rig_compliance k_rig (N/m): truth {t:.4g} tool {g:.4g}  ln error {math.log(g / t):+.3f}"
                if ci:
                    msg += f"  ci95 [{ci[0]:.4g}, {ci[1]:.4g}] covers: {ci[0] <= t <= ci[1]}"
                if abs(math.log10(g / t)) > 2.5:
                    msg += '  (off by ~1000: unit N/mm vs N/m?)'
                print(msg)
            else:
                print('   rig_compliance: no k_rig parameter found')
        elif e == 'probe_misalignment':
            t = h['params']['angle_deg']
            g = find_num(prm, ['angle_deg', 'angle', 'pitch_deg', 'probe_angle_deg'])
            ci = find_ci(entry, ['angle_deg', 'angle'])
            if g is not None:
                print(f"   probe_misalignment angle_deg: truth {t:+.2f} tool {g:+.2f}  error {g - t:+.2f} deg, sign "
                      f"{'right' if (g > 0) == (t > 0) else 'WRONG'}"
                      + (f"  ci95 [{ci[0]:.3g}, {ci[1]:.3g}] covers: {ci[0] <= t <= ci[1]}" if ci else ''))
            else:
                print('   probe_misalignment: no angle parameter found')
        elif e == 'root_compliance':
            tb = h['params']['k_root_by_bush']; tc = h['params']['k_root_by_cane']
            gm = math.exp(sum(math.log(v) for v in tb.values()) / len(tb))
            print(f"   root_compliance truth k_root by bush (N m/rad): " + ', '.join(f'b{b}={v:.3g}' for b, v in tb.items())
                  + f"  (geometric mean {gm:.3g}); tool scope {entry.get('scope')}")
            g = find_num(prm, ['k_root', 'k'])
            per = None
            for key in ('per_cane', 'by_cane', 'k_root', 'values'):
                v = prm.get(key) if isinstance(prm, dict) else None
                if isinstance(v, dict) and any(str(k) in tc for k in v):
                    per = v
                    break
            if per is None and isinstance(prm, dict) and any(k in tc for k in prm):
                per = prm
            if per:
                errs = []
                for cid, v in per.items():
                    val = v if isinstance(v, (int, float)) else find_num(v, ['k_root', 'k', 'value'])
                    if cid in tc and val and val > 0:
                        errs.append(math.log(val / tc[cid]))
                if errs:
                    errs.sort()
                    med = errs[len(errs) // 2]
                    print(f"   per-cane ln(tool/truth): median {med:+.3f}, median |.| "
                          f"{sorted(abs(x) for x in errs)[len(errs) // 2]:.3f} over {len(errs)} canes")
            elif g:
                print(f"   tool global k_root {g:.4g}: ln error vs geometric mean {math.log(g / gm):+.3f} "
                      f"(truth varies by bush, so a single value cannot fit all)")
            else:
                print('   root_compliance: no k_root parameter found')
        elif e == 'base_flare':
            print('   base_flare: named (scored by name only)')
        elif e == 'obstruction':
            pass

    # ---- obstruction onsets
    tt = [t for t in truth['trials'] if t.get('obstruction_onset_mm') is not None]
    tool_tr = disc.get('trials') or []
    tool_on = {}
    for t in tool_tr:
        k = trial_key(t)
        if k is None:
            continue
        on = t.get('obstruction_onset_mm') if isinstance(t, dict) else None
        if on is None and isinstance(t, dict):
            on = t.get('onset_mm')
        tool_on[k] = on
    if tt or any(v is not None for v in tool_on.values()):
        print('-- obstruction onsets (mm of displacement after contact)')
        keys = {}
        for t in truth['trials']:
            keys[(t['bush'], t['cane'], t['trial'])] = t
        hits = miss = fa = 0
        errs = []
        for t in truth['trials']:
            k = (t['bush'], t['cane'], t['trial'])
            g = tool_on.get(k, tool_on.get(t['stem'].lower()))
            on = t.get('obstruction_onset_mm')
            if on is not None and g is not None:
                hits += 1; errs.append(g - on)
                print(f"   {t['id']:10s} truth {on:6.2f}  tool {g:6.2f}  error {g - on:+.2f}")
            elif on is not None:
                miss += 1
                print(f"   {t['id']:10s} truth {on:6.2f}  tool   none  MISSED")
            elif g is not None:
                fa += 1
                print(f"   {t['id']:10s} truth   none  tool {g:6.2f}  FALSE ALARM")
        n_known = sum(1 for t in truth['trials'] if (t['bush'], t['cane'], t['trial']) in tool_on or t['stem'].lower() in tool_on)
        ae = sorted(abs(x) for x in errs)
        print(f"   detected {hits}/{len(tt)}, missed {miss}, false alarms {fa}; tool reported {n_known}/{len(truth['trials'])} trials; "
              f"median |onset error| {fmt(ae[len(ae) // 2] if ae else None, 3)} mm")

    # ---- gap
    gap = disc.get('gap') or {}
    def gv(x):
        if isinstance(x, dict):
            return x.get('median_abs_log_ratio')
        return x
    print(f"-- gap median|ln(sim/meas)|: before {fmt(gv(gap.get('before')), 3)}  after_cv {fmt(gv(gap.get('after_cv') or gap.get('after')), 3)}"
          f"   (truth: combined hidden-effect size {fmt(truth.get('combined_size_median_abs_log_ratio'), 3)}, per-cane modulus sd 0.15)")
    print(f"== VERDICT {truth['dataset']}: naming {'RIGHT' if naming_ok else 'WRONG'}, unexplained flag {'RIGHT' if flag_ok else 'WRONG'}")
    sys.exit(0 if ok_all else 1)


if __name__ == '__main__':
    main()
