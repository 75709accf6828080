"""``discover`` with a chosen set of candidates, printing every selection row's BIC and fit.

Run from the repository: ``python tests/scripts/two_candidate_fit.py plain|wide DIR CANDIDATES``
(CANDIDATES comma-separated, e.g. ``modulus_scale,rig_compliance``; 40 resamples, no confirmation;
a minute or two). ``wide`` replaces the fitter's first simplex by a step of 0.3 in every
coordinate, as it was checked before 2e8d5d3 fixed scipy's 0.00025 step at 0 (docs/discovery.md,
"The fitter's first simplex"); since that commit ``plain`` gives the same fit.
"""
import sys
import numpy as np
import canebench.discovery.fit as fit
from canebench.data.dataset import load_dataset
from canebench.discovery.workflow import discover
from canebench.execute.executors import make_executor

real_minimize = fit.minimize
def wide(obj, x0, method=None, options=None):
    # initial simplex with a step of 0.3 in every optimizer coordinate (log units for log parameters)
    x0 = np.asarray(x0, float)
    sim = np.vstack([x0] + [x0 + 0.3 * np.eye(len(x0))[i] for i in range(len(x0))])
    return real_minimize(obj, x0, method=method, options={**(options or {}), "initial_simplex": sim})
if sys.argv[1] == "wide":
    fit.minimize = wide
res = discover(load_dataset(sys.argv[2]), confirm=False, executor=make_executor("serial", 1, None), n_boot=40,
               candidates=tuple(sys.argv[3].split(",")))
for s in res.steps.itertuples():
    print(s.step, s.candidate, round(s.bic, 1), s.params, getattr(s, "passed", None))
print("named", [(n["effect"], n["params"], n.get("ci95")) for n in res.named])
