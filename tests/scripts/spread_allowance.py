"""What the within-cane spread check (``adequacy.within_dispersion``) would do at other allowances.

The check fails a model when the held-out residual's pooled within-cane spread ``sd`` is more
than ``verdict.WITHIN_EXCESS`` times the caliper line's own (``geometry_sd``) and at least
``verdict.WITHIN_FLOOR`` in ln k. A failure withholds every global name (``adequacy.failed``).
The spreads do not depend on the allowance, and nothing before the verdict reads it, so a
stored ``discovery.json`` says exactly which sets another allowance would fail.

For every ``discovery.json`` under the folders given (a self-test run's case folders, or one
``canebench discover`` output per folder) this prints the set's spreads, its names and, where
a ``selftest_row.json`` lies beside it, what was hidden and whether the names were right. Then,
for each allowance in a grid, the sets whose global names it would newly withhold (sets another
check already withholds cannot change), and the sets it would newly flag ``unexplained`` without
withholding anything (no global name, or only an obstruction's per-trial ones), each marked:

* ``LOSS``: a self-test set named correctly (or, with nothing hidden, named nothing), whose names
  would be withheld or which would be flagged;
* ``gain``: a self-test set misnamed (an out-of-library set with a name, or a wrong name);
* ``?``: a folder without a self-test row (an independent generator's set, the field trials):
  read its label from where its truth is.

Run: ``python tests/scripts/spread_allowance.py DIR [DIR ...]`` (a second per 40 sets).
"""
import json
import os
import sys

from canebench.discovery.adequacy import within_dispersion
from canebench.discovery.checks_text import fitted_entry
from canebench.discovery.verdict import WITHIN_EXCESS, WITHIN_FLOOR
from compare_discoveries import discovery_files  # beside this script

FACTORS = (4.0, 5.0, 6.0, 7.0, WITHIN_EXCESS)
FLOORS = (0.05, 0.06, 0.08, WITHIN_FLOOR)


def load(roots: list[str]) -> list[dict]:
    sets = []
    for root in roots:
        files = discovery_files(root)
        for f in files:
            d = json.load(open(f))
            a = d.get("adequacy", {})
            wd = a.get("within_dispersion") or {}
            folder = os.path.dirname(f)
            row_f = os.path.join(folder, "selftest_row.json")
            st = json.load(open(row_f))["row"] if os.path.exists(row_f) else None
            named = [n["effect"] for n in d.get("named", []) if fitted_entry(n)]
            sets.append({"set": os.path.relpath(folder, os.path.dirname(os.path.abspath(root).rstrip("/"))),
                         "sd": float(wd.get("sd", float("nan"))),
                         "geometry_sd": float(wd.get("geometry_sd", float("nan"))),
                         "stored_fails": bool(wd.get("fails", False)),
                         "failed": list(a.get("failed", [])), "named": named,
                         "unexplained": bool(d.get("unexplained")),
                         "partial": [n["effect"] for n in d.get("partial", [])],
                         "hidden": st["hidden"] if st else None,
                         "correct": bool(st["correct"]) if st else None})
    return sets


def fails(s: dict, factor: float, floor: float) -> bool:
    """The workflow's own rule (``adequacy.within_dispersion``) at another allowance."""
    return within_dispersion(s, factor, floor)["fails"]


def mark(s: dict) -> str:
    if s["correct"] is None:
        return "?"
    return "LOSS" if s["correct"] else "gain"


def main() -> None:
    sets = load(sys.argv[1:])
    # the rule must reproduce the stored verdicts at the allowance they were made with
    for s in sets:
        if fails(s, WITHIN_EXCESS, WITHIN_FLOOR) != s["stored_fails"]:
            sys.exit(f"{s['set']}: the stored within_dispersion.fails ({s['stored_fails']}) is not what the rule here "
                     f"gives at factor {WITHIN_EXCESS:g}, floor {WITHIN_FLOOR:g}: made with another allowance?")
    print(f"{'set':46s} {'hidden':36s} {'named (global)':40s} {'ok':5s} {'sd':>6s} {'geom':>7s} {'ratio':>6s}  failed")
    for s in sets:
        ratio = within_dispersion(s, WITHIN_EXCESS, WITHIN_FLOOR)["ratio"]
        named = "+".join(s["named"]) or ("(" + "+".join(s["partial"]) + " partial)" if s["partial"] else "-")
        print(f"{s['set']:46s} {s['hidden'] or '?':36s} {named:40s} {str(s['correct']):5s} {s['sd']:6.3f} "
              f"{s['geometry_sd']:7.4f} {ratio:6.2f}  {','.join(s['failed']) or '-'}")
    print(f"\nsets whose global names an allowance would newly withhold (now: factor {WITHIN_EXCESS:g}, "
          f"floor {WITHIN_FLOOR:g}), then the sets it would newly flag unexplained and nothing more (LOSS = "
          f"correctly named, gain = misnamed, ? = no self-test row)")
    for factor in FACTORS:
        for floor in FLOORS:
            new = [s for s in sets if s["named"] and not s["failed"] and fails(s, factor, floor)]
            # a failure also flags the set unexplained (per-trial names, an obstruction's, stand)
            flag = [s for s in sets if not s["unexplained"] and not s["failed"] and fails(s, factor, floor)
                    and s not in new]
            lost = [s for s in sets if s["failed"] == ["dispersion"] and not fails(s, factor, floor)]
            text = ", ".join(f"{s['set']} ({mark(s)})" for s in new) or "none"
            text += "; newly flagged only: " + (", ".join(f"{s['set']} ({mark(s)})" for s in flag) or "none")
            more = f"; would no longer fail: {', '.join(s['set'] for s in lost)}" if lost else ""
            print(f"  factor {factor:4.1f}, floor {floor:4.2f}: {text}{more}")


if __name__ == "__main__":
    main()
