"""One line per ``canebench discover --out`` folder: named (with 95 % intervals), partial,
unsupported, ``unexplained``, the median |ln| before -> after out of sample, and the wall time.

Run: ``python tests/scripts/discovery_summary.py ROOT NAME [NAME ...]`` (reads ROOT/NAME/discovery.json).
"""
import json
import sys
from pathlib import Path


def _param(n, k, v):
    ci = n.get("ci95", {})
    return f"{k}={v:.4g} [{ci[k][0]:.4g}, {ci[k][1]:.4g}]" if k in ci else f"{k}={v:.4g}"


for name in sys.argv[2:]:
    f = Path(sys.argv[1]) / name / "discovery.json"
    if not f.exists():
        print(name, "missing")
        continue
    x = json.loads(f.read_text())
    named = "; ".join(n["effect"] + " " + ", ".join(_param(n, k, v) for k, v in n["params"].items())
                      + (f" ({n['n_trials']} trials)" if n["effect"] == "obstruction" else "") for n in x["named"])
    part = ", ".join(n["effect"] for n in x.get("partial", []))
    uns = ", ".join(u["effect"] for u in x.get("unsupported", []))
    g = x["gap"]
    print(f"{name}: named [{named}] partial [{part}] unsupported [{uns}] unexplained {x['unexplained']} gap "
          f"{g['before']['median_abs_log_ratio']:.3f}->{g['after_cv']['median_abs_log_ratio']:.3f} "
          f"t {x['timing_s']['total_s']:.0f}s")
