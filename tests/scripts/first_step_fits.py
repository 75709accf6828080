"""Every single effect and every pair fitted on the first selection step's screen of a dataset.

Run from the repository: ``python tests/scripts/first_step_fits.py [--no-restart | --compare] DIR...``
(a minute a dataset: the baseline beam run, then the fits).

- default: each candidate's BIC and parameters;
- ``--no-restart``: the same with ``fit.BOX_RESTARTS`` = 0, the fitter before 1766fc4 (on seed 7's
  rig + flare set, which ``canebench discover --selftest --seed 7 --selftest-cases '36-*' --out
  OUT`` writes, the rig + flare pair then stops on the flare's corner; docs/discovery.md);
- ``--compare``: each dataset's 15 fits three ways in one process (scipy's default first simplex,
  as before 2e8d5d3; the first simplex without restarts; with restarts): the candidates the
  restarts fit worse (BIC more than 0.05 above the better of the other two) or better, and the
  restarts' fitting time over that without them.
"""
import itertools
import sys
import time

import canebench.discovery.fit as fit
import canebench.discovery.workflow as workflow
from canebench.data.dataset import load_dataset
from canebench.discovery.workflow import SCREENED, discover
from canebench.execute.executors import make_executor

GROUPS = [(n,) for n in SCREENED] + list(itertools.combinations(SCREENED, 2))
_minimize = fit.minimize


class _Screen(Exception):
    """Carries the first step's screen out of ``discover``."""


def _grab(candidates, at, lkf, *args, **kwargs):
    raise _Screen(at, lkf)


def _scipy_default(obj, x0, method=None, options=None):
    opts = {k: v for k, v in (options or {}).items() if k != "initial_simplex"}
    return _minimize(obj, x0, method=method, options=opts)


def screen(path):
    workflow.forward_select = _grab
    try:
        discover(load_dataset(path), confirm=False, executor=make_executor("serial", 1, None), n_boot=10)
    except _Screen as e:
        return e.args
    raise RuntimeError("discover ended before its selection")


def fits(at, lkf, restarts, minimize=_minimize):
    fit.BOX_RESTARTS, fit.minimize = restarts, minimize
    t = time.perf_counter()
    out = [fit.fit_candidate(fit.Candidate.of(g), at, lkf) for g in GROUPS]
    return out, time.perf_counter() - t


flags = {a for a in sys.argv[1:] if a.startswith("--")}
for path in (a for a in sys.argv[1:] if not a.startswith("--")):
    at, lkf = screen(path)
    if "--compare" in flags:
        default, _ = fits(at, lkf, 0, _scipy_default)
        plain, t_plain = fits(at, lkf, 0)
        restarted, t_restart = fits(at, lkf, 3)
        best = [min(a.bic, b.bic) for a, b in zip(default, plain)]
        worse = [("+".join(g), round(r.bic, 2), round(b, 2)) for g, r, b in zip(GROUPS, restarted, best)
                 if r.bic > b + 0.05]
        better = sum(r.bic < b - 0.05 for r, b in zip(restarted, best))
        print(f"{path}: restarts worse on {worse or 'none'}, better on {better}; "
              f"fitting time {t_restart / t_plain:.2f}x that without restarts", flush=True)
        continue
    for g, f in zip(GROUPS, fits(at, lkf, 0 if "--no-restart" in flags else fit.BOX_RESTARTS)[0]):
        print(f"{'+'.join(g):38s} BIC {f.bic:8.1f}  "
              + "; ".join(f"{s.name}: " + ", ".join(f"{k} = {v:.4g}" for k, v in s.params) for s in f.specs))
