"""Studies with the beam reference: its own convergence, and how the chain's
stiffness converges (or not) to the beam's with segment count and formula.

All in small deflection with gravity off, where closed forms exist: the
chain's linear stiffness 1/(u^T J K^-1 J^T u) (Pinocchio) against the rod's
F/d at a 1e-7 m push.
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
FORMULAS = ("paper", "end_angle", "dual_length")
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
    if formula == "paper":
        return (n + 1) * (2 * n + 1) / (2 * 2 * n**2)
    if formula == "end_angle":
        return (n + 1) * (2 * n + 1) / (2 * 1 * n**2)
    if formula == "dual_length":
        return 1 + 1 / (2 * n**2)
    return float("nan")


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
        k_beam = BeamStatic(build_chain(cane, pid, base), n_elements=96).linear_stiffness()
        k_beam_rigid_twist = BeamStatic(build_chain(cane, pid, base.replace(poisson_ratio=-0.99)),
                                        n_elements=96).linear_stiffness()
        for disc in discretizations:
            for formula in formulas:
                for n in segments:
                    cfg = base.replace(segments=n, stiffness_formula=formula, discretization=disc)
                    ch = build_chain(cane, pid, cfg)
                    k = PinocchioStatic(ch).linear_stiffness()
                    rows.append({"trial": tid, "cane": cane.id, "discretization": disc, "formula": formula,
                                 "segments": n, "k_chain": k, "k_beam": k_beam,
                                 "k_beam_rigid_twist": k_beam_rigid_twist, "ratio": k / k_beam,
                                 "compliance_ratio": k_beam / k})
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

    def to_df(self) -> pd.DataFrame:
        return self.chains


def converge(out: Path, trials: str | None = None, segments: tuple[int, ...] = SEGMENTS,
             progress: Callable[[int, int, str], None] | None = None) -> ConvergenceResult:
    """Run the convergence study on the two straight cantilevers and the bundled canes; write CSVs and figures."""
    from canebench.reports.convergence import chain_plot, exceedances, rod_plot, summary

    from ..data.dataset import bundled_dataset, load_dataset

    out.mkdir(parents=True, exist_ok=True)
    rod = rod_convergence()
    rod.to_csv(out / "rod_convergence.csv", index=False)
    order = -float(np.polyfit(np.log(rod.elements[:-2]), np.log(rod.rel_error[:-2]), 1)[0])
    cases = [("uniform-cantilever", straight_cantilever(False), "tip"),
             ("tapered-cantilever", straight_cantilever(True), "tip")]
    cases += [(t.id, t.cane, t.push_id) for t in load_dataset(bundled_dataset(), trials)]
    df = chain_convergence(cases, segments=segments, progress=progress)
    df.to_csv(out / "convergence.csv", index=False)
    chain_plot(df, out / "chain_convergence.png")
    rod_plot(rod, out / "rod_convergence.png")
    summ = summary(df)
    summ.to_csv(out / "convergence_summary.csv", index=False)
    return ConvergenceResult(rod, df, summ, exceedances(df), order)
