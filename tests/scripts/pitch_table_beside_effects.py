"""How well the pitch table, measured on the baseline model, serves beside other effects.

Run from the repository: ``python tests/scripts/pitch_table_beside_effects.py`` (about 30 s;
serial beam runs on 12 bundled trials). Prints the largest |engine - screen| in ln k at +30 deg.
"""
import numpy as np, pandas as pd
from canebench.data.dataset import bundled_dataset, load_dataset
from canebench.discovery.screen import trial_geometry
from canebench.discovery.screenset import Anchored, ScreenSet
from canebench.discovery.engine_runs import BaselineEngine, ok_log_k, pitch_table
from canebench.discovery.workflow import BASELINES
from canebench.execute.runner import run_trials
from canebench.execute.executors import SerialExecutor
from canebench.model.effects import EffectSpec
from canebench.model.presets import PRESETS
from canebench.probe.protocol import PROTOCOLS
EX = SerialExecutor()
trials = load_dataset(bundled_dataset(), "b1c*,b2c1")
backend, preset, _ = BASELINES["beam"]; cfg0 = PRESETS[preset]; proto = PROTOCOLS["fast"]
F = pd.DataFrame({"trial": [t.id for t in trials]})
eng = lambda specs: ok_log_k(run_trials(trials, [backend], proto, cfg0.replace(effects=specs), None, executor=EX).to_df(), backend, F.trial)
lkb = eng(())
ss = ScreenSet.build([trial_geometry(t, cfg0) for t in trials])
ss_t = pitch_table(BaselineEngine(trials, F, backend, proto, cfg0, (), None, EX, None), Anchored(ss, lkb))[0].screen
pitch = EffectSpec("probe_misalignment", (("angle_deg", 30.0),))
for other in ("modulus_scale(scale=1.7)", "root_compliance(k_root=8)"):
    o = EffectSpec.parse(other)
    lka = eng((o,)); truth = eng((o, pitch))
    for name, s in (("no table", ss), ("table", ss_t)):
        sa = s.anchored((o,))
        print(f"anchored at {other}, +30 deg, {name}: max |engine - screen| {np.max(np.abs(truth - Anchored(sa, lka).predict((o, pitch)))):.3f}")
    for name, s in (("no table", ss), ("table", ss_t)):
        print(f"  from the baseline anchor, {other} + 30 deg, {name}: {np.max(np.abs(truth - Anchored(s, lkb).predict((o, pitch)))):.3f}")
