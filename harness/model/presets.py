"""Named model configurations (presets), selectable with ``--preset``.

A preset is a complete :class:`ModelConfig`; ``--set`` overrides apply on
top of it, so ``--preset paper --set modulus_pa=3e9`` is the naive case with
another modulus.
"""

from __future__ import annotations

from ..registry import Registry
from .config import ModelConfig

PRESETS: Registry[ModelConfig] = Registry("model preset")

PRESETS.add("default", ModelConfig(), ("default",),
            "the paper's chain (K = 2EI/L, greedy 5 mm links) with each cane's own stated material")
PRESETS.add("paper", ModelConfig(modulus_pa=4.57e9, diameter_factor=1.0, stiffness_formula="paper",
                                 discretization="greedy", max_deviation_m=0.005),
            ("paper", "naive"),
            "the paper's naive case: E = 4.57 GPa for every cane, measured diameters, K = 2EI/L, greedy 5 mm chain")
PRESETS.add("beam-consistent", ModelConfig(stiffness_formula="dual_length", discretization="uniform", segments=20),
            ("converged",),
            "a chain that converges to the continuum beam: dual-length stiffness on 20 uniform links "
            "(within 1 % of the beam on 53 of 54 bundled push points)")


def get_preset(name: str) -> ModelConfig:
    return PRESETS[name]
