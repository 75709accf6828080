"""How closely can the library mimic a hidden effect it does not have, with no noise at all?

Takes a generated dataset whose truth records each trial's ``support_multiplier`` (k with the
hidden effect / k without it, from the generator's own solver), and fits library candidates to
its logarithm through the workflow's own screen (``Anchored`` at 0, so the screen predicts the
change in ln k an effect makes; the same likelihood as the selection, with its per-cane random
level and the calipers' penalty on a flare). What is left is split into cane means (between
canes) and deviations from them (within canes), and the cane means are printed beside the
canes' features.

What is left between canes is indistinguishable from each cane's own modulus unless it follows
a feature; within canes it competes with trial noise. Compare the figures with the generator's
per-cane modulus scatter (printed) and the named model's held-out gap.

Run: ``python tests/scripts/support_noiseless_fit.py DATASET`` (a self-test set folder holding
``truth/truth.json``, e.g. ``OUT/38-out_of_library-lateral_support``; a few seconds).
"""
import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd

from canebench.data.dataset import load_dataset
from canebench.discovery.fit import Candidate, fit_candidate
from canebench.discovery.screen import trial_geometry
from canebench.discovery.screenset import Anchored, ScreenSet
from canebench.model.config import ModelConfig

CANDIDATES = [("modulus_scale",), ("root_compliance",), ("rig_compliance",), ("base_flare",),
              ("root_compliance", "base_flare"), ("modulus_scale", "base_flare"),
              ("modulus_scale", "root_compliance"), ("rig_compliance", "base_flare")]

data = Path(sys.argv[1])
truth = json.loads((data / "truth" / "truth.json").read_text())
trials = load_dataset(data)
y = np.log([truth["canes"][t.cane.id]["trials"][str(t.trial_no)]["support_multiplier"] for t in trials])
moduli = np.array([c["modulus_pa"] for c in truth["canes"].values()])
print(f"hidden: {truth['effects']}")
print(f"its change in ln k: median {np.median(y):.3f}, range [{y.min():.3f}, {y.max():.3f}]; "
      f"the generator's per-cane modulus scatter: sd {np.log(moduli / truth['stated_modulus_pa']).std():.3f} in ln")
at = Anchored(ScreenSet.build([trial_geometry(t, ModelConfig()) for t in trials]), np.zeros(len(trials)))
canes = at.screen.canes
fits = {}
for names in CANDIDATES:
    f = fit_candidate(Candidate.of(names), at, y)
    r = y - at.predict(f.specs)
    cm = pd.Series(r).groupby(canes).transform("mean").to_numpy()
    fits[names] = r
    params = "; ".join(f"{s.name} " + ", ".join(f"{k} {v:.4g}" for k, v in s.params) for s in f.specs)
    print(f"{' + '.join(names):38s} left: rms {np.sqrt(np.mean(r ** 2)):.3f}, between canes "
          f"{np.sqrt(np.mean(cm ** 2)):.3f}, within {np.sqrt(np.mean((r - cm) ** 2)):.3f}  ({params})")
best = min(fits, key=lambda k: float(np.mean(fits[k] ** 2)))
r = fits[best]
df = pd.DataFrame({"cane": canes, "left": r, "effect": y, "diameter_mm": [t.diameter_mm for t in trials],
                   "height_mm": [t.height_mm for t in trials]})
cm = df.groupby("cane").mean()
print(f"\nwhat the best fit ({' + '.join(best)}) leaves, per cane (means over its pushes):")
print(cm.round(3).to_string())
for c in ("effect", "diameter_mm", "height_mm"):
    print(f"between-cane r of what is left with {c}: {np.corrcoef(cm.left, cm[c])[0, 1]:+.2f}")
