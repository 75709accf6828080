"""``canebench discover``: find, name and fit the missing physical effect (or run the self-test)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from . import common


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("discover", help="find where simulation and measurement disagree and name the missing effect")
    common.add_data_options(p)
    p.add_argument("--out", default="canebench-runs/discover", help="output folder (discovery.json, model.yaml...)")
    p.add_argument("--baseline", default="beam", help="beam (default), chain or paper")
    p.add_argument("--backends", help="engines re-run before/after with the fitted model (default: the baseline's)")
    p.add_argument("--candidates", help="comma-separated effects to screen (default: the library's global effects)")
    p.add_argument("--alpha", type=float, default=0.05, help="family-wise significance per selection step")
    p.add_argument("--min-change", type=float, default=0.05,
                   help="materiality: smallest mean |change in ln k| an effect must make to be named")
    p.add_argument("--bootstrap", type=int, default=100, help="cane-bootstrap replicates of the intervals")
    p.add_argument("--no-confirm", action="store_true", help="skip re-running the engines with the fitted model")
    p.add_argument("--selftest", action="store_true", help="run the seeded hidden-effect suite instead")
    p.add_argument("--seed", type=int, default=7, help="self-test seed")
    p.add_argument("--workers", type=int, default=2, help="self-test processes")
    p.add_argument("--selftest-cases", help="self-test: comma-separated globs on case ids (default: all 42)")
    common.add_executor_options(p, store=False)
    p.set_defaults(fn=main)


def _excluded_text(v: dict) -> str:
    """An obstructed trial left out of the fit: not scored (with its reason in the notes), or an
    early contact."""
    return " (not scored)" if "reason" in v else " (early contact)" if v.get("excluded") else ""


def main(a: argparse.Namespace) -> int:
    if a.selftest:
        from ..discovery.selftest import run_selftest, summarize

        # the suite scores the default workflow on its own datasets; say which options it leaves aside
        ignored = [opt for opt, v, default in (
            ("--field", a.field, None), ("--trials", a.trials, None), ("--baseline", a.baseline, "beam"), ("--backends", a.backends, None),
            ("--candidates", a.candidates, None), ("--alpha", a.alpha, 0.05), ("--min-change", a.min_change, 0.05),
            ("--bootstrap", a.bootstrap, 100), ("--no-confirm", a.no_confirm, False),
            # each case runs serially in one of --workers processes
            ("--executor", a.executor, common.EXECUTOR_DEFAULTS["executor"]), ("--jobs", a.jobs, common.default_jobs()),
            ("--scheduler", a.scheduler, common.EXECUTOR_DEFAULTS["scheduler"])) if v != default]
        if ignored:
            print(f"note: the self-test runs the default workflow on its own datasets: {', '.join(ignored)} "
                  "do not apply", file=sys.stderr)

        out = Path(a.out if a.out != "canebench-runs/discover" else "canebench-runs/discover-selftest")
        df = run_selftest(out, a.seed, a.workers, only=a.selftest_cases)
        cols = [c for c in ["id", "named", "partial", "unsupported", "unexplained", "adequacy_p", "size", "gap_before",
                            "gap_after_cv", "per_cane", "per_cane_p", "per_cane_r"] if c in df] + [
            c for c in df.columns if c.startswith("err_")]
        print(df[cols].to_string(index=False, float_format=lambda v: f"{v:.3g}"))
        summary = summarize(df)
        criteria = summary.pop("done_when")
        print(json.dumps(summary, indent=2, default=float))
        print("done when (issue 10):")
        for c in criteria:
            mark = {True: "met", False: "NOT met", None: "not measured"}[c["met"]]
            print(f"  {mark:12s} {c['criterion']}: {c['measured']} (target {c['target']})")
        stem = "selftest_subset" if a.selftest_cases else "selftest"
        print(f"written: {out / (stem + '.csv')}, {out / (stem + '.json')}")
        return 0
    from ..discovery.checks_text import adequacy_lines, change_text, fitted_entry, rivals_text, scope_text
    from ..discovery.verdict import INADEQUATE, UNEXPLAINED_WHY
    from ..discovery.workflow import discover
    from ..execute.progress import Progress

    _, trials = common.trials(a)
    ex = common.executor(argparse.Namespace(executor=a.executor, jobs=a.jobs, scheduler=a.scheduler))
    backends = common.names(a.backends) or None
    cands = tuple(common.names(a.candidates)) or None
    res = discover(trials, a.baseline, backends, a.out, ex, cands, a.alpha, a.bootstrap, confirm=not a.no_confirm,
                   progress=Progress(), min_change=a.min_change)
    doc = res.to_json()
    g = doc["gap"]
    print(f"canebench discover: {len(trials)} trials, baseline {res.baseline}")
    for n in doc["notes"]:
        print(f"  {n}")
    for n in doc["named"] + doc.get("partial", []):
        what = ("named" if n in doc["named"] else
                "partial (not named: the model does not fit how stiffness scales across or along canes or the "
                "traces' shape, or needs a parameter at the end of its physical range)")
        if n["effect"] == "obstruction":
            early = n.get("n_excluded_early_contact", 0)
            print(f"  named: obstruction in {n['n_trials']} trial(s)"
                  + (f" and {early} early contact(s), left out of the fit" if early else "") + ": "
                  + ", ".join(f"{t} at {v['onset_mm']:.1f} mm" + _excluded_text(v) for t, v in n["local"].items()))
        else:
            print(f"  {what}: {n['effect']} {_params_text(n)}{_part(change_text(n), '; alone: {}')}"
                  f"{_part(scope_text(n), '; {}')}{_part(rivals_text(n), ' ({})')}")
    for u in doc.get("unsupported", []):
        print(f"  not named: {u['effect']} {_params_text(u)}"
              + (f" (its interval reaches no effect: {', '.join(u['covers_null'])})" if u["covers_null"] else "")
              + (f" (entered beside {u['dropped_with']} as a pair)" if "dropped_with" in u else ""))
    if doc.get("partial") and not any(map(fitted_entry, doc["named"])):
        print(f"  named: nothing; the library's best account (partial, above) {INADEQUATE}")
    elif doc.get("unsupported") and not any(map(fitted_entry, doc["named"])):
        print("  named: no global effect; what passed the selection did not pass its interval (above): unexplained")
    elif doc.get("too_small_to_name") and not any(map(fitted_entry, doc["named"])):
        ts = doc["too_small_to_name"]
        print(f"  named: nothing; the best fit, {ts['effect']} {_params_text(ts)}, is too small to name "
              f"(it changes the model by {ts['net_change_mean_abs']:.3g} in mean |ln k|): unexplained")
    elif not doc["named"]:
        print("  named: nothing in the library explains the residual significantly")
    print(f"  stopped: {doc['stop_reason']}")
    print(f"  median |ln k_model/k_field|: {g['before']['median_abs_log_ratio']:.3f} before, "
          f"{g['after_cv']['median_abs_log_ratio']:.3f} after (out of sample); worst "
          f"{g['before']['worst_abs_log_ratio']:.3f} -> {g['after_cv']['worst_abs_log_ratio']:.3f}")
    if "partial_after_cv" in g:
        print(f"  partial model: {g['partial_after_cv']['median_abs_log_ratio']:.3f} (out of sample); worst "
              f"{g['partial_after_cv']['worst_abs_log_ratio']:.3f}; {Path(a.out) / 'model_partial.yaml'}")
    for b, v in g.get("per_backend", {}).items():
        print(f"  {b:10s} ({v.get('model', 'named')} model) before {v['before_median']:.3f}  after {v['after_median']:.3f} (in sample)  "
              f"{v['after_cv_median']:.3f} (out of sample)  screen vs engine {v['screen_vs_engine_max']:.2g} "
              f"(linear screen alone {v.get('linear_screen_vs_engine_max', float('nan')):.2g})")
    for line in adequacy_lines(doc):
        print(f"  {line}")
    print(f"  unexplained ({UNEXPLAINED_WHY}): {doc['unexplained']}")
    print(f"  {doc['timing_s']['total_s']:.1f} s; written: {Path(a.out) / 'discovery.json'}, {Path(a.out) / 'model.yaml'}")
    return 0


def _part(text: str, fmt: str) -> str:
    """``fmt`` around ``text`` (``"; alone: {}"``), or ``""`` where there is no text: the named
    line's optional parts (:mod:`..discovery.checks_text` words each, the report too)."""
    return fmt.format(text) if text else ""


def _params_text(n: dict) -> str:
    """``k = v unit [lo, hi]`` for each parameter of a named (or not named) effect in discovery.json."""
    units, ci = n.get("units", {}), n.get("ci95", {})
    return ", ".join(f"{k} = {v:.4g}" + (f" {units[k]}" if units.get(k) not in (None, "", "1") else "")
                     + (f" [{ci[k][0]:.4g}, {ci[k][1]:.4g}]" if k in ci else "") for k, v in n["params"].items())
