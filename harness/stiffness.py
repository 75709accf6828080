"""Joint stiffness formulas: named, selectable, extensible.

A formula maps per-link bending rigidity EI_j and length l_j to the stiffness
of the joint *preceding* link j (both bending axes get the same value).
Register a new one with :func:`register_formula`.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

Formula = Callable[[np.ndarray, np.ndarray], np.ndarray]
FORMULAS: dict[str, Formula] = {}
DESCRIPTIONS: dict[str, str] = {}


def register_formula(name: str, description: str) -> Callable[[Formula], Formula]:
    def deco(fn: Formula) -> Formula:
        FORMULAS[name] = fn
        DESCRIPTIONS[name] = description
        return fn

    return deco


@register_formula("paper", "K = 2EI/L of the following link (Kolano et al.; the default, for reproduction)")
def paper(ei: np.ndarray, length: np.ndarray) -> np.ndarray:
    # Paper Sec. III-C: tip deflection of a cantilever under an end moment,
    # v = ML^2/(2EI), equated with v = ML/K.
    return 2.0 * ei / length


@register_formula("end_angle", "K = EI/L of the following link (Jacob et al.; Munn): matches the end angle")
def end_angle(ei: np.ndarray, length: np.ndarray) -> np.ndarray:
    return ei / length


@register_formula(
    "dual_length",
    "beam-consistent: each joint is the series spring of the half-links around it, "
    "K_j = 1/(l_{j-1}/(2EI_{j-1}) + l_j/(2EI_j)); clamp joint 2EI_0/l_0 (reference-values sec. 5)",
)
def dual_length(ei: np.ndarray, length: np.ndarray) -> np.ndarray:
    half = length / (2.0 * ei)  # compliance of half a link
    comp = half.copy()
    comp[1:] += half[:-1]
    return 1.0 / comp


def joint_stiffness(name: str, ei: np.ndarray, length: np.ndarray, source: str = "model configuration") -> np.ndarray:
    """Stiffness (N m/rad) of each joint by the named formula."""
    from .errors import InputError

    if name not in FORMULAS:
        raise InputError(source, "stiffness_formula", f"unknown formula {name!r}; known: {', '.join(sorted(FORMULAS))}")
    return np.asarray(FORMULAS[name](np.asarray(ei, float), np.asarray(length, float)), dtype=float)
