"""Re-run stored self-test cases with the suite's own call and say whether ``discovery.json`` is unchanged.

For a change that must not alter the workflow's behaviour (a refactor): each ``CASE`` is a case
folder of an earlier ``canebench discover --selftest --out DIR`` run (it holds the dataset,
``selftest_row.json`` and the ``discovery.json`` the suite wrote). The case is discovered again by
:func:`canebench.discovery.selftest.discover_case` with its stored seed, on the installed code, and
the two documents are compared without ``timing_s`` (:func:`compare_discoveries.json_diff`). Nothing
is written. Minutes per case (no engine confirmation, 40 resamples, one worker).

Run: ``python tests/scripts/replay_selftest_cases.py [--show] CASE [CASE ...]``; exits 1 if any case
differs. ``--show`` also prints, per case, each global effect the new run names, its parameters and
what it alone changes ln k by (``ln_k_change``) and, where tested, its scope per cane, beside the
generator's size of the hidden effect
(the case row's ``size``: the median |change in ln k| it makes in the generator's own beam).
"""
import json
import sys
import time
from pathlib import Path

from canebench.discovery.checks_text import change_text, scope_text
from canebench.discovery.selftest import discover_case
from compare_discoveries import json_diff, load_doc  # beside this script


def main(cases: list[str]) -> int:
    show = "--show" in cases
    cases = [c for c in cases if c != "--show"]
    differs = 0
    for d in map(Path, cases):
        stored = json.loads((d / "selftest_row.json").read_text())
        seed = stored["case"]["seed"]
        t0 = time.perf_counter()
        # through JSON as the suite wrote it, so both sides hold the same types
        new = json.loads(json.dumps(discover_case(d, seed).to_json(), default=float))
        new.pop("timing_s", None)
        old = load_doc(d / "discovery.json", drop=("timing_s",))  # all but the seconds is compared
        found = list(json_diff(old, new))
        differs += bool(found)
        print(f"{d}: {'identical' if not found else 'DIFFERS'} ({time.perf_counter() - t0:.0f} s)", flush=True)
        for kind, path in found[:20]:
            print(f"    {kind}: {path}")
        if show:
            print(f"    hidden: {stored['case']['effects']}; the generator's size (median |change in ln k|) {stored['row']['size']:.3f}")
            for n in new["named"]:
                if n["scope"] != "per_trial":
                    print(f"    named: {n['effect']} {n['params']}; alone: {change_text(n) or 'ln k -'}"
                          + (f"; {scope_text(n)}" if scope_text(n) else ""))
    return 1 if differs else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
