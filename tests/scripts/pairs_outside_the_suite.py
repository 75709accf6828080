"""The seven two-effect combinations the self-test's suite does not hold, one dataset each.

The suite's pairs are root + scale, rig + flare and pitch + root (``selftest.PAIRS``); this
draws the other seven of the library's ten the way the suite draws its pairs (each member from
the upper part of its range, redrawn until both move the stiffness by more than twice the
noise) and scores them with the self-test's own rows. Run from the repository:
``python tests/scripts/pairs_outside_the_suite.py OUT [SEED]`` (about 3 minutes a pair on one
core). Prints each row (named, parameter errors, ``unexplained``) and the pairs' summary.
"""
import itertools
import sys

import numpy as np

from canebench.canes.generate_hidden import random_strength
from canebench.discovery.selftest import PAIRS, run_selftest, summarize

out, seed = sys.argv[1], int(sys.argv[2]) if len(sys.argv) > 2 else 97
names = ("modulus_scale", "root_compliance", "rig_compliance", "base_flare", "probe_misalignment")
suite_pairs = {frozenset(p) for p in PAIRS}
rng = np.random.default_rng(seed)
cases = []
for i, (a, b) in enumerate(p for p in itertools.combinations(names, 2) if frozenset(p) not in suite_pairs):
    cases.append({"kind": "pair", "effects": {a: random_strength(a, rng, strong=True),
                                              b: random_strength(b, rng, strong=True)},
                  "id": f"{i:02d}-pair-{a}+{b}", "seed": seed * 1000 + i})
df = run_selftest(out, seed, workers=1, cases=cases)
cols = [c for c in ("id", "named", "partial", "unsupported", "unexplained", "size", "gap_before", "gap_after_cv")
        if c in df] + [c for c in df.columns if c.startswith("err_")]
print(df[cols].to_string(index=False, float_format=lambda v: f"{v:.3g}"))
s = summarize(df)
print({k: s[k] for k in ("pairs_both_named", "n_pairs", "pairs_resolvable_both_named", "n_pairs_resolvable",
                         "median_gap_shrink_out_of_sample")})
