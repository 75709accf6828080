"""Which stored discovery results went through three verdict paths, and would change with them.

For every ``discovery.json`` under the folders given (a self-test run's case folders, or one
``canebench discover`` output per folder), prints a line when any of these holds:

* ``taker``: a trend along the canes was taken by an unnamed effect (``adequacy.within_taken_by``);
  since ``verdict.WITHIN_TAKERS`` only a flare may take it;
* ``dropped_with``: an effect left the model beside its pair partner whose interval reached no
  effect (``unsupported[].dropped_with``); since ``selection.entry_groups`` a partner that passed
  alone stays (the step's rows in ``selection`` say whether it did);
* ``curvature``: the structure table's trace-curvature row, recomputed from ``discovery.csv``
  (held-out residual, within canes) with its permutation null alone, falls below the table's
  bar (p x 12 < 0.01; the geometry null can only raise p); since ``structure.NOT_JUDGED`` it
  no longer flags. Printed beside whether another check flagged the set anyway.

Run: ``python tests/scripts/verdict_paths.py DIR [DIR ...]`` (a few seconds per 40 sets).
"""
import json
import os
import sys

import numpy as np
import pandas as pd

from canebench.discovery.structure import structure_tests
from canebench.discovery.verdict import STRUCTURE_ALPHA, TREND_WARNING_ALPHA
from compare_discoveries import discovery_files  # beside this script


def main() -> None:
    for root in sys.argv[1:]:
        files = discovery_files(root)
        hits = 0
        for f in files:
            j = json.load(open(f))
            name = os.path.relpath(os.path.dirname(f), os.path.dirname(root.rstrip("/")))
            a = j.get("adequacy", {})
            out = []
            tk = a.get("within_taken_by")
            if tk:
                out.append(f"taker {tk['effect']}")
            for u in j.get("unsupported", []):
                if "dropped_with" in u:
                    alone = [s for s in j.get("selection", []) if s.get("candidate") == u["effect"] and s.get("passed")]
                    out.append(f"dropped_with: {u['effect']} beside {u['dropped_with']}"
                               + (f" (passed alone at step {', '.join(str(s['step']) for s in alone)})" if alone
                                  else " (failed alone)"))
            csv = os.path.join(os.path.dirname(f), "discovery.csv")
            if os.path.exists(csv):
                d = pd.read_csv(csv)
                if {"r_after_cv", "curvature", "cane"} <= set(d.columns):
                    d = d[np.isfinite(d.r_after_cv)]
                    s = structure_tests(d, "r_after_cv", features=["curvature"], seed=0)
                    if len(s) and float(s.p.iloc[0]) * 12 < STRUCTURE_ALPHA:
                        other = (bool(a.get("inadequate")) or bool(tk) or bool(j.get("unsupported"))
                                 or a.get("after_cv_permutation", {}).get("p", 1.0) < TREND_WARNING_ALPHA)
                        out.append(f"curvature r {s.r.iloc[0]:+.2f}, permutation p x 12 = {12 * s.p.iloc[0]:.3f}; "
                                   f"another check flags it: {other}")
            if out:
                hits += 1
                print(f"{name}: named {[n['effect'] for n in j['named']]}, unexplained {j['unexplained']}; "
                      + "; ".join(out))
        print(f"{root}: {len(files)} results, {hits} through these paths")


if __name__ == "__main__":
    main()
