"""Compare two ``canebench discover --out`` folders of the same datasets, e.g. before and after a
change that must not alter behaviour.

Run: ``python tests/scripts/compare_discoveries.py BEFORE AFTER NAME [NAME ...]``, where
``BEFORE/NAME`` and ``AFTER/NAME`` are ``--out`` folders. Per name it says whether
``discovery.json`` (without ``timing_s`` and ``provenance``) is identical, or which keys differ;
whether each CSV (``discovery``, ``_steps``, ``_structure``, ``_engines``) is equal; and whether
``model.yaml`` is, apart from the lines that record when and by which commit it was written.
"""
import json
import sys
from pathlib import Path

import pandas as pd

before, after = Path(sys.argv[1]), Path(sys.argv[2])
for name in sys.argv[3:]:
    docs = []
    for root in (before, after):
        d = json.loads((root / name / "discovery.json").read_text())
        d.pop("timing_s", None)
        d.pop("provenance", None)
        docs.append(d)
    differ = [k for k in docs[0] if docs[0].get(k) != docs[1].get(k)]
    csvs = []
    for f in ("discovery.csv", "discovery_steps.csv", "discovery_structure.csv", "discovery_engines.csv"):
        pb, pa = before / name / f, after / name / f
        if pb.exists() or pa.exists():
            csvs.append((f, pb.exists() and pa.exists() and pd.read_csv(pb).equals(pd.read_csv(pa))))
    stamp = ("created", "git_commit", "canebench:")
    models = [[ln for ln in (root / name / "model.yaml").read_text().splitlines() if not any(k in ln for k in stamp)]
              for root in (before, after)]
    print(name, "json identical" if not differ else f"json DIFFERS in {differ}", csvs,
          "model.yaml same" if models[0] == models[1] else "model.yaml DIFFERS")
