"""``canebench converge``: beam convergence and chain/beam stiffness against segment count."""

from __future__ import annotations

import argparse
import datetime as _dt
import time
from pathlib import Path


def add_parser(sub: argparse._SubParsersAction) -> None:
    cv = sub.add_parser("converge", help="beam convergence and chain/beam stiffness vs segments, per formula")
    cv.add_argument("--trials", help="trial globs on the bundled dataset (default: all)")
    cv.add_argument("--segments", default="3,4,5,6,8,10,12,15,20,25,30,40")
    cv.add_argument("--out", help="output folder (a run folder: its report then shows the study)")
    cv.add_argument("--continuum", action="store_true",
                    help="also the continuum engines (mujoco_rod, exudyn_beam): stiffness vs element count against "
                         "the beam and the closed forms, cost against the MuJoCo chain (a few minutes on all canes)")
    cv.add_argument("--continuum-elements", default="5,10,20,40,80",
                    help="element counts for --continuum (default 5,10,20,40,80)")
    cv.set_defaults(fn=main)


def main(a: argparse.Namespace) -> int:
    from canebench.reports.build import convergence_page

    from ..studies.convergence import converge

    out = Path(a.out) if a.out else Path("canebench-runs") / _dt.datetime.now().strftime("converge-%Y%m%d-%H%M%S")
    t0 = time.perf_counter()
    from ..errors import InputError

    try:
        segs = tuple(int(s) for s in a.segments.split(","))
    except ValueError:
        raise InputError("--segments", "segments", f"expected comma-separated whole numbers, got {a.segments!r}") \
            from None
    if min(segs) < 1:
        raise InputError("--segments", "segments", "every segment count must be >= 1")
    cont = None
    if a.continuum:
        try:
            cont = tuple(int(s) for s in a.continuum_elements.split(","))
        except ValueError:
            raise InputError("--continuum-elements", "continuum_elements",
                             f"expected comma-separated whole numbers, got {a.continuum_elements!r}") from None
        if min(cont) < 2:
            raise InputError("--continuum-elements", "continuum_elements", "every element count must be >= 2")
    r = converge(out, a.trials, segs, progress=lambda i, n, tid: print(f"[{i:3d}/{n}] {tid}", flush=True),
                 continuum_elements=cont)
    print(r.beam_mesh_summary)
    if r.beam_mesh is not None and len(r.beam_mesh):
        worst = r.beam_mesh.sort_values("rel_error", ascending=False).head(5)
        print(worst[["trial", "elements", "rel_error", "pass", "rel_error_continuum", "rest_offset_m"]]
              .to_string(index=False, float_format=lambda v: f"{v:.2e}"))
    print(f"\nbeam: tip-deflection error vs RK4 elements, observed order {r.rod_order:.2f}")
    print(r.rod.to_string(index=False, float_format=lambda v: f"{v:.3e}"))
    print("\nchain stiffness / beam stiffness - 1 over the bundled canes (small deflection, gravity off):")
    print(r.summary.to_string(index=False, float_format=lambda v: f"{v:.4f}"))
    print("\ndual-length chains more than 1 % from the beam at 20 segments (torsion: the chain has no twist joint):")
    print(r.exceedances.to_string(index=False, float_format=lambda v: f"{v:.4f}") if len(r.exceedances) else "  none")
    ex = r.exceedances_twist
    print("the same chains with the twist joint (--set twist_joint=true):")
    print(ex.to_string(index=False, float_format=lambda v: f"{v:.4f}") if ex is not None and len(ex) else "  none")
    df = r.chains
    for f in ("paper", "end_angle", "dual_length"):
        g = df[(df.trial == "uniform-cantilever") & (df.formula == f) & (df.discretization == "uniform")]
        last = g[g.segments == g.segments.max()].iloc[0]
        print(f"uniform cantilever, {f}, {int(last.segments)} segments: k_chain/k_beam = {last.ratio:.4f}")
    if r.continuum_summary is not None and len(r.continuum_summary):
        print("\ncontinuum engines: stiffness vs the beam (bundled canes), closed forms (cantilevers), cost vs the "
              "MuJoCo chain (small push, gravity off):")
        print(r.continuum_summary.to_string(index=False, float_format=lambda v: f"{v:.3g}"))
    page = convergence_page(out)
    from canebench.reports.convergence import continuum_section

    sec = continuum_section(out)
    if sec:
        cpage = out / "continuum.html"
        cpage.write_text("<!doctype html><html><head><meta charset='utf-8'><title>canebench continuum engines"
                         f"</title></head><body>{sec}</body></html>")
        print(f"continuum engines: {cpage}")
    print(f"done in {time.perf_counter() - t0:.1f} s -> {page}")
    return 0
