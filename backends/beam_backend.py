"""Beam backend: the geometrically exact Kirchhoff rod (:mod:`canebench.backends.rod`)
of the cane the chain was cut from, probed by the same protocol.

It takes the chain's continuum (``chain.rod``: the smoothed centreline, the
same fitted diameter line, E, density, Poisson ratio), the probe point's arc
length, direction and gravity, and solves the rod's static equilibrium at
every protocol displacement (force controlled so the probe point sits at
each 0.5 mm step). It ignores the chain's links, joints and stiffness
formula: it is the reference they approximate.

Trustworthy by construction:

* Rest shape. The rod's stress-free centreline is the smoothed polyline
  itself (:func:`canebench.backends.rod.polyline_spec`: straight segments,
  a rest-curvature kink at every vertex, folds included), integrated with
  moment-matched coefficients, so the rest probe point is the centreline's
  point at ``s_push`` at every mesh (no spline through the vertices: a
  cubic spline overshoots at the hairpins some digitized canes have).
* Mesh. :class:`BeamStatic` starts at ``beam_elements`` (config, 48; plus a
  node at each vertex where the centreline turns by more than 10 degrees,
  ``Rod.KINK_NODE_DEG``, so 48 to 52 elements on the bundled canes) and
  doubles the mesh (every element halved) until the small-deflection
  stiffness changes by at most ``rtol`` = 1e-4 between successive meshes;
  the sweep then runs on the coarser of the last two (whose error the
  change estimates). Past ``max_elements`` (3072) the build fails, which
  fails the trial with the reason. The final element count and the relative
  change are in :attr:`BeamStatic.extras`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from canebench.backends import rod as rodmod
from canebench.model.chain import Chain
from canebench.probe.protocol import Protocol

from .base import StaticBackend, StaticModel

#: default relative change of the linear stiffness between successive meshes
#: (each twice the last) at which the mesh is accepted
RTOL = 1e-4
#: most elements solved on the way (the accepted mesh has at most half)
MAX_ELEMENTS = 3072


def rod_spec(chain: Chain, gravity: bool = True) -> rodmod.RodSpec:
    """The :class:`RodSpec` of a chain's continuum: the smoothed centreline as
    a polyline rod (its ``tangent`` is the segment direction)."""
    g = chain.rod
    if g is None:
        raise ValueError("chain carries no rod geometry (built without build_chain)")

    def ei(s: np.ndarray) -> np.ndarray:
        return g.modulus * np.pi * g.diameter(s) ** 4 / 64.0

    def rho_a(s: np.ndarray) -> np.ndarray:
        return g.density * np.pi * g.diameter(s) ** 2 / 4.0

    spec = rodmod.polyline_spec(g.points, ei, rho_a, g.poisson_ratio,
                                np.asarray(chain.gravity, float) if gravity else np.zeros(3))
    spec.base_compliance = float(chain.base_compliance)  # root_compliance effect: a base spring
    return spec


class MeshNotConverged(RuntimeError):
    """The beam's stiffness still changes by more than the tolerance at the element cap."""


class BeamStatic(StaticModel):
    """The rod of ``chain`` on a mesh refined until its linear stiffness converges.

    Parameters
    ----------
    chain : Chain
    n_elements : int, optional
        First mesh (default: the config's ``beam_elements``, 48).
    rtol : float, optional
        Largest relative change of the linear stiffness between the accepted
        mesh and the mesh twice as fine (default: config ``beam_rtol`` if
        present, else :data:`RTOL`).
    max_elements : int, optional
        Most elements solved (default: config ``beam_max_elements`` if
        present, else :data:`MAX_ELEMENTS`); not converged by then raises
        :class:`MeshNotConverged`.

    Attributes
    ----------
    rod : Rod
        The accepted mesh, used for the sweep.
    extras : dict
        ``beam_elements``: elements of the accepted mesh; ``beam_rel_error``:
        |k(N) / k(2N) - 1|, the relative change of the linear stiffness from
        the accepted mesh (N) to the mesh twice as fine (2N), an estimate of
        the accepted mesh's discretization error (for RK4, about 16/15 of it).
    mesh_history : list of (int, float)
        (elements, linear stiffness) of every mesh solved.
    """

    def __init__(self, chain: Chain, n_elements: int | None = None, rtol: float | None = None,
                 max_elements: int | None = None) -> None:
        cfg = chain.meta.get("config", {})
        n = int(n_elements or cfg.get("beam_elements", 48))
        rtol = float(rtol if rtol is not None else cfg.get("beam_rtol", RTOL))
        cap = int(max_elements or cfg.get("beam_max_elements", MAX_ELEMENTS))
        rod = rodmod.Rod(rod_spec(chain), float(chain.meta["s_push"]), chain.direction, n)
        k = rod.linear_stiffness()
        self.mesh_history = [(len(rod.h), k)]
        err = float("nan")  # relative change of the last refinement (none yet)
        while True:
            if 2 * len(rod.h) > cap:
                last = (f"the linear stiffness still changed by {err:.2e} (> {rtol:g}) from "
                        f"{self.mesh_history[-2][0]} to {len(rod.h)} elements" if len(self.mesh_history) > 1
                        else f"{len(rod.h)} elements leave no room to refine")
                raise MeshNotConverged(f"beam mesh not converged: {last}, and {2 * len(rod.h)} elements "
                                       f"would exceed the cap of {cap}")
            fine = rod.refined()
            k_fine = fine.linear_stiffness(jacobian=rod.linear_jacobian)  # a chord start: same answer, fewer shots
            self.mesh_history.append((len(fine.h), k_fine))
            err = abs(k / k_fine - 1)
            if err <= rtol:
                break
            rod, k = fine, k_fine
        self.rod = rod
        self._k_linear = k
        self.extras = {"beam_elements": len(rod.h), "beam_rel_error": float(err)}

    def solve(self, displacement: float) -> float:
        return self.rod.solve_displacement(displacement)

    def linear_stiffness(self) -> float:
        """The accepted mesh's small-deflection stiffness (computed while refining)."""
        return self._k_linear


class BeamBackend(StaticBackend):
    name = "beam"
    tags = ("static", "reference", "continuum")
    engine_module = "scipy"
    # not a chain: the rod always has torsion (GJ = EI / (1 + nu)), the reference a twist-jointed chain converges to
    supports_twist = True

    @classmethod
    def engine_version(cls) -> str:
        from canebench import __version__

        return f"canebench.backends.rod {__version__}"

    def settings(self, proto: Protocol) -> dict[str, Any]:
        return {
            "engine": "beam (canebench.backends.rod)",
            "version": self.engine_version(),
            "integrator": "shooting: RK4 on the Kirchhoff rod equations (polyline rest shape, moment-matched "
                          "coefficients), Newton on m(0) and F; mesh doubled from beam_elements until the linear "
                          f"stiffness changes < {RTOL:g} (cap {MAX_ELEMENTS} elements)",
            "dt": None,
            "springs": "continuum: EI(s) bending, GJ = EI/(1+nu) torsion",
            "damping": "n/a (static)",
            "pid": "n/a: displacement imposed exactly at each protocol step",
            "why": "geometrically exact reference every chain approximates",
        }

    def build(self, chain: Chain) -> BeamStatic:
        return BeamStatic(chain)
