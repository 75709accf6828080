"""Early contacts in datasets, and which the workflow keeps (a contact before a second body) or
reads as the load cell drifting before contact.

For each dataset directory (push_points.csv, trials/, optional canes/), every trial whose record
has a soft ramp before the field stage's contact knee (``onsets.detect_early_contact``) is
listed with its ramp's and its slope-after's ln(slope / k_model) (k_model: the screen's linear
compliance under the default model), the cane's and the data's levels (median ln(k_field /
k_model) of pushes with neither an onset nor a candidate), and the workflow's verdict
(``workflow._ramps_that_are_the_cane``). No simulation: seconds per dataset.

Run: ``python tests/scripts/early_contacts.py DIR [DIR ...]``
"""
import math
import sys

import numpy as np

from canebench.data.dataset import load_dataset
from canebench.data.rig import read_rig_csv
from canebench.discovery.onsets import detect_early_contact
from canebench.discovery.screen import trial_geometry
from canebench.discovery.workflow import BASELINES, _ramps_that_are_the_cane, field_onsets
from canebench.execute.pipeline import field_stage
from canebench.model.presets import PRESETS
from canebench.probe.protocol import PROTOCOLS
from canebench.units import GF_TO_N


def main() -> None:
    cfg = PRESETS[BASELINES["beam"][1]]
    for root in sys.argv[1:]:
        trials = load_dataset(root)
        fields = field_stage(trials, PROTOCOLS["fast"].fit_window_mm)
        onsets = field_onsets(fields)
        early = {}
        for t in trials:
            fr = fields[t.id]
            if fr.fit is not None and fr.fit.rises and t.csv is not None and np.isfinite(fr.fit.onset_mm):
                rig = read_rig_csv(t.csv)
                e = detect_early_contact(rig.displacement_mm, rig.force_gf, fr.fit.onset_mm)
                if e is not None:
                    early[t.id] = e
        if not early:
            print(f"{root}: {len(trials)} trials, no early contact")
            continue
        geoms = {t.id: trial_geometry(t, cfg) for t in trials}
        kept, drifts = _ramps_that_are_the_cane(early, trials, geoms, fields, onsets)
        k_model = {tid: 1e-3 / g.compliance()[0] for tid, g in geoms.items()}
        cane_of = {t.id: t.cane.id for t in trials}
        lv = {tid: math.log(fields[tid].k / k_model[tid]) for tid in fields
              if tid not in early and tid not in onsets and fields[tid].k > 0}
        pooled = float(np.median(list(lv.values()))) if lv else math.nan
        print(f"{root}: {len(trials)} trials, {len(early)} early contact(s): {len(kept)} kept, {len(drifts)} drift(s)")
        for tid, e in sorted(early.items()):
            km = k_model[tid] / GF_TO_N
            own = [v for k, v in lv.items() if cane_of[k] == cane_of[tid]]
            print(f"  {tid:10s} ramp {math.log(e.slope_before / km):+6.2f}  after {math.log(e.slope_after / km):+6.2f}  "
                  f"cane level {np.median(own) if own else math.nan:+6.2f}  data level {pooled:+6.2f}  "
                  f"-> {'contact' if tid in kept else 'drift'}")


if __name__ == "__main__":
    main()
