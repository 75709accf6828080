"""The lateral-support set of ``test_discover_withholds_a_pitch_the_traces_do_not_show`` (seed
9512, pitch alone screened), with the interval rule on or off.

Run from the repository: ``python tests/scripts/support_pitch_interval.py on|off OUT`` (about
1 minute). Prints what was named, partial and unsupported, the pitch's interval, ``unexplained``
and the adequacy checks that failed.
"""
import sys
from pathlib import Path

import canebench.discovery.selection as selection
import canebench.discovery.workflow as wf
from canebench.canes.generate_hidden import generate_hidden
from canebench.data.dataset import load_dataset
from canebench.execute.executors import make_executor

mode, out = sys.argv[1], Path(sys.argv[2])
if mode == "off":
    selection.covers_null = lambda spec, ci: []  # the interval rule looks it up there
d = generate_hidden(out / mode, 9512, {"lateral_support": {"k_support": 100.0, "height_frac": 0.4}})
res = wf.discover(load_dataset(d), confirm=False, executor=make_executor("serial", 1, None), n_boot=10,
                  candidates=("probe_misalignment",))
sh = res.adequacy["shape"]
print(f"rule {mode}: named {[(n['effect'], n['params'], n.get('ci95')) for n in res.named]}")
print(f"  partial {[(n['effect'], n['params'], n['ci95']) for n in res.partial]}")
print(f"  unsupported {res.unsupported}")
print(f"  unexplained {res.unexplained}; failed {res.adequacy['failed']}; shape p {sh.get('p')}, "
      f"level trend p {res.adequacy['after_cv']['p']:.3g}")
