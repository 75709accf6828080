"""Beam backend: the geometrically exact Kirchhoff rod (:mod:`canebench.backends.rod`)
of the cane the chain was cut from, probed by the same protocol.

It takes the chain's continuum (``chain.rod``: the smoothed centreline, the
same fitted diameter line, E, density, Poisson ratio), the probe point's arc
length, direction and gravity, and solves the rod's static equilibrium at
every protocol displacement (force controlled so the probe point sits at
each 0.5 mm step). It ignores the chain's links, joints and stiffness
formula: it is the reference they approximate.

Rest tangents come from a cubic spline through the smoothed centreline
(chord-length parameter); the rest probe point is the rod's own.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.interpolate import CubicSpline

from canebench.backends import rod as rodmod
from canebench.model.chain import Chain
from canebench.probe.protocol import Protocol

from .base import StaticBackend, StaticModel


def rod_spec(chain: Chain, gravity: bool = True) -> rodmod.RodSpec:
    """The :class:`RodSpec` of a chain's continuum."""
    g = chain.rod
    if g is None:
        raise ValueError("chain carries no rod geometry (built without build_chain)")
    if len(g.s) >= 3:
        spline = CubicSpline(g.s, g.points, axis=0)
        deriv = spline.derivative()

        def tangent(s: np.ndarray) -> np.ndarray:
            return deriv(np.clip(s, g.s[0], g.s[-1]))
    else:
        t = (g.points[-1] - g.points[0]) / np.linalg.norm(g.points[-1] - g.points[0])

        def tangent(s: np.ndarray) -> np.ndarray:
            return np.tile(t, (len(np.atleast_1d(s)), 1))

    def ei(s: np.ndarray) -> np.ndarray:
        return g.modulus * np.pi * g.diameter(s) ** 4 / 64.0

    def rho_a(s: np.ndarray) -> np.ndarray:
        return g.density * np.pi * g.diameter(s) ** 2 / 4.0

    return rodmod.RodSpec(float(g.s[-1]), tangent, ei, rho_a, g.poisson_ratio, g.points[0].copy(),
                          np.asarray(chain.gravity, float) if gravity else np.zeros(3))


class BeamStatic(StaticModel):
    def __init__(self, chain: Chain, n_elements: int | None = None) -> None:
        n = n_elements or int(chain.meta.get("config", {}).get("beam_elements", 48))
        self.rod = rodmod.Rod(rod_spec(chain), float(chain.meta["s_push"]), chain.direction, n)

    def solve(self, displacement: float) -> float:
        return self.rod.solve_displacement(displacement)

    def linear_stiffness(self) -> float:
        return self.rod.linear_stiffness()


class BeamBackend(StaticBackend):
    name = "beam"
    tags = ("static", "reference", "continuum")
    engine_module = "scipy"

    @classmethod
    def engine_version(cls) -> str:
        from canebench import __version__

        return f"canebench.backends.rod {__version__}"

    def settings(self, proto: Protocol) -> dict[str, Any]:
        return {
            "engine": "beam (canebench.backends.rod)",
            "version": self.engine_version(),
            "integrator": "shooting: RK4 on the Kirchhoff rod equations, Newton on m(0) and F",
            "dt": None,
            "springs": "continuum: EI(s) bending, GJ = EI/(1+nu) torsion",
            "damping": "n/a (static)",
            "pid": "n/a: displacement imposed exactly at each protocol step",
            "why": "geometrically exact reference every chain approximates",
        }

    def build(self, chain: Chain) -> BeamStatic:
        return BeamStatic(chain)
