"""Score stored per-cane self-test sets again with the current ``_per_cane_scores``.

``python tests/scripts/per_cane_rescore.py DIR [DIR ...]``

Each DIR is a ``canebench discover --selftest --out`` folder (a full run or a ``--selftest-cases``
one). Every case folder of kind ``per_cane`` in it (``4*-per_cane-*``) is scored from its stored
``discovery.json`` and ``truth/truth.json``, without running discovery again: a score added after
the run (e.g. ``per_cane_ln_sd_ratio``, the fitted spread between canes over the drawn roots') can
be read from runs already made. Prints one line per set and the median and range of each score.
"""
import json
import sys
from pathlib import Path

import numpy as np

from canebench.discovery.selftest import _per_cane_scores

KEYS = ("per_cane_p", "per_cane_r", "per_cane_rms_ln", "per_cane_err_k_root", "per_cane_ln_sd_ratio",
        "per_cane_ln_median_z", "per_cane_ln_sd_z")
scores = {k: [] for k in KEYS}
for root in sys.argv[1:]:
    for case in sorted(p for p in Path(root).glob("*-per_cane-*") if p.is_dir()):
        doc = json.loads((case / "discovery.json").read_text())
        truth = json.loads((case / "truth" / "truth.json").read_text())
        entry = next((n for n in doc["named"] if n["effect"] == "root_compliance"), None)
        sc = _per_cane_scores(entry, truth)
        print(f"{root}/{case.name}: found per cane {sc['per_cane_found']}; "
              + ", ".join(f"{k} {sc[k]:.3g}" for k in KEYS if k in sc))
        for k in KEYS:
            if k in sc and np.isfinite(sc[k]):
                scores[k].append(sc[k])
for k, v in scores.items():
    if v:
        print(f"{k}: median {np.median(v):.3g}, range {min(v):.3g} to {max(v):.3g} over {len(v)} sets")
