"""Checks behind the hidden-effect generator's sagged start (ce31d26); run from the repository root.

``python docs/generator-sag/check.py slopes CASE_DIR``
    CASE_DIR is one self-test case folder (``canebench discover --selftest --out OUT`` writes
    ``OUT/<case>/`` with ``discovery.csv``, ``trials/`` and ``truth/truth.json``). Prints, over
    the trials the workflow scored, the within-cane spread of ln(k_field / k_truth) (the field
    stage's slope against the truth's ``k_effect_n_per_mm``), the same with each slope refitted
    from the trace's true first contact sample (the truth's ``n_dead``), the residual's own
    within-cane spread, and the root mean square of the slopes' bootstrap intervals as an sd.

``python docs/generator-sag/check.py start SEED [K_ROOT]``
    Generates a 2-bush dataset with ``generate_hidden`` (a root spring K_ROOT N m/rad if given)
    into a temporary folder and prints, per push, the force (gf) that holds the probe point at
    the cane's weightless rest position, where the generator's push used to start: the jump at
    contact it made; then the sag along the probe, where the push starts now, and the force
    there (zero to the solver's tolerance).

``python docs/generator-sag/check.py bundled``
    The bundled synthetic dataset (``canes/synthetic``, from ``canes/generate.py``), which was not
    regenerated: per push with a few samples before contact, the force at contact above the tare
    (a line over the first 5 mm of contact, extrapolated back over the generator's sub-sample
    contact ``delta0`` to the rest position the sweep started from).
"""

from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd


def _pooled_within(values: pd.Series, canes: pd.Series) -> float:
    dev = values - values.groupby(canes).transform("mean")
    dof = int((canes.value_counts() - 1).sum())
    return float(np.sqrt((dev**2).sum() / dof)) if dof else float("nan")


def slopes(case: Path) -> None:
    from canebench.data.rig import read_rig_csv
    from canebench.measure.field import extract_field_stiffness
    from canebench.measure.fit import fit_line
    from canebench.units import GF_TO_N

    truth = json.loads((case / "truth" / "truth.json").read_text())
    disc = pd.read_csv(case / "discovery.csv")
    rows = []
    for r in disc[disc.k_field.notna()].itertuples():
        t = truth["canes"][r.cane]["trials"][str(r.trial_no)]
        bush, cane = r.cane[1:].split("c")
        rig = read_rig_csv(case / "trials" / f"bush_{bush}_branch_{cane}_trial_{r.trial_no}.csv")
        ff = extract_field_stiffness(rig)
        x = rig.displacement_mm - rig.displacement_mm[0]
        nd = int(t["n_dead"])
        keep = np.arange(len(x)) >= nd
        over = rig.force_gf >= 1000.0  # the rig's stop, dropped as the field stage drops it
        if over.any():
            keep &= np.arange(len(x)) < int(np.argmax(over))
        oracle = fit_line(x[keep], rig.force_gf[keep] * GF_TO_N)
        rows.append({"cane": r.cane, "err": np.log(r.k_field / t["k_effect_n_per_mm"]),
                     "err_true_contact": np.log(oracle.slope / t["k_effect_n_per_mm"]),
                     "r_after_cv": r.r_after_cv, "ci_sd": np.log(ff.ci_high / ff.ci_low) / 3.92})
    e = pd.DataFrame(rows)
    print(f"{case.name}: {len(e)} scored trials on {e.cane.nunique()} canes")
    print(f"  within-cane sd of ln(k_field / k_truth):            {_pooled_within(e.err, e.cane):.3f}")
    print(f"  ... slopes refitted from the true contact sample:   {_pooled_within(e.err_true_contact, e.cane):.3f}")
    print(f"  within-cane sd of the held-out residual:            {_pooled_within(e.r_after_cv, e.cane):.3f}")
    print(f"  rms of the slopes' bootstrap intervals (as an sd):  {np.sqrt(np.mean(e.ci_sd**2)):.3f}")
    print(f"  mean ln(k_field / k_truth) (the truth is weightless): {e.err.mean():+.3f}")


def start(seed: int, k_root: float | None) -> None:
    import canebench.backends.rod as rod
    import canebench.canes.generate_hidden as gh
    from canebench.units import GF_TO_N

    forces: list[float] = []
    starts: list[tuple[float, float]] = []
    original = gh.sagged_start

    def recording(r: rod.Rod) -> float:  # the generator's start of each push
        d = original(r)
        saved = (r.m0, r.F, r._history, dict(r._jacobian))
        forces.append(r.solve_displacement(0.0) / GF_TO_N)  # held at the weightless rest
        r._history, r._jacobian = [], {}
        starts.append((1e3 * d, r.solve_displacement(d) / GF_TO_N))  # where the push starts now
        r.m0, r.F, r._history, r._jacobian = saved
        return d

    gh.sagged_start = recording
    effects = {"root_compliance": {"k_root": k_root}} if k_root else {}
    with tempfile.TemporaryDirectory() as tmp:
        gh.generate_hidden(Path(tmp) / "d", seed, effects, n_bushes=2)
    f = np.array(forces)
    print(f"seed {seed}{f', k_root {k_root}' if k_root else ''}: force at the weightless rest, per push (gf):")
    print("  " + " ".join(f"{v:+.1f}" for v in f))
    print(f"  range {f.min():+.1f} .. {f.max():+.1f}, median |F| {np.median(np.abs(f)):.1f}")
    d, f0 = np.array(starts).T
    print(f"  the sag along the probe, where the push starts now: {d.min():+.1f} .. {d.max():+.1f} mm; "
          f"the force there: max |F| {np.max(np.abs(f0)):.1e} gf")


def bundled() -> None:
    """The bundled synthetic set (``canes/generate.py``) still sweeps from the weightless rest."""
    from canebench.data.rig import read_rig_csv

    root = Path("canes")
    truth = json.loads((root / "synthetic-truth" / "truth.json").read_text())
    offsets = []
    for cid, cane in truth["canes"].items():
        bush, c = cid[1:].split("c")
        for t, tr in cane["trials"].items():
            nd = int(tr["n_dead"])
            f = read_rig_csv(root / "synthetic" / "trials" / f"syn_bush{bush}_cane{c}_trial{t}.csv").force_gf
            y = f[nd:nd + 10]
            y = y[y < 1000.0]  # the rig's stop: the field stage drops these samples too
            if nd < 3 or len(y) < 4:  # a tare needs a few samples before contact
                continue
            # the rig's first contact sample is delta0 past the cane's rest position (the generator's
            # sub-sample contact): the line over the first 5 mm of contact, extrapolated back to the
            # rest position, above the tare, is the force the sweep started from
            x = 1e3 * tr["delta0_m"] + 0.5 * np.arange(len(y))
            offsets.append(float(np.polyval(np.polyfit(x, y - f[:nd].mean(), 1), 0.0)))
    o = np.array(offsets)
    print(f"bundled synthetic, {len(o)} pushes with 3+ samples before contact: force at the rest position above "
          f"the tare median {np.median(o):+.1f} gf, range {o.min():+.1f} .. {o.max():+.1f}, "
          f"|F| > 5 gf on {int((np.abs(o) > 5).sum())}")


if __name__ == "__main__":
    if len(sys.argv) >= 3 and sys.argv[1] == "slopes":
        slopes(Path(sys.argv[2]))
    elif len(sys.argv) == 2 and sys.argv[1] == "bundled":
        bundled()
    elif len(sys.argv) >= 3 and sys.argv[1] == "start":
        start(int(sys.argv[2]), float(sys.argv[3]) if len(sys.argv) > 3 else None)
    else:
        sys.exit(__doc__)
