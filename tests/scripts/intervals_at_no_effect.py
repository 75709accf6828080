"""List the named effects whose 95 % interval reaches their no-effect value.

Run from the repository: ``python tests/scripts/intervals_at_no_effect.py DIR [DIR ...]``. Every
``discovery.json`` under each folder is read (a self-test's ``--out``, a ``canebench discover
--out``); the judgement is the workflow's own (``nulls.covers_null``). Results written before commit
0923947 still name such effects; later ones list them under ``unsupported``, printed too.
"""
import json
import sys
from pathlib import Path

from canebench.discovery.checks_text import fitted_entry
from canebench.discovery.nulls import covers_null
from canebench.model.effects import EffectSpec

n_files = n_named = 0
for root in sys.argv[1:]:
    for f in sorted(Path(root).rglob("discovery.json")):
        doc = json.loads(f.read_text())
        n_files += 1
        for n in doc["named"]:
            if not fitted_entry(n):
                continue
            n_named += 1
            spec = EffectSpec(n["effect"], tuple(n["params"].items()))
            ci = {(n["effect"], k): tuple(v) for k, v in n["ci95"].items()}
            cov = covers_null(spec, ci)
            if cov:
                print(f"named, reaches no effect: {f}: {n['effect']} "
                      + ", ".join(f"{k} = {n['params'][k]:.4g} [{ci[(n['effect'], k)][0]:.4g}, "
                                  f"{ci[(n['effect'], k)][1]:.4g}]" for k in cov))
        for u in doc.get("unsupported", []):
            print(f"unsupported (not named): {f}: {u['effect']} {u['params']} {u['ci95']}")
print(f"{n_files} discovery.json files, {n_named} named global effects")
