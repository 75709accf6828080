"""The workflow's 95 % intervals beside likelihood-ratio ones, on datasets with a known truth.

Run from the repository: ``python tests/scripts/intervals_on_datasets.py OUT CASE [CASE ...]
[--workers 2]``. A CASE is either a self-test case folder (the dataset, with ``truth/truth.json``
and ``truth/generated_for.json`` beside it: it is run as the self-test runs it, with its seed,
40 resamples and no confirmation on the engines), or ``DATA_DIR=TRUTH_JSON`` for another
generator's dataset (run with ``canebench discover``'s defaults, 100 resamples and seed 0, also
without the confirmation, which comes after the intervals). Each case runs
:func:`canebench.discovery.workflow.discover` serially in one of ``--workers`` processes, its
output under ``OUT/<case>``, with the final model's bootstrap call recorded (its interval is the
workflow's: a percentile interval, widened about the fit for the number of canes since session
57). Where that model is one global effect with one parameter that keeps the diameters (a
modulus scale, root or rig spring, or probe pitch), the likelihood-ratio intervals of ``interval_coverage.py``
(:func:`lr_intervals`, cut at chi-square(1)'s and F(1, G - 1)'s 95 % quantiles) are computed
from the same fit, screen and data, and each interval is scored against the truth's value.

This is ``interval_coverage.py``'s question asked where the truth is richer than the fitted model
(the generator's exact rod, its noise and rig artefacts): there the fit can be biased, and an
interval's width decides whether the truth is still held. Writes ``OUT/intervals.csv``, one row
per case, and prints the counts.
"""
import argparse
import json
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats

sys.path.insert(0, str(Path(__file__).resolve().parent))  # interval_coverage, beside this script
from interval_coverage import lr_intervals, print_lr_summary, scored_rows  # noqa: E402


def _case(spec: str) -> tuple[str, Path, Path, int, int]:
    """(name, data folder, truth file, bootstrap resamples, seed) of one CASE argument."""
    if "=" in spec:
        data, truth = (Path(p) for p in spec.split("=", 1))
        return data.name, data, truth, 100, 0
    folder = Path(spec)
    made = json.loads((folder / "truth" / "generated_for.json").read_text())
    return folder.name, folder, folder / "truth" / "truth.json", 40, int(made["case"]["seed"])


def one(job: tuple[str, str]) -> dict:
    """One case's row; a case that fails says why in ``why_not``, and the others go on."""
    try:
        return _one(*job)
    except Exception as e:  # noqa: BLE001 - a bad dataset must not lose the finished cases
        return {"case": job[0], "why_not": f"{type(e).__name__}: {e}"}


def _one(spec: str, out: str) -> dict:
    import canebench.discovery.workflow as wf
    from canebench.data.dataset import load_dataset
    from canebench.discovery.checks_text import fitted_entry
    from canebench.discovery.selftest import COMPARED
    from canebench.execute.executors import make_executor

    name, data, truth_file, n_boot, seed = _case(spec)
    calls = []
    real = wf.bootstrap_ci

    def recorded(fit, at, lkf, *args, **kw):
        ci = real(fit, at, lkf, *args, **kw)
        calls.append((fit, at, lkf, ci))
        return ci

    wf.bootstrap_ci = recorded  # this worker's own module: the workflow looks it up at each call
    try:
        res = wf.discover(load_dataset(data), out=Path(out) / name, executor=make_executor("serial", 1, None),
                          n_boot=n_boot, seed=seed, confirm=False)
    finally:
        wf.bootstrap_ci = real
    doc = res.to_json()
    truth = json.loads(truth_file.read_text())["effects"]
    named = [n for n in doc["named"] if fitted_entry(n)]
    row = {"case": name, "hidden": "+".join(truth) or "none", "named": "+".join(n["effect"] for n in doc["named"]),
           "n_boot": n_boot, "seed": seed, "why_not": ""}
    if not calls or len(named) != 1 or len(named) != len(doc["named"]):
        row["why_not"] = "not one named global effect"
        return row
    fit, at, lkf, ci = calls[-1]
    if tuple(fit.candidate.names) != (named[0]["effect"],) or len(fit.candidate.free) != 1:
        row["why_not"] = f"final fit {fit.candidate.names} with {len(fit.candidate.free)} parameters"
        return row
    (effect, par), = fit.candidate.free
    if effect not in COMPARED or effect not in truth:
        row["why_not"] = f"{effect} is not a compared effect hidden here"
        return row
    if truth[effect].get("ln_sd"):  # a self-test per-cane set: each cane its own value
        row["why_not"] = f"{effect} differs between canes here (ln_sd): no one true value"
        return row
    g = len(np.unique(at.screen.canes))
    value = dict(fit.specs[-1].params)[par]
    t = float(truth[effect][COMPARED[effect][0]])  # the generator's name of the parameter
    lo, hi = ci[(effect, par)]
    # the recorded call must be the final model's: its fit and interval are the ones the run wrote
    if not (np.isclose(named[0]["params"][par], value) and np.allclose(named[0]["ci95"][par], [lo, hi])):
        row["why_not"] = f"the last bootstrap call ({value}, [{lo}, {hi}]) is not the named model's"
        return row
    (llo, lhi), (flo, fhi) = lr_intervals(fit, at, lkf, stats.chi2.ppf(0.95, 1), stats.f.ppf(0.95, 1, g - 1))
    row.update(effect=effect, truth=t, fit=value, rel_err=abs(value / t - 1), lo=lo, hi=hi, lr_lo=llo, lr_hi=lhi,
               lrf_lo=flo, lrf_hi=fhi, covers=lo <= t <= hi, lr_covers=llo <= t <= lhi, lrf_covers=flo <= t <= fhi)
    return row


def main(argv: list[str]) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("cases", nargs="+")
    ap.add_argument("--workers", type=int, default=2)
    a = ap.parse_args(argv)
    a.out.mkdir(parents=True, exist_ok=True)
    rows = []
    with ProcessPoolExecutor(a.workers) as pool:
        for row in pool.map(one, [(c, str(a.out)) for c in a.cases]):
            print(json.dumps(row, default=float), flush=True)
            rows.append(row)
            pd.DataFrame(rows).to_csv(a.out / "intervals.csv", index=False)  # kept as the cases finish
    df = pd.DataFrame(rows)
    scored = scored_rows(df)
    n = len(scored)
    if n:
        print(f"{n} of {len(df)} cases scored: the workflow's interval {int(scored.covers.sum())}/{n}")
        print_lr_summary(scored, base="the workflow's interval's")
    else:
        print(f"none of {len(df)} cases could be scored")


if __name__ == "__main__":
    main(sys.argv[1:])
