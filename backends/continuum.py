"""What the continuum backends share: the rod's stations on the chain's continuum.

The continuum backends (``mujoco_rod``, ``exudyn_beam`` and the PyElastica
plugin) ignore the chain's links, joints and stiffness formula: like the
``beam`` reference they take ``chain.rod`` (the smoothed centreline, its arc
length, the fitted diameter line with its factor and floor, E, density,
Poisson ratio), the probe's arc length ``chain.meta["s_push"]``, its
direction and gravity, and discretize that continuum with their own
elements. This module places the nodes (uniform spacing on either side of
the probe, a node exactly at the probe) and integrates the section
properties the engines need per node or per element.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from canebench.model.chain import Chain, RodGeometry

_XG, _WG = np.polynomial.legendre.leggauss(8)


@dataclass(frozen=True)
class Stations:
    """Nodes of a discretized rod, base (clamped) first.

    Attributes
    ----------
    s : (n+1,) array
        Arc length of every node; ``s[push]`` is the probe's arc length exactly.
    points : (n+1, 3) array
        The nodes on the smoothed centreline (world, rest). Consecutive nodes
        are joined by straight elements, so the discrete rest shape is the
        centreline's inscribed polygon (chord error O(h^2) where it turns).
    push : int
        Index of the node at the probe.
    """

    s: np.ndarray
    points: np.ndarray
    push: int

    @property
    def n_elements(self) -> int:
        return len(self.s) - 1

    @property
    def lengths(self) -> np.ndarray:
        return np.linalg.norm(np.diff(self.points, axis=0), axis=1)

    @property
    def tangents(self) -> np.ndarray:
        """(n, 3) unit direction of every element."""
        d = np.diff(self.points, axis=0)
        return d / np.linalg.norm(d, axis=1, keepdims=True)


def rod_of(chain: Chain) -> RodGeometry:
    if chain.rod is None:
        raise ValueError("chain carries no rod geometry (built without build_chain): a continuum backend needs it")
    return chain.rod


#: the cane beyond the probe is dropped when shorter than this fraction of an element (it would be one
#: degenerate element: a 1e-6 L tip element made MuJoCo's rod warn mjWARN_INERTIA at every step)
TIP_STUB = 0.01


def stations(chain: Chain, n_elements: int) -> Stations:
    """``n_elements`` elements over the whole cane, as uniform as a node at the probe allows.

    The probe's span [0, s_push] gets round(n s_push / L) elements (at least
    one), the rest of the cane the remainder (at least one if the probe is
    not at the tip). A rest of the cane shorter than ``TIP_STUB`` of the
    probe span's element is dropped: it carries no load but its own weight
    (less than 1 % of one element's).
    """
    g = rod_of(chain)
    n = int(n_elements)
    if n < 2:
        raise ValueError(f"a continuum rod needs at least 2 elements, got {n}")
    L = float(g.s[-1])
    sp = float(chain.meta["s_push"])
    beyond = L - sp > TIP_STUB * sp / max(1, round(n * sp / L))
    n1 = int(np.clip(round(n * sp / L), 1, n - 1 if beyond else n))
    n2 = n - n1 if beyond else 0
    s = np.linspace(0.0, sp, n1 + 1)
    if n2:
        s = np.concatenate([s, np.linspace(sp, L, n2 + 1)[1:]])
    pts = np.column_stack([np.interp(s, g.s, g.points[:, k]) for k in range(3)])
    return Stations(s, pts, n1)


def ei(g: RodGeometry, s: np.ndarray) -> np.ndarray:
    """Bending rigidity EI(s) (N m^2) of the solid circular section."""
    return g.modulus * np.pi * g.diameter(s) ** 4 / 64.0


def area(g: RodGeometry, s: np.ndarray) -> np.ndarray:
    return np.pi * g.diameter(s) ** 2 / 4.0


def integral(f, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """int_a^b f(s) ds per interval, 8-point Gauss-Legendre (exact to rounding for the
    polynomial integrands here: the diameter line is linear, so 1/EI is smooth)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    s = a[:, None] + (_XG[None, :] + 1) / 2 * (b - a)[:, None]
    return (np.asarray(f(s.ravel())).reshape(s.shape) @ _WG) * (b - a) / 2


def dual_compliance(g: RodGeometry, st: Stations) -> np.ndarray:
    """Bending compliance int ds / EI(s) over the dual segment of every node
    0..n-1 (from the middle of the previous element to the middle of the next;
    node 0, the clamp, from the base): the beam-consistent rotational spring of
    a node is 1 / this (reference-values sec. 5, Voronoi placement)."""
    mids = 0.5 * (st.s[:-1] + st.s[1:])
    lo = np.concatenate([[st.s[0]], mids[:-1]])
    return integral(lambda s: 1.0 / ei(g, s), lo, mids)


def element_mass(g: RodGeometry, st: Stations) -> np.ndarray:
    """Mass (kg) of every element: density times the integrated section area."""
    return g.density * integral(lambda s: area(g, s), st.s[:-1], st.s[1:])
