"""Could a rule on the named model tell a lateral support below every push from root + flare?

In small-deflection statics of a straight cantilever, a push at height h above a change of the
cane's bending compliance changes the push compliance by a quadratic in h:

* a flare (extra stiffness w(s) = 1/EI(s) - 1/EI_flared(s) >= 0 below the pushes) lowers it by
  A h^2 - 2 B h + C with A = int w, B = int w s, C = int w s^2; by Cauchy-Schwarz B^2 < A C;
* a root spring k_root raises it by h^2 / k_root (A becomes int w - 1 / k_root);
* a lateral spring support at height a below every push lowers it by c (h - h0)^2, a perfect
  square (B^2 = A C), with h0 = int s (a - s) / EI ds / int (a - s) / EI ds (a / 3 on a uniform rod).

So rho = B^2 / (A C) is 1 for a point support, under 1 for a flare alone, and anything for a
flare with a root. This prints rho per cane for the model a ``discover`` run named (its
``base_flare`` and ``root_compliance``), on each cane's caliper line and the stated modulus,
cane taken straight, integrals up to its lowest push; and, where the folder has the generator's
truth, the support's h0 against the lowest push. A support the named model had pinned down would
show rho near 1 on every cane.

Run: ``python tests/scripts/support_as_flare.py DATASET [DISCOVERY_JSON]`` (default
``DATASET/out/discovery.json``).
"""
import json
import sys
from pathlib import Path

import numpy as np

from canebench.data.dataset import load_dataset
from canebench.discovery.checks_text import fitted_entry
from canebench.model.diameter import fit_diameter


def moments(w: np.ndarray, s: np.ndarray) -> tuple[float, float, float]:
    return float(np.trapezoid(w, s)), float(np.trapezoid(w * s, s)), float(np.trapezoid(w * s * s, s))


data = Path(sys.argv[1])
doc = json.loads(Path(sys.argv[2] if len(sys.argv) > 2 else data / "out" / "discovery.json").read_text())
params = {n["effect"]: n["params"] for n in doc["named"] if fitted_entry(n)}
flare, root = params.get("base_flare"), params.get("root_compliance")
truth_path = data / "truth" / "truth.json"
support = json.loads(truth_path.read_text())["effects"].get("lateral_support") if truth_path.exists() else None
print(f"named: {sorted(params)}")
canes: dict[str, list] = {}
for t in load_dataset(data):
    canes.setdefault(t.cane.id, []).append(t)
rhos = []
for cid, ts in sorted(canes.items()):
    cane = ts[0].cane
    hc = np.array([c.where.height if c.where.height is not None else c.where.s for c in cane.calipers])
    dc = np.array([c.diameter for c in cane.calipers])
    line = fit_diameter(hc, dc)  # the harness's caliper line
    E = cane.material.flexural_modulus
    h_low = 1e-3 * min(t.height_mm for t in ts)
    s = np.linspace(0.0, h_low, 4000)
    d0 = line(s)
    ei = E * np.pi * d0 ** 4 / 64
    w = np.zeros_like(s)
    if flare:
        d1 = d0 + 1e-3 * flare["excess_mm"] * np.exp(-s / (1e-3 * flare["length_mm"]))
        w = 1 / ei - 1 / (E * np.pi * d1 ** 4 / 64)
    A, B, C = moments(w, s)
    rho_flare = B * B / (A * C) if A * C != 0 else float("nan")
    if root:
        A -= 1 / root["k_root"]
    rho = B * B / (A * C) if A * C != 0 else float("nan")
    rhos.append(rho)
    line_out = f"{cid}: rho {rho:6.3f} (its flare alone {rho_flare:.3f})"
    if support:
        top = np.linspace(0.0, 1.0, 2000)
        # the generator places the support at a fraction of the polyline's length
        length = float(np.sum(np.linalg.norm(np.diff(cane.polyline, axis=0), axis=1)))
        a = support["height_frac"] * length
        sa = top * a
        eia = E * np.pi * line(sa) ** 4 / 64
        h0 = float(np.trapezoid(sa * (a - sa) / eia, sa) / np.trapezoid((a - sa) / eia, sa))
        line_out += f"; truth: support at {1e3 * a:.0f} mm, h0 {1e3 * h0:.0f} mm, lowest push {1e3 * h_low:.0f} mm"
    print(line_out)
print(f"rho over {len(rhos)} canes: median {np.nanmedian(rhos):.3f}, range [{np.nanmin(rhos):.3f}, {np.nanmax(rhos):.3f}]"
      " (1: a point support; under 1: a flare alone)")
