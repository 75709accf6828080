"""How well the per-cane spread's reported error covers: the information's against the one widened to
the jackknife over plants (:func:`canebench.discovery.per_cane.wider_of`,
:func:`~canebench.discovery.per_cane.clustered_cov`).

``python tests/scripts/spread_error_coverage.py PLANTS DATASETS SEED``

G = PLANTS plants of three canes, three pushes a cane, the prediction linear in ln v (the test
suite's ``_linear_hierarchy``), mu = ln 50, omega = 0.6, s = 0.05, t = 0.15; DATASETS datasets each
where the canes of a plant share their value (``shared``) and where each cane has its own
(``independent``). Prints the datasets with no error (``none``) and those where a plant's leave-out
finds no spread, then, for (mu, ln omega), the scatter of the fits over the median error and the
95 % coverage of each error, and the mean ratio of the widened error to the information's.
docs/discovery.md, session 65, has the table (PLANTS 6 and 12, DATASETS 200, SEED 1 and 2; 160-620 s
each case on this machine).
"""
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from test_per_cane import _draw_by_plant, _fit_linear, _linear_hierarchy  # noqa: E402

from canebench.discovery import per_cane as pc  # noqa: E402

P, NDS, seed = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3])
rng = np.random.default_rng(seed)
C = 3 * P
canes = np.repeat([f"c{i:02d}" for i in range(C)], 3)
inv = np.unique(canes, return_inverse=True)[1]
b = np.tile([-0.8, -0.55, -0.3], C)
a = rng.normal(0.0, 0.3, len(canes))
plant = np.arange(C) // 3
mu, omega, s2, t2 = math.log(50.0), 0.6, 0.05**2, 0.15**2
truth = np.array([mu, math.log(omega)])
for case, of in (("shared", plant), ("independent", np.arange(C))):
    t0 = time.time()
    est, sm, sw, none, lost = [], [], [], 0, 0
    for _ in range(NDS):
        y = _draw_by_plant(rng, of, a, b, inv, mu, omega, s2, t2)
        h = _linear_hierarchy(a, b, y, canes, np.zeros((len(y), len(y))))
        x1 = _fit_linear(h, mu, s2, t2)
        model, jk = pc.sampling_cov(h, x1), pc.jackknife_over_plants(h, x1, plant)
        cl = jk.cov
        lost += bool(jk.lost_without)
        if model is None or cl is None:
            none += 1
            continue
        est.append(x1[:2])
        sm.append(np.sqrt(np.diag(model)))
        sw.append(np.sqrt(np.diag(pc.wider_of(model, cl))))
    est, sm, sw = np.array(est), np.array(sm), np.array(sw)
    sd = est.std(0, ddof=1)
    print(case, "G", P, "seed", seed, "n", len(est), "none", none, "spread lost without a plant", lost,
          "sd/med info", np.round(sd / np.median(sm, 0), 2), "sd/med wide", np.round(sd / np.median(sw, 0), 2),
          "cover95 info", np.mean(np.abs(est - truth) < 1.96 * sm, 0),
          "cover95 wide", np.mean(np.abs(est - truth) < 1.96 * sw, 0),
          "mean wide/info", np.round(np.mean(sw / sm, 0), 2), f"{time.time() - t0:.0f} s", flush=True)
