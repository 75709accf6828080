"""Obstruction onsets found in the field traces against a generator's truth, counted from the
field stage's contact knee and from the knee of the record up to the elbow
(``contacts.contacts_before_elbows``).

Self-test mode generates (or reuses) the self-test's obstruction sets (cases with ``obstruction``
among their hidden effects) of each seed under OUT/s<seed>/ and reads the truth's
``obstructed`` onsets (mm after contact). For each set it prints the onsets found
(``contacts.field_onsets``, before the early-contact split), how many are true, the median and
largest absolute onset error both ways, the trials whose contact moved (mm earlier), and how far
their field stiffness (the record up to the elbow) is from the truth's linear one.
No simulation: about a minute per generated set, seconds per set after.

Run: ``python tests/scripts/onsets_against_truth.py OUT [SEED ...]`` (default seeds 7 8 9).
"""
import json
import sys
import warnings
from pathlib import Path

import numpy as np

from canebench.data.dataset import load_dataset
from canebench.discovery.selftest import _generate_case, suite
from canebench.discovery.contacts import contacts_before_elbows, field_onsets
from canebench.execute.pipeline import field_stage


def main() -> None:
    warnings.simplefilter("ignore")
    root = Path(sys.argv[1])
    for seed in [int(s) for s in sys.argv[2:]] or [7, 8, 9]:
        for case in suite(seed):
            if "obstruction" not in case["effects"]:
                continue
            folder = root / f"s{seed}" / case["id"]
            if not (folder / "truth" / "truth.json").exists():
                _generate_case(folder, case)
            doc = json.loads((folder / "truth" / "truth.json").read_text())
            truth = doc["obstructed"]
            fields = field_stage(load_dataset(folder), None)
            onsets = field_onsets(fields)
            moved = contacts_before_elbows(onsets, fields)
            old, new = [], []
            for tid, o in onsets.items():
                if tid in truth:
                    n = moved[tid].onset_mm if tid in moved else o
                    old.append(abs(o - truth[tid]))
                    new.append(abs(n - truth[tid]))
            # the moved trials' field stiffness (the record up to the elbow) against the cane's
            k_err = [abs(np.log(m.fit.k_n_per_mm / doc["canes"][t.rpartition("t")[0]]["trials"][t.rpartition("t")[2]]
                                ["k_linear_n_per_mm"])) for t, m in moved.items()]
            if not old:
                print(f"seed {seed} {case['id']}: {len(onsets)} found, none true of {len(truth)}", flush=True)
                continue
            shift = {k: round(fields[k].fit.onset_mm - v.fit.onset_mm, 1) for k, v in sorted(moved.items())}
            print(f"seed {seed} {case['id']}: {len(onsets)} found, {len(old)} true of {len(truth)}; onset error "
                  f"median {np.median(old):.2f} -> {np.median(new):.2f} mm, largest {max(old):.1f} -> "
                  f"{max(new):.1f} mm; contact moved earlier: {shift or 'none'}; their field stiffness |ln(k / k_true)| "
                  f"median {np.median(k_err) if k_err else float('nan'):.3f}, largest "
                  f"{max(k_err) if k_err else float('nan'):.3f}", flush=True)


if __name__ == "__main__":
    main()
