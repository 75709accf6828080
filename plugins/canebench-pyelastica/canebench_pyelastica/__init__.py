"""canebench backend plugin: the cane's continuum as a PyElastica Cosserat rod.

Registered only through the ``canebench.backends`` entry point (``pyelastica``);
canebench never imports this package.

Model (what it takes from the harness: ``chain.rod``, the probe's arc length,
direction and gravity; not the chain's links, joints or stiffness formula):

* **Rod**: ``CosseratRod`` with ``n_elements`` straight elements on the
  smoothed centreline, uniform on either side of a node exactly at the probe
  (the same stations as canebench's other continuum backends,
  :func:`canebench.backends.continuum.stations`). Directors: d3 along each
  element, d1 carried from the base by parallel transport; rest curvature and
  rest strains are those of this configuration (``rest_kappa = kappa``,
  ``rest_sigma = sigma``), so the rest shape is stress-free.
* **Taper**: one radius per element, the fitted diameter line at the
  element's middle (PyElastica takes a radius array: EI, GJ = EI / (1 + nu)
  with shear modulus E / (2 (1 + nu)), EA and shear 27/28 G A per element;
  the bending stiffness at an interior node is PyElastica's length-weighted
  average of its two elements').
* **Clamp**: PyElastica clamps a rod by fixing its first node and the
  director of its first element (``OneEndFixedBC``), which makes the whole
  first element the clamp. As for the MuJoCo rod, the clamped element is a
  *stub* of length ``STUB`` x h below the base along the base tangent, so the
  cane's base is the first node free to bend, with the beam-consistent
  rotational stiffness EI / ((stub + h) / 2) ~ 2 EI / h.
* **Probe**: the node at the probe is constrained along the probe direction
  only (a ``ConstraintBase`` that projects its position and velocity); the
  force holding it there is minus the rod's internal and external force on
  that node along the probe direction, at equilibrium.
* **Gravity**: dead loads, each node carrying half of its elements' physical
  weight (density x the section area at the element's middle x length).

Statics by damped relaxation (why not a dynamic backend: PyElastica is an
explicit integrator whose stable step on a cane is a few microseconds; the
harness protocol's 90 s of simulated push would be ~10^7 steps):

* PositionVerlet on a pseudo-time with unit step and *fictitious* masses and
  rotational inertias, each the Gershgorin bound of its row of the rod's
  stiffness (so every mode is stable at the unit step and the fast modes all
  sit near it). Masses do not enter the static answer; gravity uses the
  physical ones.
* Viscous damping of all velocities by exp(-gamma) per step, gamma adapted
  every ``CHUNK`` steps to twice the Rayleigh-quotient frequency of the
  last chunk's motion (Underwood's adaptive dynamic relaxation; the motion
  is soon dominated by the slowest mode, which is then damped near
  critically).
* Each protocol step starts from the previous equilibrium, its positions
  extrapolated linearly in the displacement (directors kept), at rest.
* Converged when, twice in a row, the probe force changes by less than
  ``RTOL`` of itself over a chunk and the change still to come, estimated
  from the ratio of the last two chunks' changes (geometric convergence of
  the slowest mode: |dF| q / (1 - q)), is below that too; past ``MAX_STEPS``
  steps the solve raises, which fails the trial with the reason.
"""

from __future__ import annotations

import importlib.metadata
from typing import Any

import numpy as np

from canebench.backends import continuum as cont
from canebench.backends.base import StaticBackend, StaticModel

#: default element count over the whole cane (README of this package: measured convergence)
ELEMENTS = 40
#: clamped stub element below the base, as a fraction of the first element's length
STUB = 0.01
#: relaxation steps between convergence checks (and damping updates)
CHUNK = 100
#: converged when the probe force's change over a chunk, and the change still to come estimated from the last
#: two (geometric convergence), are both below this relative to the force, twice in a row
RTOL = 1e-6
#: most relaxation steps per solve
MAX_STEPS = 2_000_000
#: bounds of the adaptive damping rate per (unit) step
GAMMA_MIN, GAMMA_MAX = 1e-5, 0.5


def _frames(P: np.ndarray) -> np.ndarray:
    """(3, 3, n) PyElastica directors (rows d1, d2, d3; d3 along each element), d1 parallel-transported."""
    d = np.diff(P, axis=0)
    t = d / np.linalg.norm(d, axis=1, keepdims=True)
    ref = np.array([1.0, 0.0, 0.0]) if abs(t[0, 0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    n1 = ref - (ref @ t[0]) * t[0]
    D = np.empty((3, 3, len(t)))
    for e in range(len(t)):
        n1 = n1 - (n1 @ t[e]) * t[e]
        n1 /= np.linalg.norm(n1)
        D[0, :, e], D[1, :, e], D[2, :, e] = n1, np.cross(t[e], n1), t[e]
    return D


class ElasticaStatic(StaticModel):
    """The cane's continuum as a PyElastica Cosserat rod, solved for static equilibrium by damped relaxation."""

    def __init__(self, chain: Any, n_elements: int = ELEMENTS, rtol: float = RTOL) -> None:
        import elastica as ea
        from elastica.boundary_conditions import ConstraintBase, OneEndFixedBC
        from elastica.external_forces import NoForces

        g = cont.rod_of(chain)
        st = cont.stations(chain, n_elements)
        h = st.lengths
        t0 = st.tangents[0]
        P = np.vstack([st.points[0] - STUB * h[0] * t0, st.points])  # stub node, then the cane's nodes
        mids = 0.5 * (st.s[:-1] + st.s[1:])
        r_el = g.diameter(mids) / 2
        r = np.concatenate([[r_el[0]], r_el])
        self.k = st.push + 1  # probe node (after the stub node)
        self.u = np.asarray(chain.direction, float) / np.linalg.norm(chain.direction)
        self.rtol = float(rtol)

        # physical dead loads: half of each element's weight on each of its nodes (the stub weighs nothing)
        m_el = g.density * np.pi * r_el**2 * h
        W = np.zeros(len(P))
        W[1:-1] += m_el / 2
        W[2:] += m_el / 2
        weights = np.outer(np.asarray(chain.gravity, float), W)  # (3, nodes)

        class Gravity(NoForces):
            def __init__(self, w: np.ndarray, **kw: Any) -> None:
                super().__init__(**kw)
                self.w = w

            def apply_forces(self, system: Any, time: Any = 0.0) -> None:
                system.external_forces += self.w

        model = self

        class ProbeConstraint(ConstraintBase):
            """Holds the probe node's coordinate along ``u`` at ``model.target``; free across it."""

            def constrain_values(self, system: Any, time: Any) -> None:
                p = system.position_collection[:, model.k]
                p += (model.target - p @ model.u) * model.u

            def constrain_rates(self, system: Any, time: Any) -> None:
                v = system.velocity_collection[:, model.k]
                v -= (v @ model.u) * model.u

        class Sim(ea.BaseSystemCollection, ea.Constraints, ea.Forcing):
            pass

        D = _frames(P)
        L = float(np.sum(np.linalg.norm(np.diff(P, axis=0), axis=1)))
        E, nu = g.modulus, g.poisson_ratio
        sim = Sim()
        rod = ea.CosseratRod.straight_rod(len(P) - 1, P[0].copy(), D[2, :, 0].copy(), D[0, :, 0].copy(), L, r,
                                          g.density, youngs_modulus=E, shear_modulus=E / (2 * (1 + nu)),
                                          position=P.T.copy(), directors=D.copy())
        rod.rest_kappa[:] = rod.kappa  # stress-free rest shape: the discretized centreline
        rod.rest_sigma[:] = rod.sigma
        sim.append(rod)
        sim.constrain(rod).using(OneEndFixedBC, constrained_position_idx=(0,), constrained_director_idx=(0,))
        sim.constrain(rod).using(ProbeConstraint)
        if np.any(weights):
            sim.add_forcing_to(rod).using(Gravity, w=weights)
        self.target = float(P[self.k] @ self.u)
        self.x0 = self.target
        sim.finalize()
        self.sim, self.rod = sim, rod
        self.stepper = ea.PositionVerlet()
        self._fictitious_inertia()
        self._history: list[tuple[float, np.ndarray, np.ndarray]] = [
            (0.0, rod.position_collection.copy(), rod.director_collection.copy())]
        self.time = 0.0
        self.steps = 0
        self.extras = {"pyelastica_elements": int(n_elements), "relaxation_steps": 0}

    def _fictitious_inertia(self) -> None:
        """Masses and rotational inertias at the Gershgorin bound of each row of the stiffness, for a unit step."""
        rod = self.rod
        sh = np.array([rod.shear_matrix[i, i, :] for i in range(3)]).max(axis=0)  # (elements,) EA or alpha GA
        bt = np.array([rod.bend_matrix[i, i, :] for i in range(3)]).max(axis=0)  # (voronoi,) EI or GJ
        h, lv = rod.rest_lengths, rod.rest_voronoi_lengths
        kn = np.zeros(len(h) + 1)  # translational rows: each element couples its two nodes (and rotations)
        kn[:-1] += 4 * sh / h
        kn[1:] += 4 * sh / h
        kr = 2 * sh * h  # rotational rows: shear couples the element's rotation to its nodes ...
        kr[:-1] += 4 * bt / lv  # ... and bending/twist to its neighbours
        kr[1:] += 4 * bt / lv
        safety = 2.0  # omega_max * dt <= sqrt(4 / safety) < 2 (PositionVerlet's limit)
        rod.mass[:] = safety * kn / 4
        J = safety * kr / 4
        inv = np.zeros_like(rod.inv_mass_second_moment_of_inertia)
        for i in range(3):
            inv[i, i, :] = 1.0 / J
        rod.inv_mass_second_moment_of_inertia[:] = inv
        self._m = rod.mass.copy()

    def _force(self) -> float:
        """Force along u that holds the probe node: minus the rod's own internal and external force on it."""
        rod = self.rod
        return float(-(rod.internal_forces[:, self.k] + rod.external_forces[:, self.k]) @ self.u)

    def _predict(self, d: float) -> None:
        """Start from the last equilibrium, its positions extrapolated linearly in the displacement (directors
        kept: extrapolating them too made the relaxation drift on b1c1t1 past 15 mm), at rest."""
        rod = self.rod
        d1, x1, Q1 = self._history[-1]
        if len(self._history) >= 2 and d1 != self._history[-2][0]:
            d0, x0, _ = self._history[-2]
            rod.position_collection[:] = x1 + (d - d1) / (d1 - d0) * (x1 - x0)
        else:
            rod.position_collection[:] = x1
        rod.director_collection[:] = Q1
        rod.velocity_collection[:] = 0.0
        rod.omega_collection[:] = 0.0

    def solve(self, displacement: float) -> float:
        rod, sim, step = self.rod, self.sim, self.stepper.step
        self._predict(float(displacement))
        self.target = self.x0 + float(displacement)
        free = np.ones(rod.position_collection.shape[1], bool)
        free[0] = False
        gamma = GAMMA_MAX
        F_prev, dF_prev, calm, n = None, 0.0, 0, 0
        x_prev = rod.position_collection.copy()
        R_prev = None
        while n < MAX_STEPS:
            a = np.exp(-gamma)
            for _ in range(CHUNK):
                self.time = step(sim, self.time, 1.0)
                rod.velocity_collection *= a
                rod.omega_collection *= a
            n += CHUNK
            x = rod.position_collection.copy()
            R = rod.internal_forces + rod.external_forces
            if R_prev is not None:  # Rayleigh quotient of the chunk's motion: omega^2 = -dx.dR / dx.M dx
                dx = (x - x_prev)[:, free]
                dR = (R - R_prev)[:, free]
                den = float(np.sum(self._m[free] * (dx * dx)))
                num = -float(np.sum(dx * dR))
                if den > 0 and num > 0:
                    gamma = float(np.clip(2.0 * np.sqrt(num / den), GAMMA_MIN, GAMMA_MAX))
            x_prev, R_prev = x, R.copy()
            F = self._force()
            if not np.isfinite(F) or not np.all(np.isfinite(x)):
                raise FloatingPointError("PyElastica relaxation diverged (non-finite state)")
            if F_prev is not None:
                dF = F - F_prev
                # the force converges geometrically (ratio q per chunk) once the slowest mode dominates: what is
                # left is about |dF| q / (1 - q); a ratio >= 1 or of changing sign means not yet
                q = dF / dF_prev if dF_prev else 0.0
                left = abs(dF) * q / (1.0 - q) if 0.0 <= q < 1.0 else np.inf
                if abs(dF) <= self.rtol * max(abs(F), 1e-9) and left <= self.rtol * max(abs(F), 1e-9):
                    calm += 1
                    if calm >= 2:
                        break
                else:
                    calm = 0
                dF_prev = dF
            F_prev = F
        else:
            raise RuntimeError(f"PyElastica damped relaxation did not converge in {MAX_STEPS} steps "
                               f"(probe force still changing by {abs(F - F_prev):.3g} N)")
        self.steps += n
        self.extras["relaxation_steps"] = self.steps
        self._history = self._history[-1:] + [(float(displacement), rod.position_collection.copy(),
                                               rod.director_collection.copy())]
        return F


class PyElasticaBackend(StaticBackend):
    """PyElastica's Cosserat rod of the cane's continuum, static equilibrium by damped relaxation."""

    name = "pyelastica"
    tags = ("static", "continuum", "plugin")
    engine_module = "elastica"
    supports_twist = True  # a continuum: torsion always (GJ = EI / (1 + nu)), whatever the chain's joints

    def __init__(self, n_elements: int = ELEMENTS) -> None:
        self.n_elements = int(n_elements)

    @classmethod
    def engine_version(cls) -> str:
        return importlib.metadata.version("pyelastica")

    def settings(self, protocol: Any) -> dict[str, Any]:
        return {
            "engine": "pyelastica",
            "version": self.engine_version(),
            "model": (f"CosseratRod, {self.n_elements} elements + clamped stub ({STUB:g} h), radius per element "
                      "(diameter line at the element's middle)"),
            "integrator": (f"damped relaxation: PositionVerlet, unit pseudo-time step, Gershgorin fictitious "
                           f"inertia, adaptive viscous damping; converged at {RTOL:g} relative change of the "
                           f"probe force over two {CHUNK}-step chunks"),
            "dt": None,
            "springs": "continuum: Cosserat rod (bend, twist, shear, stretch)",
            "damping": "n/a (static)",
            "pid": "n/a: displacement imposed exactly at each protocol step (probe node constrained along the probe)",
            "why": "third continuum engine, as a plugin; an explicit rod would need ~1e7 steps for a dynamic push",
        }

    def build(self, chain: Any) -> ElasticaStatic:
        return ElasticaStatic(chain, self.n_elements)
