"""table.py: the set table from truth/*.json"""
import glob, json
print("| set | hidden effect (truth) | trials (bushes x canes x pushes) | size | noise | size/noise | apparent | expected named | expected unexplained |")
print("|---|---|---|---|---|---|---|---|---|")
for f in sorted(glob.glob('truth/ds*.json')):
    t = json.load(open(f))
    desc = []
    for h in t['hidden_effects']:
        p = h.get('params', {})
        if h['effect'] == 'modulus_scale': desc.append(f"modulus_scale {p['scale']} global (realised geomean {h['realised_geomean']:.2f})")
        elif h['effect'] == 'root_compliance':
            pc = list(h['per_cane'].values())
            desc.append(f"root_compliance per plant {list(p['k_root_by_bush'].values())} N m/rad x exp(N(0,0.08)) per cane; geomean {p['k_root_geomean']:.0f}")
        elif h['effect'] == 'rig_compliance': desc.append(f"rig_compliance k_rig {p['k_rig']} N/m")
        elif h['effect'] == 'probe_misalignment': desc.append(f"probe_misalignment +{p['angle_deg']} deg (up)")
        elif h['effect'] == 'base_flare':
            D = [v['D_mm'] for v in h['per_cane'].values()]; l = [v['ell_m'] for v in h['per_cane'].values()]
            desc.append(f"base_flare d + D(1-s/ell)^2, D {min(D):.0f}-{max(D):.0f} mm, ell {min(l):.2f}-{max(l):.2f} m")
        elif h['effect'] == 'obstruction': desc.append(f"obstruction in {h['n_trials']} trials")
        else: desc.append(h['effect'])
    if not desc: desc = ['none (null)']
    sizes = f"{t['size']:.2f}"
    if 'size_rig_only' in t and 'size_obstruction_only_obstructed_trials' in t:
        sizes += f" (rig {t['size_rig_only']:.2f}; obstruction {t['size_obstruction_only_obstructed_trials']:.2f} on obstructed)"
    if 'size_flare_only' in t:
        sizes += f" (scale {t['size_scale_only']:.2f}, flare {t['size_flare_only']:.2f})"
    if t['kind'] == 'obstruction': sizes += " (obstructed trials)"
    if t['kind'] == 'ool_play': sizes += f"; shape rms {t['shape_rms_gf_median']:.1f} gf vs noise {t['noise_gf_median']:.1f}"
    so = '-' if t['size'] == 0 else f"{t['size']/t['noise']:.1f}"
    nb = len({c['id'].split('c')[0] for c in t['canes']})
    print(f"| {t['set']} | {'; '.join(desc)} | {t['n_trials']} ({nb} x {t['n_canes']//nb} x {t['n_trials']//t['n_canes']}) | {sizes} | {t['noise']:.2f} | {so} | {t['apparent']:+.2f} | {t['expected']['named'] or '[]'} | {t['expected']['unexplained']} |")
