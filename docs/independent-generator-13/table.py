"""Print the README's set table from truth/*.json."""
import glob, json
import numpy as np
print('| set | hidden effect | trials (bushes x canes x 3) | size: median abs ln(k_with/k_without) | between-cane noise (SD ln k) | size / noise | apparent ln(k_with/k_files) | expected names | unexplained |')
print('|---|---|---|---|---|---|---|---|---|')
for f in sorted(glob.glob('truth/ds*.json')):
    t = json.load(open(f))
    c = t['config']
    names = ', '.join('%s (%s%s)' % (e['effect'], e['scope'],
                                    ''.join(', %s=%s' % (k, v) for k, v in e['params'].items() if not isinstance(v, dict))
                                    + (', k_root per cane, median %.0f' % e['params_median']['k_root'] if 'params_median' in e else ''))
                      for e in t['expected']['named']) or '(none)'
    sz = t['size_median_abs_ln_k']
    by = t['size_by_effect']
    extra = ''
    if by:
        extra = ' (' + ', '.join('%s %.2f' % (k, v) for k, v in by.items()) + ')'
    nob = sum(v is not None for v in t['obstruction_onsets_mm'].values())
    desc = t['description']
    if nob:
        desc += ' [%d of %d trials obstructed]' % (nob, t['n_trials'])
    nr = sum(1 for cc in t['canes'].values() if cc['rub'])
    if nr:
        desc += ' [%d of %d canes rub]' % (nr, t['n_canes'])
    noise = t['between_cane_noise_sd_ln_k']
    print('| %s | %s | %d (%d x %d x 3) | %.2f%s | %.2f | %s | %+.2f | %s | %s |' % (
        t['set'], desc, t['n_trials'], c['n_bush'], c['n_cane'], sz, extra, noise,
        '%.1f' % (sz / noise) if sz else '-', t['apparent_median_ln_k_with_over_view'], names,
        'true' if t['expected']['unexplained'] else 'false'))
