"""The shape check on the real field trials with a probe pitch set by hand beside the fitted flare.

Run from the repository: ``python tests/scripts/shape_check_real_pitch.py [FIELD_DIR]`` (default
``../shared/field-data``; about a minute of serial beam runs). The flare is the one
``canebench discover`` named on the real trials until 208bf78, which scores b5c2t3 up to its
elbow and names nothing global since (docs/discovery.md); trials with an obstruction onset are
left out here. Prints the check's p and beta per pitch, and how the
traces' stiffening relative to the beam trends with the push's length.
"""
import sys

import numpy as np

from canebench.data.dataset import load_dataset
from canebench.discovery.shape import shape_check, trace_shapes
from canebench.discovery.contacts import field_onsets
from canebench.execute.executors import SerialExecutor
from canebench.execute.pipeline import field_stage
from canebench.execute.runner import run_trials
from canebench.model.effects import EffectSpec
from canebench.model.presets import PRESETS
from canebench.probe.protocol import PROTOCOLS

field = sys.argv[1] if len(sys.argv) > 1 else "../shared/field-data"
trials = load_dataset(field)
fields = field_stage(trials, PROTOCOLS["fast"].fit_window_mm)
onsets = field_onsets(fields)
trials = [t for t in trials if fields[t.id].fit is not None and fields[t.id].fit.usable and t.id not in onsets]
cfg0, proto, ex = PRESETS["beam-consistent"], PROTOCOLS["fast"], SerialExecutor()
flare = EffectSpec.parse("base_flare(excess_mm=13.13, length_mm=141.5)")
base = run_trials(trials, ["beam"], proto, cfg0, None, executor=ex)
cane_of = {t.id: t.cane.id for t in trials}
for pitch in (10.0, 20.0, -20.0):
    eff = (flare, EffectSpec("probe_misalignment", (("angle_deg", pitch),)))
    mod = run_trials(trials, ["beam"], proto, cfg0.replace(effects=eff), None, executor=ex)
    sh = trace_shapes([t.id for t in trials], base.traces, base.traces, mod.traces, "beam").dropna()
    r = shape_check(sh.trial.map(cane_of).to_numpy(), sh)
    u = sh.kappa_field - sh.kappa_base
    print(f"flare + pitch {pitch:+.0f} deg: p = {r['p']:.3g}, beta = {r['beta']:.2f}, predicted mean change "
          f"{r['predicted_mean']:+.3f} (spread {r['predicted_spread']:.3f}) on {r['n_trials']} trials; the traces' "
          f"stiffening relative to the beam changes by {10 * np.polyfit(sh.window_mm, u, 1)[0]:+.3f} per 10 mm of push")
