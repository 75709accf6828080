"""Does the structure table's curvature row flag a correct model when the rig's noise is rough?

The row correlates, within canes, the stiffness residual with the trace's curvature (slope over
the second half of contact / over the first, ``measure.fit.halves_slope_ratio``).
Both are read off the same trace. This script simulates correct models: 18 canes of three
pushes, each cane with its own level (a modulus scatter of 0.3 in ln k), each trace a slightly
stiffening line (0.5 mm steps, 20-88 samples) times (1 + e) with e an AR(1) roughness, plus a
white load-cell noise. The residual is the cane's level plus what the noise did to the fitted
slope (the model is right, so nothing else), and the table's curvature row is run on it with
its within-cane permutation null. Printed: the median r, and how often the row's p falls below
0.05, and below 0.01 / 12 (the table's Bonferroni level over its 12 rows), for each roughness.

It also prints, per roughness, the correlation over repeated traces of one shape between the
noise in ln k and the noise in the curvature: the mechanism, with no canes involved.

Run: ``python tests/scripts/curvature_shared_noise.py [N_DATASETS]`` (default 100; under
a minute).
"""
import sys
from pathlib import Path

import numpy as np
import pandas as pd

from canebench.discovery.structure import structure_tests
from canebench.measure.fit import fit_line, halves_slope_ratio

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the tests folder: the rough-trace simulator
from test_structure import rough_trace  # noqa: E402


def dataset(rng: np.random.Generator, rough: float, phi: float) -> pd.DataFrame:
    rows = []
    for c in range(18):
        level = rng.normal(0.0, 0.3)
        for _ in range(3):
            x, clean, f = rough_trace(rng, rough, phi)
            noise = np.log(fit_line(x, f).slope) - np.log(fit_line(x, clean).slope)
            rows.append({"cane": f"c{c}", "r": level + noise, "curvature": halves_slope_ratio(x, f)})
    return pd.DataFrame(rows)


def main() -> None:
    n_sets = int(sys.argv[1]) if len(sys.argv) > 1 else 100
    rng = np.random.default_rng(2026)
    for rough, phi in [(0.0, 0.0), (0.01, 0.85), (0.03, 0.85), (0.03, 0.0)]:
        ps, rs = [], []
        for i in range(n_sets):
            s = structure_tests(dataset(rng, rough, phi), "r", features=["curvature"], seed=i)
            ps.append(float(s.p.iloc[0]))
            rs.append(float(s.r.iloc[0]))
        ps = np.array(ps)
        lk, cv = [], []
        for _ in range(400):
            x, clean, f = rough_trace(rng, rough, phi, n=60, k=0.2, bend=0.15)
            lk.append(np.log(fit_line(x, f).slope))
            cv.append(halves_slope_ratio(x, f))
        print(f"roughness {rough:.2f} (AR(1) {phi:.2f}): one trace's noise in ln k vs in curvature r = "
              f"{np.corrcoef(lk, cv)[0, 1]:+.2f}; correct models: median r {np.median(rs):+.2f}, "
              f"p < 0.05 in {np.mean(ps < 0.05):.2f}, p < 0.01/12 in {np.mean(ps < 0.01 / 12):.2f} of {n_sets}")


if __name__ == "__main__":
    main()
