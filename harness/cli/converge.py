"""``canebench converge``: beam convergence and chain/beam stiffness against segment count."""

from __future__ import annotations

import argparse
import datetime as _dt
import time
from pathlib import Path

import numpy as np


def add_parser(sub: argparse._SubParsersAction) -> None:
    cv = sub.add_parser("converge", help="beam convergence and chain/beam stiffness vs segments, per formula")
    cv.add_argument("--trials", help="trial globs on the bundled dataset (default: all)")
    cv.add_argument("--segments", default="3,4,5,6,8,10,12,15,20,25,30,40")
    cv.add_argument("--out", help="output folder (a run folder: its report then shows the study)")
    cv.set_defaults(fn=main)


def main(a: argparse.Namespace) -> int:
    from canebench.reports.build import build_report
    from canebench.reports.convergence import chain_plot, rod_plot, summary

    from ..data.dataset import bundled_dataset, load_dataset
    from ..studies.convergence import chain_convergence, rod_convergence, straight_cantilever

    out = Path(a.out) if a.out else Path("canebench-runs") / _dt.datetime.now().strftime("converge-%Y%m%d-%H%M%S")
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    rod = rod_convergence()
    rod.to_csv(out / "rod_convergence.csv", index=False)
    order = np.polyfit(np.log(rod.elements[:-2]), np.log(rod.rel_error[:-2]), 1)[0]
    print(f"beam: tip-deflection error vs RK4 elements, observed order {-order:.2f}")
    print(rod.to_string(index=False, float_format=lambda v: f"{v:.3e}"))
    cases = [("uniform-cantilever", straight_cantilever(False), "tip"), ("tapered-cantilever", straight_cantilever(True), "tip")]
    cases += [(t.id, t.cane, t.push_id) for t in load_dataset(bundled_dataset(), a.trials)]
    segs = tuple(int(s) for s in a.segments.split(","))
    df = chain_convergence(cases, segments=segs, progress=lambda i, n, tid: print(f"[{i:3d}/{n}] {tid}", flush=True))
    df.to_csv(out / "convergence.csv", index=False)
    chain_plot(df, out / "chain_convergence.png")
    rod_plot(rod, out / "rod_convergence.png")
    summ = summary(df)
    summ.to_csv(out / "convergence_summary.csv", index=False)
    print("\nchain stiffness / beam stiffness - 1 over the bundled canes (small deflection, gravity off):")
    print(summ.to_string(index=False, float_format=lambda v: f"{v:.4f}"))
    from canebench.reports.convergence import exceedances

    exc = exceedances(df)
    print("\ndual-length chains more than 1 % from the beam at 20 segments (torsion: the chain has no twist joint):")
    print(exc.to_string(index=False, float_format=lambda v: f"{v:.4f}") if len(exc) else "  none")
    for f in ("paper", "end_angle", "dual_length"):
        g = df[(df.trial == "uniform-cantilever") & (df.formula == f) & (df.discretization == "uniform")]
        last = g[g.segments == g.segments.max()].iloc[0]
        print(f"uniform cantilever, {f}, {int(last.segments)} segments: k_chain/k_beam = {last.ratio:.4f}")
    if (out / "results.csv").exists():
        page = build_report(out)
    else:
        from canebench.reports.build import _convergence_section

        page = out / "convergence.html"
        page.write_text("<!doctype html><html><head><meta charset='utf-8'><title>canebench convergence</title>"
                        "</head><body style='font-family:sans-serif;max-width:1200px;margin:auto'>"
                        f"{_convergence_section(out)}</body></html>")
    print(f"done in {time.perf_counter() - t0:.1f} s -> {page}")
    return 0

