"""Force drops in rig traces: how often a trace falls between two rows by more than five noise sd.

``python tests/scripts/force_drops.py DIR [DIR ...]``

Each DIR is a dataset (the field data's layout: rig CSVs in DIR or DIR/trials). Per trace, from the
first row over 30 gf (a trace with fewer than 8 such rows is skipped), the noise sd is robust: the
median absolute second difference of the force / 0.6745 / sqrt(6) (white noise's second difference
has six times its variance). A drop is a row-to-row fall larger than 5 sd (at least 5 gf). Prints
the traces counted, the share with a drop, the median number of drops, the median largest fall
(most negative row-to-row change) and the median noise sd. Used in docs/discovery.md, session 65,
to ask whether force drops could mark an out-of-library effect (the real trials have them too).
"""
import glob
import sys

import numpy as np

from canebench.data.rig import read_rig_csv


def drops_in(d: str) -> tuple[int, float, float, float, float]:
    out = []
    for f in sorted(glob.glob(d + "/trials/*.csv") + glob.glob(d + "/*.csv")):
        if f.endswith("push_points.csv"):
            continue
        try:
            F = np.asarray(read_rig_csv(f).force_gf, float)
        except Exception:  # not a rig file
            continue
        on = F > 30
        if on.sum() < 8:
            continue
        d1 = np.diff(F[np.argmax(on):])
        sig = np.median(np.abs(np.diff(d1))) / 0.6745 / np.sqrt(6)
        out.append(((d1 < -5 * max(sig, 1.0)).sum(), d1.min(), sig))
    a = np.array(out)
    return len(a), float(np.mean(a[:, 0] > 0)), float(np.median(a[:, 0])), float(np.median(a[:, 1])), float(np.median(a[:, 2]))


if __name__ == "__main__":
    for d in sys.argv[1:]:
        n, share, med, fall, sig = drops_in(d)
        print(f"{d}: {n} traces, {share:.0%} with a drop, median drops {med:.0f}, median largest fall {fall:.1f} gf, "
              f"median noise sd {sig:.2f} gf")
