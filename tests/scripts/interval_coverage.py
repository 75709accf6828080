"""How often the workflow's 95 % cane-bootstrap interval covers a hidden parameter, in the model.

Run from the repository: ``python tests/scripts/interval_coverage.py OUT.csv [--reps 25] [--seed 1]
[--workers 2] [--n-boot 100]``, or ``... --summary CSV [CSV ...]``. On the bundled geometry's screen (the beam-consistent preset),
each of the four compared effects is hidden
``--reps`` times, at the self-test's strengths (``random_strength``, one in each fifth of the range
in turn), under per-cane scatter of ``MODULUS_LOG_SD`` (0.15 in ln, the self-test's) and per-trial
scatter of 0.03 (about the within-cane spread of the field data). The data are the screen's own
prediction (``Anchored.predict``) plus normal scatter of the kind the fit's likelihood assumes
(per cane and per trial), so the fitted model is the true one. The single effect is fitted
(``fit_candidate``) and its cane resamples refitted as the workflow refits them (``bootstrap_draws``; 100
resamples, as ``canebench discover`` by default; the self-test draws 40). The resamples are
seeded by the replicate's number alone, so the four effects share them at a replicate (their
data differ). One row per replicate: truth, fit, intervals, and whether each covers the truth.
Four intervals come from the same draws: the plain percentile interval (``lo``, ``hi``,
``covers``: the workflow's until it was widened), the "basic" interval (reflected about the fit:
2 fit - hi, 2 fit - lo), the workflow's own (``intervals_from_draws``: the percentile interval
widened about the fit for G canes by t(0.975, G - 1) / z(0.975) * sqrt(G / (G - 1)), in the fit's
coordinate, log for a log parameter; 1.11 at 18 canes; ``widened_covers``; session 47 scored
that widening in the parameter's own units, the workflow widens in the fit's coordinate), and,
for comparison (session 59), the fit -/+ t(0.975, G - 1) times the draws' sd times sqrt(G / (G - 1))
in the fit's coordinate (``se_covers``). A fifth takes G more refits: the fit -/+ t(0.975, G - 1)
times the leave-one-cane-out jackknife's standard error (``jack_covers``). The row also keeps the
draws (``draws``, space-separated), so that other intervals can be scored from the CSV.
Two more need no resampling: the likelihood-ratio interval of the fit's own objective
(:func:`lr_intervals`), cut at the chi-square's 95 % quantile (3.84) and at F(1, G - 1)'s (4.45
at 18 canes: Student's t squared, since the cane offsets' variance is estimated from G canes).
The summary prints coverage per effect and overall, the spread of (fit - truth) over each
standard error, and each interval's median width against the percentile interval's.
``--summary CSV [CSV ...]`` prints that summary again from stored CSVs, pooled, without refitting.

``--spread EFFECT:PARAM:VALUE [--reps N]`` instead compares spreads at one strength: the fitted
parameter's (in the fit's own coordinate) over N datasets, against the bootstrap's within each
of the first four, whose resamples are refitted both from the fit's value (as the workflow does)
and from a fresh start grid, to show whether the start holds the draws back.

This separates the interval's own calibration from the self-test's misses: there the truth is
a richer rod than the fitted model (the generator's exact beam, its noise and rig artefacts), so
a miss there can be the model's bias, which no resampling of canes can show.
"""
import argparse
import functools
import math
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats

TRIAL_SD = 0.03
#: steps from the fit to each end of the search box, looking for the profile's first crossing: about
#: 0.1 in ln for a log parameter and 1.35 degrees for a pitch, under the intervals' half-widths here
#: (a narrower dip of the profile could still be stepped over)
SCAN = 60


@functools.lru_cache(maxsize=1)  # once per worker
def _screen():
    from canebench.data.dataset import bundled_dataset, load_dataset
    from canebench.discovery.screen import trial_geometry
    from canebench.discovery.screenset import ScreenSet
    from canebench.model.presets import PRESETS

    ss = ScreenSet.build([trial_geometry(t, PRESETS["beam-consistent"]) for t in load_dataset(bundled_dataset())])
    return ss, -np.log(ss.c0 * 1e3)


def lr_intervals(fit, at, lkf: np.ndarray, *qs: float) -> list[tuple[float, float]]:
    """A one-parameter fit's likelihood-ratio intervals: where 2 (nll - nll at the fit) stays below each ``q``.

    The fit's own objective (:func:`~canebench.discovery.fit.nll`, with the cane and trial
    variances at their moment estimates at each point, as in the fit: not their maximum-likelihood
    values, so the cut's coverage is measured, not assured), scanned in the fit's coordinate (log
    for a log parameter) out to the search box; an end that the box cuts off is the box's. One
    walk serves every cut.
    """
    from scipy.optimize import brentq

    from canebench.discovery.fit import nll
    from canebench.model.effects import AppliedEffects

    cand, groups = fit.candidate, at.screen.canes
    if len(cand.free) != 1 or AppliedEffects([sp.instance() for sp in cand.specs(fit.x)]).changes_diameter:
        # fit.nll then also holds the calipers' penalty, which this profile leaves out
        raise ValueError(f"lr_intervals takes one free parameter of an effect that keeps the diameters, not {cand.names}")
    (blo,), (bhi,) = cand.box()
    x_hat = float(fit.x[0])

    def rise(x: float) -> float:
        return 2 * (nll(lkf - at.predict(cand.specs(np.array([x]))), groups) - fit.nll)

    ends: dict[float, list[float]] = {q: [] for q in qs}
    for bound in (blo, bhi):
        # the first crossing out from the fit, not any: a pitch's profile falls again toward the
        # mirror angle (the 1/cos^2 part is even in the angle), so bracket on a walk outward
        xs = np.linspace(x_hat, bound, SCAN + 1)
        rises = [0.0]
        for q in qs:
            while len(rises) < len(xs) and rises[-1] <= q:
                rises.append(rise(xs[len(rises)]))
            above = [i for i, r in enumerate(rises) if r > q]
            ends[q].append(brentq(lambda x: rise(x) - q, xs[above[0] - 1], xs[above[0]], xtol=1e-10) if above
                           else bound)
    (_, par), = cand.free
    return [tuple(dict(cand.specs(np.array([e]))[0].params)[par] for e in ends[q]) for q in qs]


def scored_rows(df: pd.DataFrame) -> pd.DataFrame:
    """The rows that hold intervals: a case that could not be scored has none (and maybe no such column)."""
    return df[df.lr_covers.notna()] if "lr_covers" in df else df.iloc[:0]


def print_lr_summary(df: pd.DataFrame, base: str = "the percentile interval's") -> None:
    """Coverage of the two likelihood-ratio cuts, and each one's median width against ``lo``-``hi``'s.

    Counts are of :func:`scored_rows`; ``base`` names the interval in ``lo``, ``hi``.
    """
    df = scored_rows(df)
    n = len(df)
    print(f"  likelihood ratio {int(df.lr_covers.sum())}/{n} ({df.lr_covers.mean():.1%}), "
          f"with F(1, G-1) {int(df.lrf_covers.sum())}/{n} ({df.lrf_covers.mean():.1%})")
    width = df.hi - df.lo  # so a variant's coverage is read beside its cost
    cols = {"likelihood ratio": ("lr_lo", "lr_hi"), "F(1, G-1)": ("lrf_lo", "lrf_hi")}
    if "wf_lo" in df:  # the workflow's own, widened, interval (rows written since it was widened)
        cols["the workflow's (widened)"] = ("wf_lo", "wf_hi")
    if "jack_lo" in df:  # the standard-error intervals (rows written since session 59)
        cols["the draws' sd"] = ("se_lo", "se_hi")
        cols["the jackknife's"] = ("jack_lo", "jack_hi")
    for col, (lo, hi) in cols.items():
        print(f"  median width against {base}, {col}: {((df[hi] - df[lo]) / width).median():.3f}")


def sd_interval(x_fit: float, sd: float, n_canes: int, log: bool, widen: bool) -> tuple[float, float]:
    """The fit -/+ t(0.975, G - 1) x ``sd`` in the fit's coordinate (log for a log parameter), in the
    parameter's units; ``widen`` also multiplies by sqrt(G / (G - 1)), the share of the variance a cane
    bootstrap leaves out (a jackknife's variance already carries (G - 1) / G)."""
    half = stats.t.ppf(0.975, n_canes - 1) * sd * (math.sqrt(n_canes / (n_canes - 1)) if widen else 1.0)
    ends = (x_fit - half, x_fit + half)
    return tuple(float(math.exp(e)) if log else float(e) for e in ends)


def widened_t_sd(n_canes: int) -> float:
    """The sd that (fit - truth) / the bootstrap's sd would have if the workflow's widening were exact:
    Student's t with G - 1 degrees of freedom, times sqrt(G / (G - 1))."""
    dof = n_canes - 1
    if dof <= 2:  # Student's t has no finite variance there
        return math.inf
    return math.sqrt(dof / (dof - 2)) * math.sqrt(n_canes / dof)


def jackknife_se(fit, at, lkf: np.ndarray) -> float:
    """The leave-one-cane-out jackknife's standard error of a one-parameter fit, in its coordinate:
    sqrt((G - 1) / G x sum of squared deviations of the G refits from their mean), each refit
    started from the fit's value as :func:`~canebench.discovery.fit.bootstrap_draws` starts its own."""
    from canebench.discovery.fit import fit_candidate

    canes = np.unique(at.screen.canes)
    xs = np.array([fit_candidate(fit.candidate, at.take(rows), lkf[rows], x0=fit.x).x[0]
                   for rows in (np.flatnonzero(at.screen.canes != c) for c in canes)])
    return float(math.sqrt((len(canes) - 1) / len(canes) * ((xs - xs.mean()) ** 2).sum()))


def one(job: tuple[str, int, int, int]) -> dict:
    from canebench.canes.generate_hidden import MODULUS_LOG_SD, random_strength
    from canebench.discovery.fit import Candidate, bootstrap_draws, fit_candidate, intervals_from_draws
    from canebench.discovery.screenset import Anchored
    from canebench.discovery.selftest import COMPARED
    from canebench.model.effects import EFFECTS, EffectSpec

    ss, lkb = _screen()
    at = Anchored(ss, lkb)
    name, rep, seed, n_boot = job
    rng = np.random.default_rng([seed, list(COMPARED).index(name), rep])
    gen_param, lib_param = COMPARED[name]
    truth = random_strength(name, rng, stratum=(rep % 5, 5))[gen_param]
    canes, inv = np.unique(ss.canes, return_inverse=True)
    scatter = rng.normal(0, MODULUS_LOG_SD, len(canes))[inv] + rng.normal(0, TRIAL_SD, len(lkb))
    lkf = at.predict((EffectSpec(name, ((lib_param, truth),)),)) + scatter
    fit = fit_candidate(Candidate.of((name,)), at, lkf)
    value = dict(fit.specs[0].params)[lib_param]
    draws = bootstrap_draws(fit, at, lkf, n_boot=n_boot, seed=rep)
    lo, hi = (float(v) for v in np.percentile(draws[:, 0], [2.5, 97.5]))  # the plain percentile interval
    blo, bhi = 2 * value - hi, 2 * value - lo
    wlo, whi = intervals_from_draws(fit, draws, len(canes))[(name, lib_param)]  # the workflow's
    # two standard-error intervals, for comparison: the bootstrap draws' sd (steadier than two tail
    # percentiles) and the leave-one-cane-out jackknife's (the usual remedy for few clusters)
    log = EFFECTS[name].parameters[lib_param].log
    x_fit, x_truth = (math.log(value), math.log(truth)) if log else (value, truth)
    boot_sd = float(np.std(np.log(draws[:, 0]) if log else draws[:, 0], ddof=1))
    jack_se = jackknife_se(fit, at, lkf)
    slo, shi = sd_interval(x_fit, boot_sd, len(canes), log, widen=True)
    jlo, jhi = sd_interval(x_fit, jack_se, len(canes), log, widen=False)
    # likelihood-ratio intervals: the chi-square's quantile, and F(1, G - 1)'s (Student's t squared:
    # the cane offsets' variance is estimated from G canes, as a between-cane effect's is)
    (llo, lhi), (flo, fhi) = lr_intervals(fit, at, lkf, stats.chi2.ppf(0.95, 1), stats.f.ppf(0.95, 1, len(canes) - 1))
    return {"effect": name, "rep": rep, "seed": seed, "n_boot": n_boot, "truth": truth, "fit": value, "lo": lo, "hi": hi,
            "rel_err": abs(value / truth - 1), "covers": lo <= truth <= hi, "basic_covers": blo <= truth <= bhi,
            "wf_lo": wlo, "wf_hi": whi, "widened_covers": wlo <= truth <= whi,
            "n_canes": len(canes), "x_fit": x_fit, "x_truth": x_truth, "boot_sd": boot_sd, "jack_se": jack_se,
            "se_lo": slo, "se_hi": shi, "se_covers": slo <= truth <= shi,
            "jack_lo": jlo, "jack_hi": jhi, "jack_covers": jlo <= truth <= jhi,
            "draws": " ".join(f"{d:.17g}" for d in draws[:, 0]),  # so other intervals can be scored from the CSV
            "lr_lo": llo, "lr_hi": lhi, "lr_covers": llo <= truth <= lhi,
            "lrf_lo": flo, "lrf_hi": fhi, "lrf_covers": flo <= truth <= fhi,
            "truth_above": truth > hi, "truth_below": truth < lo}


def spread(name: str, param: str, value: float, n: int, n_boot: int) -> None:
    """Print the sampling spread of the fitted coordinate over ``n`` datasets, and the bootstrap's."""
    from canebench.canes.generate_hidden import MODULUS_LOG_SD
    from canebench.discovery.fit import Candidate, cane_resamples, fit_candidate
    from canebench.discovery.screenset import Anchored
    from canebench.model.effects import EffectSpec

    ss, lkb = _screen()
    at = Anchored(ss, lkb)
    canes, inv = np.unique(ss.canes, return_inverse=True)
    rng = np.random.default_rng(11)
    data = []
    for _ in range(n):
        lkf = at.predict((EffectSpec(name, ((param, value),)),)) + rng.normal(0, MODULUS_LOG_SD, len(canes))[inv] \
            + rng.normal(0, TRIAL_SD, len(lkb))
        data.append((lkf, fit_candidate(Candidate.of((name,)), at, lkf)))
    xs = np.array([f.x[0] for _, f in data])
    print(f"{name} {param} = {value}: fitted coordinate over {n} datasets, mean {xs.mean():.4f}, sd {xs.std(ddof=1):.4f}")
    for lkf, f in data[:4]:
        warm, fresh = [], []
        for rows, sub in cane_resamples(at, n_boot, seed=0):  # bootstrap_draws' resamples
            warm.append(fit_candidate(f.candidate, sub, lkf[rows], x0=f.x).x[0])
            fresh.append(fit_candidate(f.candidate, sub, lkf[rows]).x[0])
        warm, fresh = np.array(warm), np.array(fresh)
        print(f"  bootstrap sd from the fit {warm.std(ddof=1):.4f}, from a fresh grid {fresh.std(ddof=1):.4f}, "
              f"largest difference {np.abs(warm - fresh).max():.2g}")


def main(argv: list[str]) -> None:
    from canebench.discovery.selftest import COMPARED

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path, nargs="?")
    ap.add_argument("--reps", type=int, default=25)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--n-boot", type=int, default=100)
    ap.add_argument("--spread", metavar="EFFECT:PARAM:VALUE")
    ap.add_argument("--summary", nargs="+", type=Path, metavar="CSV", help="print the summary of stored CSVs, pooled")
    a = ap.parse_args(argv)
    if a.summary:
        print_summary(pd.concat([pd.read_csv(p) for p in a.summary], ignore_index=True))
        return
    if a.out is None and not a.spread:
        ap.error("OUT is required unless --summary or --spread is given")
    if a.spread:
        name, param, value = a.spread.split(":")
        spread(name, param, float(value), a.reps, a.n_boot)
        return
    jobs = [(name, r, a.seed, a.n_boot) for name in COMPARED for r in range(a.reps)]
    with ProcessPoolExecutor(a.workers) as pool:
        rows = list(pool.map(one, jobs))
    df = pd.DataFrame(rows)
    df.to_csv(a.out, index=False)
    print_summary(df)


def print_summary(df: pd.DataFrame) -> None:
    """Coverage per effect and overall, the spreads of (fit - truth) over each standard error, and
    the intervals' widths (:func:`print_lr_summary`)."""
    by = df.groupby("effect").agg(n=("covers", "size"), covered=("covers", "sum"), basic=("basic_covers", "sum"),
                                  widened=("widened_covers", "sum"), se=("se_covers", "sum"),
                                  jack=("jack_covers", "sum"), lr=("lr_covers", "sum"),
                                  lr_f=("lrf_covers", "sum"),
                                  above=("truth_above", "sum"), below=("truth_below", "sum"),
                                  median_err=("rel_err", "median"), max_err=("rel_err", "max"))
    print(by.to_string())
    print(f"all: percentile {int(df.covers.sum())}/{len(df)} ({df.covers.mean():.1%}), "
          f"basic {int(df.basic_covers.sum())}/{len(df)} ({df.basic_covers.mean():.1%}), "
          f"the workflow's (widened) {int(df.widened_covers.sum())}/{len(df)} ({df.widened_covers.mean():.1%}), "
          f"the draws' sd {int(df.se_covers.sum())}/{len(df)} ({df.se_covers.mean():.1%}), "
          f"the jackknife's {int(df.jack_covers.sum())}/{len(df)} ({df.jack_covers.mean():.1%})")
    # rows written before the column was added (65a8af3) are all on the bundled screen
    (g,) = df.n_canes.unique() if "n_canes" in df else (len(np.unique(_screen()[0].canes)),)
    print(f"  sd of (fit - truth) / the draws' sd: {((df.x_fit - df.x_truth) / df.boot_sd).std():.3f} "
          f"(Student's t({g - 1}) times sqrt({g}/{g - 1}), if the widening were exact: {widened_t_sd(g):.3f}); "
          f"/ the jackknife's: {((df.x_fit - df.x_truth) / df.jack_se).std():.3f} "
          f"(Student's t({g - 1}): {widened_t_sd(g) * math.sqrt((g - 1) / g):.3f})")
    print_lr_summary(df)

if __name__ == "__main__":
    main(sys.argv[1:])
