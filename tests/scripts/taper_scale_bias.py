"""How far a power-law taper below the calipers pulls a fitted modulus scale, on the screen alone.

Run from the repository: ``python tests/scripts/taper_scale_bias.py [N_DRAWS]`` (about a minute;
no engine runs). On the bundled canes' geometry, each draw makes every cane's diameters a power
law a + b (1 - s/L)^p through its caliper line's values at the calipers (the within-cane
check's test helper, ``tests/test_discovery.py::_power_law_diameters``), with p drawn per cane
from a range; hides a modulus scale of 1.5 with cane offsets (0.15 in ln) and trial noise
(0.03); and fits, on the linear screen anchored at the caliper-line geometry, the scale alone
and the scale beside a flare. Prints the median and worst relative error of the fitted scale
per exponent range. The screen is the workflow's small-deflection linearization, so these are
not the engines' figures; they say whether a flare fitted beside the scale would take the
taper's pull.
"""
import sys
from pathlib import Path

import numpy as np

from canebench.data.dataset import bundled_dataset, load_dataset
from canebench.discovery.fit import Candidate, fit_candidate
from canebench.discovery.screenset import Anchored

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the tests folder: its geometry helpers
from test_discovery import _power_law_diameters, _scaled_bundled_screen  # noqa: E402

n_draws = int(sys.argv[1]) if len(sys.argv) > 1 else 10
trials = load_dataset(bundled_dataset())
cfg, ss, lkb, _, _, inv, _, _, scale = _scaled_bundled_screen(trials)
TRUE = dict(scale[0].params)["scale"]
at = Anchored(ss, lkb)


def fitted_scale(names: tuple[str, ...], lkf: np.ndarray) -> float:
    f = fit_candidate(Candidate.of(names), at, lkf)
    return next(dict(s.params)["scale"] for s in f.specs if s.name == "modulus_scale")


for lo, hi in ((1.0, 1.0), (0.9, 1.15), (0.5, 2.0), (0.4, 2.2), (1.5, 2.2)):
    rng = np.random.default_rng(11)
    alone, beside = [], []
    for _ in range(n_draws):
        d0 = _power_law_diameters(trials, cfg, ss, inv, rng, lo, hi)
        noise = rng.normal(0, 0.15, inv.max() + 1)[inv] + rng.normal(0, 0.03, len(lkb))
        lkf = at.with_diameters(d0).predict(scale) + noise
        alone.append(fitted_scale(("modulus_scale",), lkf) / TRUE - 1)
        beside.append(fitted_scale(("modulus_scale", "base_flare"), lkf) / TRUE - 1)
    a, b = np.abs(alone), np.abs(beside)
    print(f"exponents {lo:.2f}-{hi:.2f}: scale alone median error {np.median(a):.1%} (worst {a.max():.1%}, "
          f"mean signed {np.mean(alone):+.1%}); beside a flare {np.median(b):.1%} (worst {b.max():.1%}, "
          f"mean signed {np.mean(beside):+.1%}); {n_draws} draws", flush=True)
