"""How often the per-cane test calls a root per cane, on the bundled canes' screen.

Datasets as ``tests/test_per_cane.py`` draws them (each cane's own level, sd 0.15 in ln; trial
noise 0.05; one draw of the caliper lines' error): ``--nulls`` with one root of 20 N m/rad for every
cane, ``--spread`` with roots scattered by ``--ln-sd`` in ln between canes. Prints how many nulls fall
below 0.05 and below the workflow's level (``PER_CANE_ALPHA``), how many spread sets are called per
cane, and how closely each cane's value follows its true one (r of the logs).

Run: ``python tests/scripts/per_cane_calibration.py --nulls 200 --spread 40 --seed 7`` (about 0.6 s a set).
"""
import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import test_per_cane as T  # noqa: E402  (the test's own draws)

from canebench.data.dataset import bundled_dataset, load_dataset  # noqa: E402
from canebench.discovery.per_cane import PER_CANE_ALPHA  # noqa: E402
from canebench.discovery.screen import trial_geometry  # noqa: E402
from canebench.discovery.screenset import Anchored, ScreenSet  # noqa: E402
from canebench.model.presets import PRESETS  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--nulls", type=int, default=200)
    ap.add_argument("--spread", type=int, default=40)
    ap.add_argument("--ln-sd", type=float, default=0.7)
    ap.add_argument("--seed", type=int, default=7)
    a = ap.parse_args()
    ss = ScreenSet.build([trial_geometry(t, PRESETS["beam-consistent"]) for t in load_dataset(bundled_dataset())])
    at = Anchored(ss, np.log(np.full(len(ss.trials), 0.1)))
    rng = np.random.default_rng(a.seed)
    ps = np.array([T._test(at, T._simulate(at, rng, 20.0, 0.0)[0]).p for _ in range(a.nulls)])
    print(f"one root for all canes, {a.nulls} sets: p < 0.05 in {(ps < 0.05).sum()}, p < {PER_CANE_ALPHA} "
          f"(the workflow's level) in {(ps < PER_CANE_ALPHA).sum()}")
    found, rs = 0, []
    for _ in range(a.spread):
        y, truth = T._simulate(at, rng, 20.0, a.ln_sd)
        t = T._test(at, y)
        c = sorted(truth)
        found += t.per_cane
        if t.per_cane:
            rs.append(np.corrcoef(np.log([t.values[k] for k in c]), np.log([truth[k] for k in c]))[0, 1])
    if a.spread:
        print(f"roots scattered by {a.ln_sd} in ln, {a.spread} sets: per cane in {found}"
              + (f"; each cane's value against its true one, r {min(rs):.2f} to {max(rs):.2f} (median "
                 f"{np.median(rs):.2f})" if rs else ""))


if __name__ == "__main__":
    main()
