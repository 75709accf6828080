"""How often the workflow's 95 % cane-bootstrap interval covers a hidden parameter, in the model.

Run from the repository: ``python tests/scripts/interval_coverage.py OUT.csv [--reps 25] [--seed 1]
[--workers 2]``. On the bundled geometry's screen (the beam-consistent preset, its own stiffness
as the anchor, so the fitted model is the true one), each of the four compared effects is hidden
``--reps`` times, at the self-test's strengths (``random_strength``, one in each fifth of the range
in turn), under per-cane scatter of ``MODULUS_LOG_SD`` (0.15 in ln, the self-test's) and per-trial
scatter of 0.03 (about the within-cane spread of the field data). The single effect is fitted
(``fit_candidate``) and its interval drawn as the workflow draws it (``bootstrap_ci``, 100 cane
resamples). One row per replicate: truth, fit, interval, and whether it covers the truth. Two
variants are scored beside it from the same end points: the "basic" interval (reflected about
the fit: 2 fit - hi, 2 fit - lo), and the percentile interval "widened" about the fit for G
canes by t(0.975, G - 1) / z(0.975) * sqrt(G / (G - 1)) (Student's quantile for an estimated
spread, and the bootstrap's variance (G - 1) / G of the cluster variance; 1.11 at 18 canes). The
summary prints coverage per effect and overall.

This separates the interval's own calibration from the self-test's misses: there the truth is
a richer rod than the fitted model (the generator's exact beam, its noise and rig artefacts), so
a miss there can be the model's bias, which no resampling of canes can show.
"""
import argparse
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats

TRIAL_SD = 0.03


def _screen():
    from canebench.data.dataset import bundled_dataset, load_dataset
    from canebench.discovery.screen import trial_geometry
    from canebench.discovery.screenset import ScreenSet
    from canebench.model.presets import PRESETS

    ss = ScreenSet.build([trial_geometry(t, PRESETS["beam-consistent"]) for t in load_dataset(bundled_dataset())])
    return ss, -np.log(ss.c0 * 1e3)


def one(job: tuple[str, int, int]) -> dict:
    from canebench.canes.generate_hidden import MODULUS_LOG_SD, random_strength
    from canebench.discovery.fit import Candidate, bootstrap_ci, fit_candidate
    from canebench.discovery.screenset import Anchored
    from canebench.discovery.selftest import COMPARED
    from canebench.model.effects import EffectSpec

    name, rep, seed = job
    ss, lkb = _screen()
    at = Anchored(ss, lkb)
    rng = np.random.default_rng([seed, list(COMPARED).index(name), rep])
    gen_param, lib_param = COMPARED[name]
    truth = random_strength(name, rng, stratum=(rep % 5, 5))[gen_param]
    canes, inv = np.unique(ss.canes, return_inverse=True)
    scatter = rng.normal(0, MODULUS_LOG_SD, len(canes))[inv] + rng.normal(0, TRIAL_SD, len(lkb))
    lkf = at.predict((EffectSpec(name, ((lib_param, truth),)),)) + scatter
    fit = fit_candidate(Candidate.of((name,)), at, lkf)
    value = dict(fit.specs[0].params)[lib_param]
    lo, hi = bootstrap_ci(fit, at, lkf, n_boot=100, seed=rep)[(name, lib_param)]
    blo, bhi = 2 * value - hi, 2 * value - lo
    g = len(canes)
    w = stats.t.ppf(0.975, g - 1) / stats.norm.ppf(0.975) * np.sqrt(g / (g - 1))
    wlo, whi = value - w * (value - lo), value + w * (hi - value)
    return {"effect": name, "rep": rep, "seed": seed, "truth": truth, "fit": value, "lo": lo, "hi": hi,
            "rel_err": abs(value / truth - 1), "covers": lo <= truth <= hi, "basic_covers": blo <= truth <= bhi,
            "widened_covers": wlo <= truth <= whi,
            "truth_above": truth > hi, "truth_below": truth < lo}


def main(argv: list[str]) -> None:
    from canebench.discovery.selftest import COMPARED

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("--reps", type=int, default=25)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--workers", type=int, default=2)
    a = ap.parse_args(argv)
    jobs = [(name, r, a.seed) for name in COMPARED for r in range(a.reps)]
    with ProcessPoolExecutor(a.workers) as pool:
        rows = list(pool.map(one, jobs))
    df = pd.DataFrame(rows)
    df.to_csv(a.out, index=False)
    by = df.groupby("effect").agg(n=("covers", "size"), covered=("covers", "sum"), basic=("basic_covers", "sum"),
                                  widened=("widened_covers", "sum"),
                                  above=("truth_above", "sum"), below=("truth_below", "sum"),
                                  median_err=("rel_err", "median"), max_err=("rel_err", "max"))
    print(by.to_string())
    print(f"all: percentile {int(df.covers.sum())}/{len(df)} ({df.covers.mean():.1%}), "
          f"basic {int(df.basic_covers.sum())}/{len(df)} ({df.basic_covers.mean():.1%}), "
          f"widened {int(df.widened_covers.sum())}/{len(df)} ({df.widened_covers.mean():.1%})")


if __name__ == "__main__":
    main(sys.argv[1:])
