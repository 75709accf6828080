"""A minimal canebench backend, installed as a separate package.

``linear`` answers each protocol step with the small-deflection static force
of the chain, F = k d with k = 1 / (u^T J K^-1 J^T u): J from the joint axes
and positions of the rest configuration, K the joint springs; no gravity, no
geometric nonlinearity. It needs nothing but numpy and the chain the harness
hands it.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from canebench.backends.base import StaticBackend, StaticModel


class LinearModel(StaticModel):
    def __init__(self, chain: Any) -> None:
        axes = chain.joint_axes_world()  # (2n, 3), joint order x0, y0, x1, y1, ...
        origins = np.repeat(chain.nodes[:-1], 2, axis=0)
        Ju = np.array([np.cross(a, chain.push_point - o) @ chain.direction for a, o in zip(axes, origins)])
        Ju[2 * (chain.push_link + 1):] = 0.0  # joints beyond the probe link do not move it
        self.k = 1.0 / float(Ju @ (Ju / np.repeat(chain.stiffness, 2)))

    def solve(self, displacement: float) -> float:
        return self.k * displacement

    def linear_stiffness(self) -> float:
        return self.k


class LinearBackend(StaticBackend):
    name = "linear"
    tags = ("static", "linear", "example-plugin")
    engine_module = "numpy"

    def settings(self, protocol: Any) -> dict[str, Any]:
        return {"engine": "numpy", "version": np.__version__, "integrator": "none (linear statics)",
                "dt": None, "springs": "exact, linearised at rest", "damping": "n/a", "pid": "n/a",
                "why": "example plugin: the small-deflection limit of every backend, without gravity"}

    def build(self, chain: Any) -> LinearModel:
        return LinearModel(chain)
