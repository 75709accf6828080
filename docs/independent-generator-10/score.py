"""Score a discovery run against an indep10 truth file.

    /work/venv/bin/python score.py truth/dsNN.json OUT_DIR

Reads OUT_DIR/discovery.json (robust to missing keys) and prints hidden vs
named effects, scope, global params / ci95 vs the truth, per-cane `local`
values vs the truth's per-cane values, `unexplained` and `gap`.
"""
import json
import math
import os
import sys

import numpy as np

PARAM = {"root_compliance": "k_root", "rig_compliance": "k_rig", "modulus_scale": "scale",
         "probe_misalignment": "angle_deg", "base_flare": "excess_mm"}


def num(v):
    try:
        v = float(v)
        return v if math.isfinite(v) else None
    except (TypeError, ValueError):
        return None


def interval(ci, key):
    """ci95 may be {key: [lo, hi]}, {key: {lo:, hi:}}, [lo, hi] or {lo:, hi:}."""
    if ci is None:
        return None
    c = ci.get(key, ci) if isinstance(ci, dict) else ci
    if isinstance(c, dict):
        lo = c.get("lo", c.get("low", c.get("lower", c.get("0"))))
        hi = c.get("hi", c.get("high", c.get("upper", c.get("1"))))
    elif isinstance(c, (list, tuple)) and len(c) == 2:
        lo, hi = c
    else:
        return None
    lo, hi = num(lo), num(hi)
    if lo is None and hi is None:
        return None
    return (lo if lo is not None else -math.inf, hi if hi is not None else math.inf)


def local_value(v, key):
    if isinstance(v, dict):
        x = v.get(key)
        if x is None and len(v) == 1:
            x = next(iter(v.values()))
        return num(x)
    return num(v)


def corr_stats(pairs, log=True):
    pairs = [(a, b) for a, b in pairs if a is not None and b is not None and (not log or (a > 0 and b > 0))]
    if len(pairs) < 2:
        return dict(n=len(pairs))
    t = np.array([p[0] for p in pairs])
    e = np.array([p[1] for p in pairs])
    if log:
        t, e = np.log(t), np.log(e)
    r = float(np.corrcoef(t, e)[0, 1]) if np.std(t) > 0 and np.std(e) > 0 else float("nan")
    out = dict(n=len(pairs), pearson_r=r)
    if log:
        out.update(rms_ln_ratio=float(np.sqrt(np.mean((e - t) ** 2))),
                   median_ln_ratio=float(np.median(e - t)))
    else:
        out.update(rms_diff=float(np.sqrt(np.mean((e - t) ** 2))))
    return out


def fmtd(d):
    return "{" + ", ".join(f"{k}: {v:.4g}" if isinstance(v, float) else f"{k}: {v}"
                           for k, v in d.items()) + "}"


def main(truth_path, out_dir):
    truth = json.load(open(truth_path))
    p = out_dir if out_dir.endswith(".json") else os.path.join(out_dir, "discovery.json")
    if not os.path.exists(p):
        print(f"no discovery.json at {p}")
        return 2
    disc = json.load(open(p))
    hidden = truth.get("hidden_effects", [])
    exp = truth.get("expected", {})
    named = disc.get("named") or []
    named = [n for n in named if isinstance(n, dict)]
    print(f"dataset {truth.get('dataset')}  (truth size: median |ln k_with/k_without| = "
          f"{truth.get('size', {}).get('median_abs_log_k_with_over_without', float('nan')):.3f})")
    print("hidden : " + (", ".join(
        f"{h['effect']}[{'per_cane' if h.get('varies_per_cane') else 'global'}"
        f"{'' if h.get('in_library', True) else ', NOT in library'}] {fmtd(h.get('global_value', {}))}"
        for h in hidden) or "none"))
    print("named  : " + (", ".join(f"{n.get('effect')}[{n.get('scope', '?')}] {fmtd(n.get('params') or {})}"
                                   for n in named) or "none"))
    hid_names = {h["effect"] for h in hidden if h.get("in_library", True)}
    nam_names = [n.get("effect") for n in named]
    tp = sorted(hid_names & set(nam_names))
    print(f"found  : {tp or '-'}   missed: {sorted(hid_names - set(nam_names)) or '-'}   "
          f"extra: {sorted(set(nam_names) - hid_names) or '-'}")

    for h in hidden:
        eff = h["effect"]
        if not h.get("in_library", True):
            continue
        key = h.get("param") or PARAM.get(eff)
        for n in [n for n in named if n.get("effect") == eff]:
            scope = n.get("scope", "?")
            want = "per_cane" if h.get("varies_per_cane") else "global"
            print(f"\n[{eff}] scope {scope} (truth varies: {h.get('varies_by')}; expected {want}) "
                  f"-> {'OK' if scope == want else 'MISMATCH'}")
            tv = num(h.get("global_value", {}).get(key))
            ev = num((n.get("params") or {}).get(key))
            ci = interval(n.get("ci95"), key)
            if tv is not None and ev is not None:
                rel = (ev - tv) / tv
                cov = "n/a" if ci is None else ("covers" if ci[0] <= tv <= ci[1] else "MISSES")
                cis = "none" if ci is None else f"[{ci[0]:.4g}, {ci[1]:.4g}]"
                print(f"  global {key}: named {ev:.4g} vs truth {tv:.4g}  rel.err {100*rel:+.1f} %"
                      f"  (ln ratio {math.log(ev/tv) if ev > 0 and tv > 0 else float('nan'):+.3f})"
                      f"  ci95 {cis} {cov}")
                if eff == "modulus_scale" and h.get("realized_geomean_scale"):
                    g = h["realized_geomean_scale"]
                    print(f"  (realised geometric-mean E_true/E_stated over canes {g:.4g}: "
                          f"rel.err {100*(ev-g)/g:+.1f} %)")
                if eff == "base_flare" and h.get("global_value_geomean"):
                    g = h["global_value_geomean"][key]
                    print(f"  (geometric mean of per-cane excess {g:.4g} mm)")
            else:
                print(f"  global {key}: named {ev} truth {tv} (cannot compare)")
            loc = n.get("local")
            tpc = h.get("per_cane") or {}
            if isinstance(loc, dict) and loc:
                pairs = [(num(tpc.get(c, {}).get(key)), local_value(v, key)) for c, v in loc.items()]
                st = corr_stats(pairs, log=True)
                print(f"  local {key} vs truth per cane (ln): {fmtd(st)}  "
                      f"[{len(loc)} local, {len(tpc)} truth canes]")
                if eff == "base_flare":
                    pairs = [(num(tpc.get(c, {}).get("excess_vs_caliper_line_mm")), local_value(v, key))
                             for c, v in loc.items()]
                    print(f"  local {key} vs truth excess over the caliper line (raw mm): "
                          f"{fmtd(corr_stats(pairs, log=False))}")
                for c in sorted(set(loc) | set(tpc)):
                    tvc = num(tpc.get(c, {}).get(key))
                    evc = local_value(loc.get(c), key) if c in loc else None
                    print(f"    {c:6s} truth {tvc if tvc is None else f'{tvc:9.4g}'}  "
                          f"named {evc if evc is None else f'{evc:9.4g}'}")
            elif h.get("varies_per_cane"):
                print("  no `local` values given")
            if n.get("per_cane_test") is not None:
                print(f"  per_cane_test: {json.dumps(n.get('per_cane_test'))[:300]}")
    for n in named:
        if n.get("effect") not in hid_names:
            print(f"\n[{n.get('effect')}] NOT hidden: scope {n.get('scope')} params {n.get('params')} "
                  f"ci95 {n.get('ci95')}")
            if n.get("per_cane_test") is not None:
                print(f"  per_cane_test: {json.dumps(n.get('per_cane_test'))[:300]}")

    u = disc.get("unexplained")
    eu = exp.get("unexplained")
    print(f"\nunexplained: {u}  (expected {eu}) -> {'OK' if u == eu else 'MISMATCH'}")
    gap = disc.get("gap") or {}
    for k in ("before", "after_cv"):
        g = gap.get(k) or {}
        print(f"gap {k:8s}: median_abs_log_ratio {g.get('median_abs_log_ratio')}  "
              f"worst_abs_log_ratio {g.get('worst_abs_log_ratio')}")
    if "baseline" in disc:
        print(f"baseline: {json.dumps(disc['baseline'])[:200]}")
    return 0


if __name__ == "__main__":
    if len(sys.argv) != 3:
        print(__doc__)
        sys.exit(2)
    sys.exit(main(sys.argv[1], sys.argv[2]))
