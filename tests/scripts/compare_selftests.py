"""Compare two self-test runs row by row: ``python tests/scripts/compare_selftests.py OLD NEW``.

OLD and NEW are ``canebench discover --selftest --out`` folders (their ``selftest.csv`` and
``selftest.json``, or ``selftest_subset.*`` for a ``--selftest-cases`` run). A row is ``same`` when its name, partial names, ``unexplained`` flag and
verdict agree; each row also prints the parameter errors of both runs. Then every summary figure
that differs.
"""
import json
import sys
from pathlib import Path

import pandas as pd

old, new = sys.argv[1], sys.argv[2]


def _files(root: str) -> tuple[str, str]:
    """A run's table and summary: a ``--selftest-cases`` run writes them as ``selftest_subset.*``."""
    stem = "selftest" if Path(f"{root}/selftest.csv").exists() else "selftest_subset"
    return f"{root}/{stem}.csv", f"{root}/{stem}.json"


a = pd.read_csv(_files(old)[0]).set_index("id")
b = pd.read_csv(_files(new)[0]).set_index("id")
verdict = ["named", "partial", "unexplained", "correct"]
errors = ["err_scale", "err_k_root", "err_k_rig", "err_angle_deg"]
for i in b.index:
    if i not in a.index:
        print(f"{i:42s} only in {new}")
        continue
    ra, rb = a.loc[i], b.loc[i]
    ch = {c: (ra[c], rb[c]) for c in verdict if str(ra[c]) != str(rb[c])}
    errs = " ".join(f"{c[4:]} {ra[c]:.3f}->{rb[c]:.3f}" for c in errors
                    if c in a and c in b and (pd.notna(rb[c]) or pd.notna(ra[c])))
    print(f"{i:42s} {'CHANGED ' + str(ch) if ch else 'same'} named={rb['named']} size {ra['size']:.2f}->{rb['size']:.2f} "
          f"spread {ra['within_spread_ratio']:.1f}->{rb['within_spread_ratio']:.1f} {errs}")
sa = json.load(open(_files(old)[1]))
sb = json.load(open(_files(new)[1]))
for k in sb:
    if k != "datasets" and sa.get(k) != sb.get(k):
        print(f"  {k}: {sa.get(k)} -> {sb.get(k)}")
