"""Compare two ``canebench discover --out`` folders of the same datasets, e.g. before and after a
change that must not alter behaviour.

Run: ``python tests/scripts/compare_discoveries.py [--tol T] BEFORE AFTER NAME [NAME ...]``, where
``BEFORE/NAME`` and ``AFTER/NAME`` are ``--out`` folders, or case folders of two self-test runs
(``canebench discover --selftest --out``). Per name it says whether
``discovery.json`` (without ``timing_s`` and ``provenance``) is identical, and otherwise which
values differ (by path, e.g. ``trials[3].obstruction_onset_mm``) apart from which keys one side
has and the other lacks (an output written by older code lacks a key added since: that is reported
as added, not as a difference); whether each CSV (``discovery``, ``_steps``, ``_structure``,
``_engines``) is equal on the columns both have (columns on one side only are listed); and
whether ``model.yaml`` is, apart from the lines that record when and by which commit it was
written (a self-test case writes none).
"""
import glob
import json
import math
import os
import sys
from pathlib import Path

import pandas as pd


def load_doc(path, drop=("timing_s", "provenance")):
    """A stored ``discovery.json`` without the keys in ``drop``: by default those that differ between
    two runs of the same code on the same data (the stages' seconds, and what wrote it)."""
    doc = json.loads(Path(path).read_text())
    for key in drop:
        doc.pop(key, None)
    return doc


def discovery_files(root):
    """Every ``discovery.json`` in ``root`` or one folder below it (a self-test run's case folders,
    or one ``canebench discover --out`` folder), sorted."""
    return sorted(set(glob.glob(os.path.join(root, "*", "discovery.json"))
                      + glob.glob(os.path.join(root, "discovery.json"))))


def json_diff(a, b, path="", tol=0.0):
    """Walk two JSON values together, yielding ``("changed" | "before" | "after", path)``: a value
    that differs (two numbers by more than ``tol`` times the larger of 1 and their sizes: absolute
    below 1, relative above), or a key present only before or only after."""
    if isinstance(a, dict) and isinstance(b, dict):
        for k in a.keys() | b.keys():
            p = f"{path}.{k}" if path else str(k)
            if k in a and k in b:
                yield from json_diff(a[k], b[k], p, tol)
            else:
                yield ("before" if k in a else "after"), p
    elif isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
        for i, (x, y) in enumerate(zip(a, b)):
            yield from json_diff(x, y, f"{path}[{i}]", tol)
    elif a != b and not (isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b)):
        numbers = all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in (a, b))
        if not (numbers and abs(a - b) <= tol * max(1.0, abs(a), abs(b))):
            yield "changed", path or "(top)"


def csv_diff(pb, pa):
    """'equal', 'DIFFERS' (on the common columns) or 'missing', and the columns on one side only."""
    if not (pb.exists() and pa.exists()):
        return "missing on one side", []
    db, da = pd.read_csv(pb), pd.read_csv(pa)
    common = [c for c in db.columns if c in da.columns]
    extra = [f"-{c}" for c in db.columns if c not in da.columns] + [f"+{c}" for c in da.columns if c not in db.columns]
    same = len(db) == len(da) and db[common].equals(da[common])
    return ("equal" if same else "DIFFERS"), extra


def _short(paths, n=6):
    return ", ".join(sorted(paths)[:n]) + (f" (+{len(paths) - n} more)" if len(paths) > n else "")


if __name__ == "__main__":
    args = sys.argv[1:]
    tol = 0.0
    if args and args[0] == "--tol":  # numbers this close (absolute below 1, relative above) count as equal
        tol, args = float(args[1]), args[2:]
    before, after = Path(args[0]), Path(args[1])
    for name in args[2:]:
        docs = [load_doc(root / name / "discovery.json") for root in (before, after)]
        found = list(json_diff(*docs, tol=tol))
        changed, only_b, only_a = ([p for k, p in found if k == kind] for kind in ("changed", "before", "after"))
        text = "json identical" if not changed else f"json DIFFERS at {_short(changed)}"
        if only_b or only_a:
            text += f" (keys only before: {_short(only_b) or '-'}; only after: {_short(only_a) or '-'})"
        verdicts = []
        for f in ("discovery.csv", "discovery_steps.csv", "discovery_structure.csv", "discovery_engines.csv"):
            pb, pa = before / name / f, after / name / f
            if pb.exists() or pa.exists():
                verdict, extra = csv_diff(pb, pa)
                verdicts.append(f"{f} {verdict}" + (f" [{' '.join(extra)}]" if extra else ""))
        stamp = ("created", "git_commit", "git_dirty", "canebench:")
        paths = [root / name / "model.yaml" for root in (before, after)]
        if all(p.exists() for p in paths):
            models = [[ln for ln in p.read_text().splitlines() if not any(k in ln for k in stamp)] for p in paths]
            verdicts.append("model.yaml same" if models[0] == models[1] else "model.yaml DIFFERS")
        elif any(p.exists() for p in paths):  # a self-test case writes none
            verdicts.append("model.yaml on one side only")
        print(name, "; ".join([text, *verdicts]))
