"""The one intermediate representation: a serial chain every backend compiles.

``build_chain(cane, push_id, config)`` turns a cane description into rigid
links (solid cylinders) joined by two coincident revolute joints each (two
bending axes perpendicular to the link, no twist), with torsional springs from
a named stiffness formula, plus the probe: a point rigidly attached to one
link and a fixed world direction. All positions are in the world frame of the
rest (unloaded) configuration, z up, base of the cane at its first polyline
point, which is clamped.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..data.cane import CaneDescription, Location
from .config import ModelConfig
from .diameter import fit_diameter
from ..errors import InputError
from .geometry import Curve, chaikin, greedy_discretize, uniform_discretize
from .stiffness import StiffnessContext, joint_stiffness


@dataclass(frozen=True)
class RodGeometry:
    """The continuous rod a chain approximates (for the beam reference).

    ``points`` is the smoothed centreline the chain was cut from, ``s`` its
    arc length; the diameter is the same fitted line (with the same factor
    and floor) the chain evaluates at link midpoints, here continuous.
    """

    points: np.ndarray
    s: np.ndarray
    s_centroid: float
    d_centroid: float
    slope: float  # already multiplied by the diameter factor
    min_diameter: float
    modulus: float
    density: float
    poisson_ratio: float
    #: effects that change the diameter profile (base flare...), applied before the floor
    effects: Any = None
    #: rotational compliance of the base (rad/(N m)) about both bending axes (root_compliance)
    base_compliance: float = 0.0

    def diameter(self, s: np.ndarray) -> np.ndarray:
        s = np.asarray(s, float)
        d = self.d_centroid + self.slope * (s - self.s_centroid)
        if self.effects is not None:
            d = self.effects.diameter(s, d)
        return np.maximum(d, self.min_diameter)


@dataclass(frozen=True)
class Chain:
    """Backend-agnostic pseudo-rigid-body chain (SI units, world rest frame).

    Attributes
    ----------
    nodes : (n+1, 3) array
        Joint positions; node 0 is the clamped base, node n the tip.
    frames : (n, 3, 3) array
        Rest orientation of each link; columns x, y, z with z along the link.
        The two joints preceding link j rotate about its x then its y axis.
    lengths, diameters, masses : (n,) arrays
    inertias : (n, 3) array
        Principal moments about the centre of mass in the link frame.
    stiffness : (n,) array
        Torsional stiffness (N m/rad) of both bending joints preceding each link.
    twist_stiffness : (n,) array or None
        With the ``twist_joint`` model option, a third joint per link about
        the link's own axis (z), after the two bending joints, with this
        stiffness (from GJ = EI / (1 + nu) on the same formula); ``None``: the
        paper's two-joint chain, rigid in torsion.
    damping : float
        Joint damping (N m s/rad), the same for every joint.
    push_link : int
        Index of the link that carries the probe point.
    push_point : (3,) array
        Probe point (world, rest).
    direction : (3,) array
        Unit probe direction (world, fixed during the push).
    gravity : (3,) array
    meta : dict
        Cane id, push point id, configuration, assumptions, warnings.
    """

    nodes: np.ndarray
    frames: np.ndarray
    lengths: np.ndarray
    diameters: np.ndarray
    masses: np.ndarray
    inertias: np.ndarray
    stiffness: np.ndarray
    damping: float
    push_link: int
    push_point: np.ndarray
    direction: np.ndarray
    gravity: np.ndarray
    modulus: float
    meta: dict[str, Any] = field(default_factory=dict)
    rod: RodGeometry | None = None
    twist_stiffness: np.ndarray | None = None
    #: rotational compliance (rad/(N m)) of the base about both bending axes
    #: (root_compliance effect), already in series in ``stiffness[0]``; the
    #: beam reference reads it for its base spring
    base_compliance: float = 0.0

    @property
    def n_links(self) -> int:
        return len(self.lengths)

    @property
    def joints_per_link(self) -> int:
        return 2 if self.twist_stiffness is None else 3

    @property
    def n_dof(self) -> int:
        return self.joints_per_link * self.n_links

    def joint_layout(self) -> list[tuple[int, int]]:
        """(link, local axis index) of every joint in chain order: x, y (, z) per link."""
        return [(j, k) for j in range(self.n_links) for k in range(self.joints_per_link)]

    def joint_stiffness_vector(self) -> np.ndarray:
        """Spring stiffness of every joint in chain order (N m/rad)."""
        if self.twist_stiffness is None:
            return np.repeat(self.stiffness, 2)
        return np.column_stack([self.stiffness, self.stiffness, self.twist_stiffness]).ravel()

    def com(self, j: int) -> np.ndarray:
        """Centre of mass of link ``j`` (world, rest)."""
        return self.nodes[j] + 0.5 * self.lengths[j] * self.frames[j][:, 2]

    def local(self, j: int, point: np.ndarray) -> np.ndarray:
        """Coordinates of a world rest point in link ``j``'s frame (origin at node j)."""
        return self.frames[j].T @ (np.asarray(point) - self.nodes[j])

    def relative_pose(self, j: int) -> tuple[np.ndarray, np.ndarray]:
        """(R, p) of link ``j``'s frame in its parent's (world for j = 0)."""
        if j == 0:
            return self.frames[0].copy(), self.nodes[0].copy()
        rp = self.frames[j - 1]
        return rp.T @ self.frames[j], rp.T @ (self.nodes[j] - self.nodes[j - 1])

    def joint_axes_world(self) -> np.ndarray:
        """(n_dof, 3) rest-configuration joint axes in world, in joint order."""
        return np.stack([self.frames[j][:, k] for j, k in self.joint_layout()])

    def fingerprint(self) -> str:
        """Short hash of everything the physics depends on."""
        h = hashlib.sha256()
        for a in (self.nodes, self.frames, self.lengths, self.diameters, self.masses,
                  self.inertias, self.stiffness, self.push_point, self.direction, self.gravity):
            h.update(np.ascontiguousarray(np.round(a, 12)).tobytes())
        if self.twist_stiffness is not None:
            h.update(np.ascontiguousarray(np.round(self.twist_stiffness, 12)).tobytes())
        h.update(json.dumps([self.damping, self.push_link, self.base_compliance]).encode())
        return h.hexdigest()[:12]


# ---------------------------------------------------------------- building


def cane_curve(cane: CaneDescription, config: ModelConfig) -> Curve:
    """The smoothed centreline (Chaikin only when the polyline is raw)."""
    pts = cane.polyline
    if cane.raw_polyline and config.chaikin_iterations > 0:
        pts = chaikin(pts, config.chaikin_iterations, config.chaikin_strength)
    return Curve.from_points(pts)


def resolve_s(curve: Curve, where: Location, source: str, fld: str) -> float:
    """Arc length of a location given by ``s`` or ``height``."""
    if where.s is not None:
        # 1 mm of slack, as at load: smoothing with other settings than the load check's may shorten the curve
        if where.s > curve.length + 1e-3:
            raise InputError(source, f"{fld}.s", f"{where.s:.4g} m is beyond the cane's length {curve.length:.4g} m")
        return float(min(where.s, curve.length))
    s = curve.s_at_height(float(where.height))
    if s is None:
        z = curve.points[:, 2]
        zmin, zmax = z.min(), z.max()
        if zmax < where.height <= zmax + 1e-3:  # the same 1 mm of slack as at load: the highest point
            return float(curve.s[int(np.argmax(z))])
        if zmin - 1e-3 <= where.height < zmin:
            return float(curve.s[int(np.argmin(z))])
        raise InputError(source, f"{fld}.height",
                         f"{where.height:.4g} m is outside the cane's heights [{zmin:.4g}, {zmax:.4g}] m")
    return s


def _parallel_transport_frames(tangents: np.ndarray) -> np.ndarray:
    """Link frames with z along each tangent, x carried by minimal rotations."""
    frames = np.empty((len(tangents), 3, 3))
    z = tangents[0]
    ref = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = ref - (ref @ z) * z
    x /= np.linalg.norm(x)
    for j, zj in enumerate(tangents):
        x = x - (x @ zj) * zj  # project previous x onto the new normal plane
        x /= np.linalg.norm(x)
        frames[j] = np.column_stack([x, np.cross(zj, x), zj])
    return frames


def probe_direction(azimuth: np.ndarray, tangent: np.ndarray, angle_deg: float) -> np.ndarray:
    """Probe direction: the horizontal azimuth pitched to be perpendicular to
    the cane (what the field crew set by hand), then pitched by ``angle_deg``
    (positive up) for the paper's probe-angle sensitivity."""
    a = np.asarray(azimuth, float)
    a = a / np.linalg.norm(a)
    ez = np.array([0.0, 0.0, 1.0])
    t = np.asarray(tangent, float)
    # u = cos(th) a + sin(th) ez with u . t = 0
    th = np.arctan2(-(a @ t), t[2]) if abs(t[2]) > 1e-12 or abs(a @ t) > 1e-12 else 0.0
    th += np.deg2rad(angle_deg)
    u = np.cos(th) * a + np.sin(th) * ez
    return u / np.linalg.norm(u)


def build_chain(cane: CaneDescription, push_id: str, config: ModelConfig | None = None) -> Chain:
    """Discretize ``cane`` into a :class:`Chain` probed at push point ``push_id``."""
    config = config or ModelConfig()
    src = cane.source
    curve = cane_curve(cane, config)
    pp = cane.push_point(push_id)
    pidx = cane.push_points.index(pp)
    trial_id = f"{cane.id}t{pp.id}"  # as the dataset names trials (b1c2t3)
    fx = config.applied_effects(cane.id, trial_id) if config.effects else None
    s_push = resolve_s(curve, pp.where, src, f"push_points[{pidx}]")
    fixed = (s_push,) if config.node_at_push else ()
    if config.discretization == "uniform":
        n = config.segments or max(config.min_segments, 1)
        nodes_s = uniform_discretize(curve, n, fixed)
    else:
        nodes_s = greedy_discretize(curve, config.max_deviation_m, config.segments, config.min_segments, fixed)
    nodes = curve.at(nodes_s)

    cal_s = np.array([resolve_s(curve, c.where, src, f"calipers[{i}]") for i, c in enumerate(cane.calipers)])
    cal_d = np.array([c.diameter for c in cane.calipers])
    fit = fit_diameter(cal_s, cal_d, config.diameter_factor)
    # the calipers' line must describe the cane from the base to the push point: extrapolated far from
    # calipers that lie well below (or above) the push, a steep line can reach the floor there, and a
    # cane of thread has no stiffness worth reporting (beyond the push, toward the tip, the floor only
    # trims the weight of a line that ends before the cane does: a warning below)
    for s_end in (0.0, s_push):  # a line's lowest value on [0, s_push] is at an end
        d_end = float(fit(s_end))
        if d_end < config.min_diameter_m:
            where = ", ".join(f"{v:.3f}" for v in cal_s)
            raise InputError(src, "calipers", f"their line (least squares, diameter factor {fit.factor:g}) reaches "
                             f"{1e3 * d_end:.1f} mm at s = {s_end:.3f} m, below the "
                             f"{1e3 * config.min_diameter_m:g} mm floor between the base and push point {pp.id} "
                             f"(s = {s_push:.3f} m): calipers at s = {where} m do not describe the cane there; "
                             f"measure it nearer the push points")
    mid_s = 0.5 * (nodes_s[:-1] + nodes_s[1:])  # paper: diameter at the middle of each link
    diam_raw = fit(mid_s)
    if fx is not None and fx.changes_diameter:
        diam_raw = fx.diameter(mid_s, diam_raw)
    clamped = int(np.sum(diam_raw < config.min_diameter_m))
    diam = np.maximum(diam_raw, config.min_diameter_m)

    E = config.modulus_pa if config.modulus_pa is not None else cane.material.flexural_modulus
    if fx is not None:
        E = fx.modulus(E)
    rho = config.density if config.density is not None else cane.material.density
    damping = config.damping if config.damping is not None else cane.material.joint_damping

    link = int(np.clip(np.searchsorted(nodes_s, s_push, side="left") - 1, 0, len(nodes_s) - 2))
    point = curve.at(s_push)
    pitch = config.probe_angle_deg + (fx.probe_pitch_deg() if fx is not None else 0.0)
    t_push = curve.chord_tangent(s_push, config.probe_tangent_window_m)
    u = probe_direction(np.array(pp.direction), t_push, pitch)

    warnings = []
    if clamped:
        warnings.append(f"{clamped} link diameter(s) extrapolated below {config.min_diameter_m} m were clamped")
    meta = {
        "cane": cane.id,
        "push_point": pp.id,
        "source": src,
        "s_push": s_push,
        "cane_length": curve.length,
        "probe_tangent": t_push.tolist(),
        "nodes_s": nodes_s.tolist(),
        "diameter_fit": {"s_centroid": fit.s_centroid, "d_centroid": fit.d_centroid, "slope": fit.slope,
                         "factor": fit.factor},
        "calipers": {"s": cal_s.tolist(), "diameter": cal_d.tolist()},
        "config": config.to_dict(),
        "assumptions": list(cane.provenance.get("assumptions", [])),
        "warnings": warnings,
        "synthetic": bool(cane.provenance.get("synthetic", False)),
    }
    c_root = fx.root_compliance() if fx is not None else 0.0
    rod = RodGeometry(curve.points, curve.s, fit.s_centroid, fit.d_centroid, fit.factor * fit.slope,
                      config.min_diameter_m, float(E), float(rho), config.poisson_ratio,
                      fx if fx is not None and fx.changes_diameter else None, c_root)
    ctx = StiffnessContext(nodes_s, lambda s: rod.modulus * np.pi * rod.diameter(s) ** 4 / 64.0)
    chain = assemble_chain(nodes, diam, E, rho, damping, config.stiffness_formula, link, point, u,
                           config.gravity, meta, src, ctx)
    twist = None
    if config.twist_joint:
        # GJ = E (2I) / (2 (1 + nu)) = EI / (1 + nu): the beam reference's torsion, on the same formula
        gj = lambda s: rod.modulus * np.pi * rod.diameter(s) ** 4 / 64.0 / (1.0 + rod.poisson_ratio)  # noqa: E731
        twist = joint_stiffness(config.stiffness_formula, chain.modulus * np.pi * diam**4 / 64.0
                                / (1.0 + config.poisson_ratio), chain.lengths, StiffnessContext(nodes_s, gj))
    if c_root > 0:
        # root_compliance: a joint pair at the base about the same two axes as the
        # first pair, in series with it, is exactly one pair of springs 1/(1/K0 + c)
        K = chain.stiffness.copy()
        K[0] = 1.0 / (1.0 / K[0] + c_root)
        chain = dataclasses.replace(chain, stiffness=K)
    return dataclasses.replace(chain, rod=rod, twist_stiffness=twist, base_compliance=c_root)


def assemble_chain(nodes: np.ndarray, diameters: np.ndarray, modulus: float, density: float, damping: float,
                   formula: str, push_link: int, push_point: np.ndarray, direction: np.ndarray,
                   gravity: float, meta: dict[str, Any] | None = None, source: str = "<memory>",
                   stiffness_context: StiffnessContext | None = None) -> Chain:
    """Rigid solid-cylinder links between ``nodes`` with springs by ``formula``.

    The physical half of :func:`build_chain`, also used directly to build
    chains from other geometry (the synthetic truth model's fine chain).
    """
    nodes = np.asarray(nodes, float)
    vec = np.diff(nodes, axis=0)
    lengths = np.linalg.norm(vec, axis=1)
    if np.any(lengths < 1e-6):
        raise InputError(source, "polyline", "discretization produced a zero-length link (degenerate polyline)")
    frames = _parallel_transport_frames(vec / lengths[:, None])
    diam = np.asarray(diameters, float)
    I_area = np.pi * diam**4 / 64.0
    K = joint_stiffness(formula, modulus * I_area, lengths, stiffness_context)
    r = diam / 2.0
    masses = density * np.pi * r**2 * lengths
    inertias = np.column_stack([
        masses * (3 * r**2 + lengths**2) / 12.0,
        masses * (3 * r**2 + lengths**2) / 12.0,
        masses * r**2 / 2.0,
    ])
    g = np.array([0.0, 0.0, -float(gravity)])
    return Chain(nodes, frames, lengths, diam, masses, inertias, K, float(damping), int(push_link),
                 np.asarray(push_point, float), np.asarray(direction, float), g, float(modulus), dict(meta or {}))
