"""Do a weak pitch's cane resamples split between signs? Hidden pitches of +-12, +-15 and
+-18 degrees (the generator's own probe, seeds 9600-9605), each through ``discover`` with 100
resamples; prints what was named or refused and the pitch's 95 % interval.

Run from the repository: ``python tests/scripts/weak_pitch_intervals.py OUT [ANGLE ...]``
(about 2 minutes a set on one core; the named angles only, each with its own seed as in the
full run). The interval rule refuses a pitch whose percentile interval reaches 0; a pitch
whose resamples split between +a and -a would be refused with no resample near 0.
"""
import sys
from pathlib import Path

from canebench.canes.generate_hidden import generate_hidden
from canebench.data.dataset import load_dataset
from canebench.discovery.checks_text import fitted_entry
from canebench.discovery.selftest import _effect_size
from canebench.discovery.workflow import discover
from canebench.execute.executors import make_executor

out = Path(sys.argv[1])
ANGLES = (12.0, -12.0, 15.0, -15.0, 18.0, -18.0)
only = {float(a) for a in sys.argv[2:]}
if only - set(ANGLES):
    sys.exit(f"no set at {sorted(only - set(ANGLES))} deg; the sets are at {ANGLES}")
for i, angle in enumerate(ANGLES):
    if only and angle not in only:
        continue
    d = generate_hidden(out / f"pitch{angle:+.0f}", 9600 + i, {"probe_misalignment": {"angle_deg": angle}})
    res = discover(load_dataset(d), confirm=False, executor=make_executor("serial", 1, None), n_boot=100,
                   out=out / f"pitch{angle:+.0f}" / "out")
    print(f"hidden {angle:+.0f} deg (median |d ln k| {_effect_size(d):.3f}): "
          f"named {[(n['effect'], n['params'], n.get('ci95')) for n in res.named if fitted_entry(n)]}; "
          f"refused {[(u['effect'], u['params'], u['ci95']) for u in res.unsupported]}; "
          f"unexplained {res.unexplained}", flush=True)
