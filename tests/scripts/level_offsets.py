"""How far each self-test set's mean residual sits from what its canes' moduli and hidden effect
give: mean r_before (``discovery.csv``) minus the canes' mean ln(E / E_stated) and the truth's
median |d ln k| (``truth/truth.json``). On the nulls this is the level offset a dataset carries
by chance (the caliper line's error, extrapolated to the base, does not average out over 18 canes).

Run from the repository: ``python tests/scripts/level_offsets.py DIR [DIR ...]`` (a self-test's
``--out``, or any folder of datasets with a truth and a discovery output beside it).
"""
import json
import math
import sys
from pathlib import Path

import numpy as np
import pandas as pd

for root in sys.argv[1:]:
    for truth_path in sorted(Path(root).rglob("truth/truth.json")):
        case = truth_path.parent.parent
        csv = next((p for p in (case / "discovery.csv", case / "out" / "discovery.csv") if p.exists()), None)
        if csv is None:
            continue
        t = json.loads(truth_path.read_text())
        if "modulus_scale" in t["effects"]:
            continue  # its scale is in the canes' moduli and in the effect alike
        e = float(np.mean([math.log(c["modulus_pa"] / t["stated_modulus_pa"]) for c in t["canes"].values()]))
        eff = float(np.median([math.log(tr["k_effect_n_per_mm"] / tr["k_plain_n_per_mm"])
                               for c in t["canes"].values() for tr in c["trials"].values()]))
        r = pd.read_csv(csv).r_before.mean()
        print(f"{case.name:45s} {'+'.join(t['effects']) or 'none':20s} moduli {e:+.3f} effect {eff:+.3f} "
              f"mean r_before {r:+.3f} offset {r - e - eff:+.3f}")
