"""Where would the too-small-to-name rule (d516769) have fired? Read the selection tables of
earlier ``discovery.json`` files and list every step at which a single effect that fails only
the materiality rule fits better (lower BIC) than the effect chosen there, or where nothing was
chosen.

Run: ``python tests/scripts/too_small_to_name.py DIR...`` (folders searched for discovery.json;
a self-test's output folder holds one per case). The condition read here is wider than the rule
(the BIC against the current model is not in the rows), so a run it does not list takes the
same steps under the rule.
"""
import collections
import json
import sys
from pathlib import Path

MIN_REDUCTION, MIN_CHANGE = 0.05, 0.05  # selection.MIN_REDUCTION and the default --min-change
files = sorted({f for d in sys.argv[1:] for f in Path(d).rglob("discovery.json")})
hits = 0
for f in files:
    doc = json.loads(f.read_text())
    steps = collections.defaultdict(list)
    for r in doc.get("selection", []):
        if r.get("p") is not None and "candidate" in r:
            steps[r["step"]].append(r)
    for k, rows in sorted(steps.items()):
        chosen = [r for r in rows if r.get("chosen")]
        small = [r for r in rows if "+" not in r["candidate"] and r["p"] < r["level"]
                 and r["cv_relative_gain"] > MIN_REDUCTION and r["net_change_mean_abs"] < MIN_CHANGE]
        if not small:
            continue
        top = min(small, key=lambda r: r["bic"])
        if not chosen or top["bic"] < chosen[0]["bic"]:
            hits += 1
            print(f"{f}: step {k}: {top['candidate']} BIC {top['bic']:.1f}, changes the model by "
                  f"{top['net_change_mean_abs']:.3f}; chosen: "
                  + (f"{chosen[0]['candidate']} BIC {chosen[0]['bic']:.1f}" if chosen else "nothing")
                  + f"; named {[n['effect'] for n in doc.get('named', [])]}")
print(f"{len(files)} discovery.json files, {hits} steps listed")
