"""Self-test of score.py with hand-made discovery.json files (a perfect answer and
a wrong one per set, plus a few tolerance cases).  Writes under _selftest_*/ here."""
import copy
import json
import os
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
PY = sys.executable
tmp = tempfile.mkdtemp(prefix='_selftest_', dir=HERE)


def run(ds, disc, tag):
    d = os.path.join(tmp, '%s_%s' % (ds, tag))
    os.makedirs(d, exist_ok=True)
    json.dump(disc, open(os.path.join(d, 'discovery.json'), 'w'))
    return subprocess.run([PY, os.path.join(HERE, 'score.py'), os.path.join(HERE, 'truth', ds + '.json'), d],
                          capture_output=True, text=True).returncode


fails = 0
for n in range(1, 13):
    ds = 'ds%02d' % n
    t = json.load(open(os.path.join(HERE, 'truth', ds + '.json')))
    named = [dict(effect=e['effect'], scope=e['scope'], params=e['params']) for e in t['expected']['named']]
    trials = [dict(trial=k, obstruction_onset_mm=None if v is None else v + 1.0)
              for k, v in t['obstruction_onsets_mm'].items()]
    good = dict(baseline={}, named=named, unexplained=t['expected']['unexplained'], gap={}, trials=trials)
    bad = copy.deepcopy(good)
    if not any(e['effect'] == 'modulus_scale' for e in named):
        bad['named'].append(dict(effect='modulus_scale', scope='global', params=dict(scale=0.8)))
    else:
        bad['unexplained'] = not bad['unexplained']
    rg, rb = run(ds, good, 'good'), run(ds, bad, 'bad')
    ok = rg == 0 and rb == 1
    fails += not ok
    print('%s perfect answer -> %d, wrong answer -> %d  %s' % (ds, rg, rb, 'ok' if ok else 'FAIL'))

cases = [
    ('ds02', dict(named=[dict(effect='modulus_scale', scope='global', params=dict(scale=0.66))],
                  unexplained=False, trials=[]), 0),       # |ln| 0.129 within 0.15
    ('ds02', dict(named=[dict(effect='modulus_scale', scope='global', params=dict(scale=0.70))],
                  unexplained=False, trials=[]), 1),       # |ln| 0.188
    ('ds06', dict(named=[dict(effect='probe_misalignment', scope='global', params=dict(angle_deg=26.5))],
                  unexplained=False, trials=[]), 0),
    ('ds06', dict(named=[dict(effect='probe_misalignment', scope='global', params=dict(angle_deg=25.0))],
                  unexplained=False, trials=[]), 1),
    ('ds03', dict(named=[dict(effect='root_compliance', scope='global', params=dict(k_root=60.0))],
                  unexplained=False, trials=[]), 0),       # single value vs truth median
]
for ds, disc, want in cases:
    r = run(ds, disc, 'case%d' % len(disc['named']))
    fails += r != want
    print('%s %s -> %d (want %d)' % (ds, disc['named'][0]['params'], r, want))
t = json.load(open(os.path.join(HERE, 'truth', 'ds07.json')))
late = dict(named=[dict(effect='obstruction', scope='per_trial', params={})], unexplained=False,
            trials=[dict(trial=k, obstruction_onset_mm=None if v is None else v + 4.0)
                    for k, v in t['obstruction_onsets_mm'].items()])
r = run('ds07', late, 'late')
fails += r != 1
print('ds07 onsets 4 mm late -> %d (want 1)' % r)
print('score.py self-test: %s (outputs in %s)' % ('PASS' if not fails else '%d FAIL' % fails, tmp))
sys.exit(1 if fails else 0)
