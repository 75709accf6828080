"""Summarize a full self-test run together with a ``--selftest-cases`` run of other sets.

``python tests/scripts/selftest_merged_summary.py FULL SUBSET``

FULL is a ``canebench discover --selftest --out`` folder (its ``selftest.csv``), SUBSET one written
with ``--selftest-cases`` (its ``selftest_subset.csv``), for sets FULL does not hold: e.g. a run of
sets 00-39 and a later run of the per-cane sets 40-41. Prints the done-when block of the merged rows,
whether it equals FULL's own, the summary keys that the added rows change, and the per-cane keys.
"""
import sys

import pandas as pd

from canebench.discovery.selftest import summarize

full = pd.read_csv(f"{sys.argv[1]}/selftest.csv")
subset = pd.read_csv(f"{sys.argv[2]}/selftest_subset.csv")
both = set(full.id) & set(subset.id)
if both:
    sys.exit(f"sets in both runs: {sorted(both)}")
old = summarize(full)
new = summarize(pd.concat([full, subset], ignore_index=True))
print(f"{len(full)} + {len(subset)} rows")
for c in new["done_when"]:
    print(f"  {c['met']!s:5s} {c['criterion']}: {c['measured']}")
print("done-when equal to the full run's alone:", new["done_when"] == old["done_when"])
print("summary keys the added rows change:",
      sorted(k for k in old if k != "done_when" and str(old[k]) != str(new.get(k))))
print({k: v for k, v in new.items() if k.startswith(("n_per_cane", "per_cane_sets", "per_cane_r", "per_cane_rms",
                                                       "per_cane_err", "per_cane_median"))})
