"""Studies with the beam reference: its own convergence, and how the chain's
stiffness converges (or not) to the beam's with segment count and formula.

All in small deflection with gravity off, where closed forms exist: the
chain's linear stiffness 1/(u^T J K^-1 J^T u) (Pinocchio) against the rod's
(F(d) - F(-d)) / 2d at d = 1e-5 m.

The beam's own mesh convergence on every push point (:func:`beam_mesh_convergence`):
the beam as the runs build it (mesh doubled until its linear stiffness changes
by less than 1e-4) against the same rod at twice that mesh, and against an
independent small-deflection solution of the same continuum
(:func:`continuum_stiffness`: Castigliano's integral over the polyline by
Gauss-Legendre quadrature, no shooting).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np
import pandas as pd

from ..data.cane import CaneDescription, cane_from_dict
from ..model.chain import build_chain
from ..model.config import ModelConfig
from ..backends.rod import Rod, RodSpec

SEGMENTS = (3, 4, 5, 6, 8, 10, 12, 15, 20, 25, 30, 40)
#: the beam's mesh is accepted when its linear stiffness is within this of the mesh twice as fine
BEAM_RTOL = 1e-4
# "+twist": the same formula with the optional twist joint per link (model option twist_joint)
FORMULAS = ("paper", "end_angle", "dual_length", "dual_length+twist")
DISCRETIZATIONS = ("greedy", "uniform")


def rod_convergence(elements=(4, 8, 16, 32, 64, 128), E: float = 4.57e9, L: float = 1.2, d0: float = 0.012,
                    d1: float = 0.006) -> pd.DataFrame:
    """Tip deflection error of a tapered solid circular cantilever (closed
    form 64 P L^3 / (3 pi E d0^3 d1)) against RK4 elements."""
    P = 1e-4
    exact = 64 * P * L**3 / (3 * np.pi * E * d0**3 * d1)
    spec = RodSpec(L, tangent=lambda s: np.tile([1.0, 0.0, 0.0], (len(s), 1)),
                   ei=lambda s: E * np.pi * (d0 + (d1 - d0) * s / L) ** 4 / 64)
    rows = []
    for n in elements:
        st = Rod(spec, L, [0, 0, -1.0], int(n)).solve_force(P)
        w = -st["r_end"][0][2]
        rows.append({"elements": int(n), "deflection": w, "exact": exact, "rel_error": abs(w / exact - 1)})
    return pd.DataFrame(rows)


def straight_cantilever(tapered: bool, E: float = 4.57e9, L: float = 1.2, d0: float = 0.012,
                        d1: float = 0.006) -> CaneDescription:
    """A straight vertical cantilever probed at its tip (uniform or tapered)."""
    cal = [{"s": 0.0, "diameter": d0}, {"s": L, "diameter": d1 if tapered else d0}]
    return cane_from_dict({
        "id": "tapered-cantilever" if tapered else "uniform-cantilever",
        "polyline": {"raw": False, "points": [[0, 0, 0], [0, 0, L]]},
        "calipers": cal, "push_points": [{"id": "tip", "s": L, "direction": [1, 0, 0]}],
        "material": {"flexural_modulus": E},
        "provenance": {"synthetic": True, "notes": "closed-form check case"},
    }, f"<{'tapered' if tapered else 'uniform'} cantilever>")


def closed_form_ratio(formula: str, n: int) -> float:
    """reference-values sec. 5: chain/beam tip compliance of a uniform cantilever."""
    formula = formula.removesuffix("+twist")  # a straight cantilever under an in-plane load does not twist
    if formula == "paper":
        return (n + 1) * (2 * n + 1) / (2 * 2 * n**2)
    if formula == "end_angle":
        return (n + 1) * (2 * n + 1) / (2 * 1 * n**2)
    if formula == "dual_length":
        return 1 + 1 / (2 * n**2)
    return float("nan")


def continuum_stiffness(chain, gauss_points: int = 10) -> float:
    """Small-deflection stiffness (N/m) of the chain's continuum, independently
    of the rod solver: Castigliano's theorem on the rest geometry.

    A unit force along u at the probe point r_p puts the moment
    m(s) = (r_p - r(s)) x u on the section at s < s_p; the probe's deflection
    along u is int_0^{s_p} m . C^-1 m ds with C^-1 = (1/EI)(I + nu t0 t0^T)
    (bending 1/EI, torsion 1/GJ = (1 + nu)/EI). The rest geometry is the
    smoothed polyline (r linear and t0 constant per segment) and EI(s) the
    fitted diameter line (floored), so the integrand is smooth on each piece
    between vertices, the probe and the diameter floor; Gauss-Legendre with
    ``gauss_points`` per piece integrates it to rounding. Gravity plays no
    part (as in the rod's linear stiffness).
    """
    g = chain.rod
    sp = float(chain.meta["s_push"])
    u = np.asarray(chain.direction, float) / np.linalg.norm(chain.direction)
    P, S = np.asarray(g.points, float), np.asarray(g.s, float)
    rp = np.array([np.interp(sp, S, P[:, k]) for k in range(3)])
    cuts = [S[(S > 0) & (S < sp)], [0.0, sp]]
    if g.slope != 0:  # where the diameter line meets its floor
        cuts.append([g.s_centroid + (g.min_diameter - g.d_centroid) / g.slope])
    br = np.unique(np.concatenate(cuts))
    br = br[(br >= 0) & (br <= sp)]
    a, b = br[:-1], br[1:]
    xg, wg = np.polynomial.legendre.leggauss(gauss_points)
    s = (a[:, None] + (xg[None] + 1) / 2 * (b - a)[:, None]).ravel()
    w = (wg[None] * ((b - a) / 2)[:, None]).ravel()
    seg = np.clip(np.searchsorted(S, 0.5 * (a + b), side="right") - 1, 0, len(S) - 2)
    t = np.diff(P, axis=0)[seg]
    t = np.repeat(t / np.linalg.norm(t, axis=1, keepdims=True), gauss_points, axis=0)
    r = np.column_stack([np.interp(s, S, P[:, k]) for k in range(3)])
    m = np.cross(rp - r, u)
    ei = g.modulus * np.pi * g.diameter(s) ** 4 / 64.0
    compliance = w @ (((m * m).sum(axis=1) + g.poisson_ratio * (t * m).sum(axis=1) ** 2) / ei)
    return float(1.0 / compliance)


def beam_mesh_convergence(cases: list[tuple[str, CaneDescription, str]], base: ModelConfig | None = None,
                          rtol: float = BEAM_RTOL, progress=None) -> pd.DataFrame:
    """Per push point: the beam as the runs build it against itself on a mesh
    twice as fine, and against :func:`continuum_stiffness`.

    Columns: ``elements`` (the accepted mesh), ``refinements`` (doublings from
    the configured start), ``k_beam`` (its linear stiffness), ``k_refined`` (the
    same rod at 2 x ``elements``, solved here again), ``rel_error`` =
    |k_beam / k_refined - 1| and ``pass`` (<= ``rtol``), ``k_continuum`` and
    ``rel_error_continuum``, and ``rest_offset_m``: the distance of the rod's
    rest probe point from the smoothed centreline's point at ``s_push`` (zero
    to rounding by construction).
    """
    from canebench.backends.beam_backend import BeamStatic

    base = (base or ModelConfig()).replace(gravity=0.0)
    rows = []
    for i, (tid, cane, pid) in enumerate(cases):
        chain = build_chain(cane, pid, base)
        beam = BeamStatic(chain, rtol=rtol)
        k = beam.linear_stiffness()
        k_ref = beam.rod.refined().linear_stiffness()
        k_cont = continuum_stiffness(chain)
        g = chain.rod
        on_curve = np.array([np.interp(chain.meta["s_push"], g.s, g.points[:, j]) for j in range(3)])
        err = abs(k / k_ref - 1)
        rows.append({"trial": tid, "elements": beam.extras["beam_elements"],
                     "refinements": len(beam.mesh_history) - 2, "k_beam": k, "k_refined": k_ref,
                     "rel_error": err, "pass": bool(err <= rtol), "beam_rel_error": beam.extras["beam_rel_error"],
                     "k_continuum": k_cont, "rel_error_continuum": abs(k / k_cont - 1),
                     "rest_offset_m": float(np.linalg.norm(beam.rod.p0 - on_curve))})
        if progress:
            progress(i + 1, len(cases), tid)
    return pd.DataFrame(rows)


def chain_convergence(cases: list[tuple[str, CaneDescription, str]], segments=SEGMENTS, formulas=FORMULAS,
                      discretizations=DISCRETIZATIONS, base: ModelConfig | None = None,
                      progress=None) -> pd.DataFrame:
    """k_chain / k_beam for every case, segment count, formula and discretization.

    ``cases`` are (trial id, cane, push point id).
    """
    from canebench.backends.beam_backend import BeamStatic
    from canebench.backends.pinocchio_backend import PinocchioStatic

    base = (base or ModelConfig()).replace(gravity=0.0)
    rows = []
    for i, (tid, cane, pid) in enumerate(cases):
        # the beam as the runs build it: mesh refined until converged to 1e-4
        k_beam = BeamStatic(build_chain(cane, pid, base)).linear_stiffness()
        k_beam_rigid_twist = BeamStatic(build_chain(cane, pid, base.replace(poisson_ratio=-0.99))).linear_stiffness()
        for disc in discretizations:
            for formula in formulas:
                for n in segments:
                    name, twist = (formula[: -len("+twist")], True) if formula.endswith("+twist") else (formula, False)
                    cfg = base.replace(segments=n, stiffness_formula=name, discretization=disc, twist_joint=twist)
                    ch = build_chain(cane, pid, cfg)
                    k = PinocchioStatic(ch).linear_stiffness()
                    rows.append({"trial": tid, "cane": cane.id, "discretization": disc, "formula": formula,
                                 "segments": n, "k_chain": k, "k_beam": k_beam,
                                 "k_beam_rigid_twist": k_beam_rigid_twist, "ratio": k / k_beam,
                                 "compliance_ratio": k_beam / k})
        if progress:
            progress(i + 1, len(cases), tid)
    return pd.DataFrame(rows)


#: element counts of the continuum engines' convergence (``canebench converge --continuum-elements``)
CONTINUUM_ELEMENTS = (5, 10, 20, 40, 80)
#: protocol samples per continuum probe in the convergence study (2 mm: small deflection, the same push for all)
CONTINUUM_STEPS = 4
#: cantilevers of :func:`straight_cantilever` and their closed-form tip stiffness (reference-values sec. 1)
CANTILEVERS = ("uniform-cantilever", "tapered-cantilever")


def cantilever_stiffness(tapered: bool, E: float = 4.57e9, L: float = 1.2, d0: float = 0.012,
                         d1: float = 0.006) -> float:
    """Closed-form small-deflection tip stiffness (N/m) of :func:`straight_cantilever`:
    3 E I0 / L^3, times r = d1 / d0 when tapered (reference-values sec. 1)."""
    k = 3 * E * np.pi * d0**4 / 64 / L**3
    return k * (d1 / d0) if tapered else k


def continuum_variants(elements=CONTINUUM_ELEMENTS) -> list[tuple[str, str, int, Callable[[], object]]]:
    """(backend, variant, elements, factory) of every continuum configuration the study probes.

    Every engine at every element count; the MuJoCo rod's two alternatives
    (one documented radius instead of the per-vertex taper, MuJoCo's plain
    first-edge clamp instead of the stub) at its default element count; the
    MuJoCo chain (default model) once, as the cost reference.
    """
    from canebench.backends import exudyn_beam_backend as xb
    from canebench.backends import mujoco_rod_backend as mr
    from canebench.backends.mujoco_backend import MujocoBackend

    out: list[tuple[str, str, int, Callable[[], object]]] = []
    for n in elements:
        out.append(("mujoco_rod", "per-vertex", n, lambda n=n: mr.MujocoRodBackend(n)))
    out.append(("mujoco_rod", "uniform-radius", mr.ELEMENTS, lambda: mr.MujocoRodBackend(mr.ELEMENTS, taper="uniform")))
    out.append(("mujoco_rod", "first-edge-clamp", mr.ELEMENTS,
                lambda: mr.MujocoRodBackend(mr.ELEMENTS, clamp="first-edge")))
    for n in elements:
        out.append(("exudyn_beam", "", n, lambda n=n: xb.ExudynBeamBackend(n)))
    out.append(("mujoco", "chain", 0, MujocoBackend))
    return out


def continuum_convergence(cases: list[tuple[str, CaneDescription, str]], elements=CONTINUUM_ELEMENTS,
                          n_steps: int = CONTINUUM_STEPS, base: ModelConfig | None = None,
                          progress=None) -> pd.DataFrame:
    """Stiffness of the continuum engines against element count, relative to the beam.

    Each case is probed by the harness (fast protocol, ``n_steps`` samples,
    gravity off) on every configuration of :func:`continuum_variants` and on
    the beam (the same protocol and samples, so the push's small geometric
    nonlinearity is common to both). Columns: ``trial``, ``backend``,
    ``variant``, ``elements`` (0: not a continuum), ``k`` and ``k_beam`` (N/m),
    ``rel_error`` = k / k_beam - 1, ``k_closed`` and ``rel_error_closed``
    (closed form; straight cantilevers only), ``wall_s`` (build and probe),
    ``wall_ratio`` (to the MuJoCo chain on the same case), ``status``, ``reason``.
    """
    from canebench.backends.beam_backend import BeamBackend
    from canebench.probe.driver import run_probe
    from canebench.probe.protocol import PROTOCOLS

    proto = PROTOCOLS["fast"]
    base = (base or ModelConfig()).replace(gravity=0.0)
    variants = continuum_variants(elements)
    rows = []
    for i, (tid, cane, pid) in enumerate(cases):
        chain = build_chain(cane, pid, base)
        # one protocol and the same samples for the beam and every engine (no finer repeat)
        tb = run_probe(BeamBackend(), chain, proto, n_steps, repeat_finer=False)
        fb = tb.fit()
        k_beam = fb.slope if (fb is not None and tb.status == "ok") else np.nan  # N/m (SI trace)
        k_closed = cantilever_stiffness(tid.startswith("tapered")) if tid in CANTILEVERS else np.nan
        case_rows = []
        for backend, variant, n, make in variants:
            tr = run_probe(make(), chain, proto, n_steps, repeat_finer=False)
            f = tr.fit()
            k = f.slope if (f is not None and tr.status == "ok") else np.nan
            case_rows.append({"trial": tid, "backend": backend, "variant": variant, "elements": n, "k": k,
                              "k_beam": k_beam, "rel_error": k / k_beam - 1, "k_closed": k_closed,
                              "rel_error_closed": k / k_closed - 1, "wall_s": tr.wall_s, "status": tr.status,
                              "reason": tr.reason})
        t_chain = next(r["wall_s"] for r in case_rows if r["backend"] == "mujoco")
        for r in case_rows:
            r["wall_ratio"] = r["wall_s"] / t_chain
        rows += case_rows
        if progress:
            progress(i + 1, len(cases), tid)
    return pd.DataFrame(rows)


@dataclass
class ConvergenceResult:
    """The convergence study's tables (``canebench converge``)."""

    rod: pd.DataFrame  # beam tip-deflection error against RK4 elements
    chains: pd.DataFrame  # chain/beam stiffness per case, formula, discretization, segment count
    summary: pd.DataFrame
    exceedances: pd.DataFrame
    rod_order: float
    beam_mesh: pd.DataFrame | None = None  # per push point: beam vs its own mesh twice as fine (beam_mesh.csv)
    beam_mesh_summary: str = ""  # one line: how many push points pass, the worst
    exceedances_twist: pd.DataFrame | None = None  # the same with the twist joint (expected: none)
    continuum: pd.DataFrame | None = None  # continuum engines vs element count (continuum_convergence.csv)
    continuum_summary: pd.DataFrame | None = None  # error vs beam and cost per engine (continuum_summary.csv)

    def to_df(self) -> pd.DataFrame:
        return self.chains


def converge(out: Path, trials: str | None = None, segments: tuple[int, ...] = SEGMENTS,
             progress: Callable[[int, int, str], None] | None = None,
             continuum_elements: tuple[int, ...] | None = None) -> ConvergenceResult:
    """Run the convergence study on the two straight cantilevers and the bundled canes; write CSVs and figures.

    ``continuum_elements`` (None or empty, the default: skipped; ``canebench
    converge --continuum`` gives :data:`CONTINUUM_ELEMENTS`): element counts of
    the continuum engines' part (:func:`continuum_convergence`), written to
    ``continuum_convergence.csv``, ``continuum_summary.csv`` and
    ``continuum_convergence.png``.
    """
    from canebench.reports.convergence import (beam_mesh_summary, chain_plot, continuum_plot, continuum_summary,
                                               exceedances, rod_plot, summary)

    from ..data.dataset import bundled_dataset, load_dataset

    out.mkdir(parents=True, exist_ok=True)
    rod = rod_convergence()
    rod.to_csv(out / "rod_convergence.csv", index=False)
    order = -float(np.polyfit(np.log(rod.elements[:-2]), np.log(rod.rel_error[:-2]), 1)[0])
    cases = [("uniform-cantilever", straight_cantilever(False), "tip"),
             ("tapered-cantilever", straight_cantilever(True), "tip")]
    trial_cases = [(t.id, t.cane, t.push_id) for t in load_dataset(bundled_dataset(), trials)]
    mesh = beam_mesh_convergence(trial_cases)
    mesh.to_csv(out / "beam_mesh.csv", index=False)
    cases += trial_cases
    df = chain_convergence(cases, segments=segments, progress=progress)
    df.to_csv(out / "convergence.csv", index=False)
    chain_plot(df, out / "chain_convergence.png")
    rod_plot(rod, out / "rod_convergence.png")
    summ = summary(df)
    summ.to_csv(out / "convergence_summary.csv", index=False)
    cont = cont_summ = None
    if continuum_elements:
        cont = continuum_convergence(cases, tuple(continuum_elements), progress=progress)
        cont.to_csv(out / "continuum_convergence.csv", index=False)
        cont_summ = continuum_summary(cont)
        cont_summ.to_csv(out / "continuum_summary.csv", index=False)
        continuum_plot(cont, out / "continuum_convergence.png")
    return ConvergenceResult(rod, df, summ, exceedances(df), order, mesh, beam_mesh_summary(mesh),
                             exceedances(df, "dual_length+twist"), cont, cont_summ)
