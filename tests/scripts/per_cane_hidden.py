"""The per-cane test on the generator's exact rod: a root per cane, and one root for every cane.

Writes (or reuses) ``OUT/per_cane`` (k_root about ``K`` N m/rad, scattered by ``LN_SD`` in ln
between canes) and ``OUT/one`` (``K`` for every cane), both from ``SEED``, discovers each as the
self-test does (:func:`canebench.discovery.selftest.discover_case`) and prints the root's scope and
test and, where per cane, how closely each cane's value follows the generator's (r and rms of the logs).

Run: ``python tests/scripts/per_cane_hidden.py OUT [SEED [K [LN_SD]]]`` (defaults 101 20 0.7; about
a minute a set).
"""
import json
import sys
from pathlib import Path

import numpy as np

from canebench.canes.generate_hidden import generate_hidden
from canebench.discovery.checks_text import fitted_entry, scope_text
from canebench.discovery.selftest import _per_cane_scores, discover_case


def main(out: Path, seed: int, k: float, ln_sd: float) -> None:
    for tag, eff in (("per_cane", {"k_root": k, "ln_sd": ln_sd}), ("one", {"k_root": k})):
        d = out / tag
        if not (d / "truth" / "truth.json").exists():
            generate_hidden(d, seed, {"root_compliance": eff})
        truth = json.loads((d / "truth" / "truth.json").read_text())
        kt = {c: v["k_root"] for c, v in truth["canes"].items()}
        lk = np.log(list(kt.values()))
        res = discover_case(d, seed)
        print(f"{tag}: generator's k_root median {np.exp(np.median(lk)):.3g}, ln sd {lk.std(ddof=1):.2f} over "
              f"{len(kt)} canes")
        for n in res.named:
            if not fitted_entry(n):
                continue
            print(f"  named {n['effect']} {n['params']} ci95 {n.get('ci95')}; {scope_text(n)}")
            t = n.get("per_cane_test")
            if t:
                print(f"  test: LR {t['lr']:.2f}, p {t['p']:.2g}, ln sd {t['ln_sd_between_canes']:.2f}, median "
                      f"{t['median']:.3g}, spread {t['spread_mean_abs_ln_k']:.3f}")
            if "local" in n and n["effect"] == "root_compliance":
                sc = _per_cane_scores(n, truth)  # the self-test's own scoring of a per-cane root
                print(f"  each cane's k_root against the generator's: r {sc.get('per_cane_r', np.nan):.2f}, rms "
                      f"{sc.get('per_cane_rms_ln', np.nan):.2f} in ln")
        tr = res.trials
        left = tr[tr.not_scored != ""]
        print(f"  scored: {int((tr.not_scored == '').sum())} trials on {tr[tr.not_scored == ''].cane.nunique()} canes"
              + "".join(f"; {t} not scored: {why}" for t, why in zip(left.trial, left.not_scored)))
        print(f"  unexplained {res.unexplained}; median |ln| {res.gap['before']['median_abs_log_ratio']:.3f} -> "
              f"{res.gap['after_cv']['median_abs_log_ratio']:.3f} out of sample")


if __name__ == "__main__":
    args = sys.argv[1:]
    main(Path(args[0]), int(args[1]) if len(args) > 1 else 101, float(args[2]) if len(args) > 2 else 20.0,
         float(args[3]) if len(args) > 3 else 0.7)
