"""Early contacts in datasets, and which the workflow keeps (a contact before a second body) or
reads as the load cell drifting before contact.

For each dataset directory (push_points.csv, trials/, optional canes/), every trial whose record
has a soft ramp before the field stage's contact knee (``onsets.detect_early_contact``) is
listed with its ramp's and its slope-after's ln(slope / k_model) (k_model: the screen's linear
compliance under the default model), the cane's and the data's levels (median ln(k_field /
k_model) of pushes with neither an onset nor a candidate), and the workflow's verdict
(``contacts.split_early_contacts``). No simulation: seconds per dataset.

Run: ``python tests/scripts/early_contacts.py DIR [DIR ...]``
"""
import math
import sys

import numpy as np

from canebench.data.dataset import load_dataset
from canebench.discovery.screen import trial_geometry
from canebench.discovery.contacts import (contact_levels, contacts_before_elbows, early_contacts, field_onsets,
                                         split_early_contacts)
from canebench.discovery.workflow import BASELINES
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
        moved = contacts_before_elbows(onsets, fields)
        early = early_contacts(fields, knees={k: m.fit.onset_mm for k, m in moved.items()})
        if not early:
            print(f"{root}: {len(trials)} trials, no early contact")
            continue
        geoms = {t.id: trial_geometry(t, cfg) for t in trials}
        kept, drifts = split_early_contacts(early, trials, geoms, fields, onsets)
        k_model, by_cane, pooled = contact_levels(trials, geoms, fields, set(early) | set(onsets))
        cane_of = {t.id: t.cane.id for t in trials}
        print(f"{root}: {len(trials)} trials, {len(early)} early contact(s): {len(kept)} kept, {len(drifts)} drift(s)")
        for tid, e in sorted(early.items()):
            km = k_model[tid] / GF_TO_N
            own = by_cane.get(cane_of[tid])
            print(f"  {tid:10s} ramp {math.log(e.slope_before / km):+6.2f}  after {math.log(e.slope_after / km):+6.2f}  "
                  f"cane level {np.median(own) if own else math.nan:+6.2f}  "
                  f"data level {np.median(pooled) if pooled else math.nan:+6.2f}  "
                  f"-> {'contact' if tid in kept else 'drift'}")

if __name__ == "__main__":
    main()
