"""Joint stiffness formulas: named, selectable, extensible.

A formula maps per-link bending rigidity EI_j and length l_j to the stiffness
of the joint *preceding* link j (both bending axes get the same value). It may
also use a :class:`StiffnessContext` with the continuous EI(s) of the cane and
the nodes' arc lengths. Register a new one with :func:`register_formula`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..errors import InputError
from ..registry import Registry


@dataclass(frozen=True)
class StiffnessContext:
    """What a formula may know beyond per-link EI and length."""

    nodes_s: np.ndarray  # arc length of each node (n + 1)
    ei_of_s: Callable[[np.ndarray], np.ndarray]  # continuous EI(s)


Formula = Callable[[np.ndarray, np.ndarray, "StiffnessContext | None"], np.ndarray]
FORMULAS: Registry[Formula] = Registry("stiffness formula")
_XG, _WG = np.polynomial.legendre.leggauss(8)


def register_formula(name: str, description: str, tags: tuple[str, ...] = ()) -> Callable[[Formula], Formula]:
    """Register a formula under ``name`` (a duplicate name is an error)."""
    return FORMULAS.register(name, tags, description)


@register_formula("paper", "K = 2EI/L of the following link (Kolano et al.; the default, for reproduction)", ("paper",))
def paper(ei: np.ndarray, length: np.ndarray, ctx: StiffnessContext | None = None) -> np.ndarray:
    # Paper Sec. III-C: tip deflection of a cantilever under an end moment,
    # v = ML^2/(2EI), equated with v = ML/K.
    return 2.0 * ei / length


@register_formula("end_angle", "K = EI/L of the following link (Jacob et al.; Munn): matches the end angle")
def end_angle(ei: np.ndarray, length: np.ndarray, ctx: StiffnessContext | None = None) -> np.ndarray:
    return ei / length


def _integral_inv_ei(ctx: StiffnessContext, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """int_a^b ds / EI(s) by 8-point Gauss-Legendre per interval."""
    s = a[:, None] + (_XG[None, :] + 1) / 2 * (b - a)[:, None]
    f = 1.0 / np.asarray(ctx.ei_of_s(s.ravel())).reshape(s.shape)
    return (f @ _WG) * (b - a) / 2


@register_formula(
    "dual_length",
    "beam-consistent (Voronoi): each joint carries the compliance of its dual segment, from the middle of the "
    "previous link to the middle of the next (the clamp joint: from the base); K_j = 1 / int ds/EI(s) over it, "
    "integrated on the continuous EI(s) when known, else with each half-link's EI (reference-values sec. 5)",
)
def dual_length(ei: np.ndarray, length: np.ndarray, ctx: StiffnessContext | None = None) -> np.ndarray:
    if ctx is not None:
        mids = 0.5 * (ctx.nodes_s[:-1] + ctx.nodes_s[1:])
        bounds = np.concatenate([[ctx.nodes_s[0]], mids])
        return 1.0 / _integral_inv_ei(ctx, bounds[:-1], bounds[1:])
    half = length / (2.0 * ei)  # compliance of half a link
    comp = half.copy()
    comp[1:] += half[:-1]
    return 1.0 / comp


def joint_stiffness(name: str, ei: np.ndarray, length: np.ndarray, ctx: StiffnessContext | None = None,
                    source: str = "model configuration") -> np.ndarray:
    """Stiffness (N m/rad) of each joint by the named formula."""
    if name not in FORMULAS:
        raise InputError(source, "stiffness_formula", f"unknown formula {name!r}; known: {', '.join(sorted(FORMULAS))}")
    return np.asarray(FORMULAS[name](np.asarray(ei, float), np.asarray(length, float), ctx), dtype=float)
