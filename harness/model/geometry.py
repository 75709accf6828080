"""Cane centreline geometry: Chaikin smoothing, arc length, greedy discretization.

Implements the paper's Sec. III-B exactly: polylines smoothed with Chaikin
(5 iterations, strength 0.35, as CloudCompare does), then discretized greedily:
start with one link from end to end, query 100 uniform points along the curve,
split at the farthest from the current chain, until the largest distance is at
most 5 mm (or until a requested number of links).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..limits import check_deadline

QUERY_POINTS = 100  # paper: "100 uniform points on the curve were queried"
STRAIGHT_TOL = 1e-6  # m; a curve this close to its chord is treated as straight


def chaikin(points: np.ndarray, iterations: int = 5, strength: float = 0.35) -> np.ndarray:
    """Chaikin corner cutting of an open polyline, end points kept.

    Each segment P0-P1 is replaced by the two points (1-w)P0 + wP1 and
    wP0 + (1-w)P1 with w = ``strength`` (Chaikin's classic value is 0.25).
    """
    p = np.asarray(points, dtype=float)
    w = float(strength)
    for _ in range(iterations):
        if len(p) < 3:
            break
        a, b = p[:-1], p[1:]
        q = (1 - w) * a + w * b
        r = w * a + (1 - w) * b
        inner = np.empty((2 * len(a), 3))
        inner[0::2], inner[1::2] = q, r
        # keep the clamped base and the tip where they are
        p = np.vstack([p[:1], inner[1:-1], p[-1:]])
    return p


@dataclass(frozen=True)
class Curve:
    """A polyline parametrised by arc length ``s`` from the base."""

    points: np.ndarray
    s: np.ndarray

    @classmethod
    def from_points(cls, points: np.ndarray) -> "Curve":
        pts = np.asarray(points, dtype=float)
        seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
        keep = np.concatenate([[True], seg > 1e-12])  # drop exact duplicates
        pts = pts[keep]
        seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
        return cls(pts, np.concatenate([[0.0], np.cumsum(seg)]))

    @property
    def length(self) -> float:
        return float(self.s[-1])

    def at(self, s: np.ndarray | float) -> np.ndarray:
        """Points at arc length(s) ``s`` (clipped to the curve)."""
        s = np.clip(np.asarray(s, dtype=float), 0.0, self.length)
        return np.stack([np.interp(s, self.s, self.points[:, k]) for k in range(3)], axis=-1)

    def tangent(self, s: float) -> np.ndarray:
        """Unit tangent of the segment containing ``s``."""
        i = int(np.clip(np.searchsorted(self.s, s, side="right") - 1, 0, len(self.s) - 2))
        t = self.points[i + 1] - self.points[i]
        return t / np.linalg.norm(t)

    def chord_tangent(self, s: float, half_window: float) -> np.ndarray:
        """Unit chord from ``s - half_window`` to ``s + half_window`` (clipped to the curve).

        A clicked polyline's single segment is off by its points' noise over one gap
        (2 mm over 100 mm is about 1 degree); the chord over a window of a few gaps
        averages that away and, being centred, is off the true tangent only by the
        change in curvature across the window. ``half_window = 0`` is :meth:`tangent`.
        """
        if half_window <= 0:
            return self.tangent(s)
        a, b = max(0.0, s - half_window), min(self.length, s + half_window)
        t = self.at(b) - self.at(a)
        n = float(np.linalg.norm(t))
        return t / n if n > 0 else self.tangent(s)

    def s_at_height(self, height: float) -> float | None:
        """First arc length at which the curve reaches ``height`` (z), or None."""
        z = self.points[:, 2]
        for i in range(len(z) - 1):
            z0, z1 = z[i], z[i + 1]
            if (z0 - height) * (z1 - height) <= 0 and z0 != z1:
                f = (height - z0) / (z1 - z0)
                return float(self.s[i] + f * (self.s[i + 1] - self.s[i]))
            if z0 == height:
                return float(self.s[i])
        if abs(z[-1] - height) < 1e-12:
            return self.length
        return None


def frame_with_x(x: np.ndarray) -> np.ndarray:
    """A right-handed rotation (columns x, y, z) whose x axis is along ``x``."""
    x = np.asarray(x, float) / np.linalg.norm(x)
    ref = np.array([0.0, 0.0, 1.0]) if abs(x[2]) < 0.9 else np.array([0.0, 1.0, 0.0])
    y = np.cross(ref, x)
    y /= np.linalg.norm(y)
    return np.column_stack([x, y, np.cross(x, y)])


def point_segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distances from points ``p`` (m, 3) to every segment a[k]-b[k]; shape (m, k)."""
    ab = b - a  # (k, 3)
    ap = p[:, None, :] - a[None, :, :]  # (m, k, 3)
    denom = np.maximum(np.einsum("kj,kj->k", ab, ab), 1e-300)
    t = np.clip(np.einsum("mkj,kj->mk", ap, ab) / denom, 0.0, 1.0)
    closest = a[None] + t[..., None] * ab[None]
    return np.linalg.norm(p[:, None, :] - closest, axis=-1)


def chain_deviation(curve: Curve, nodes_s: np.ndarray, n_query: int = QUERY_POINTS) -> np.ndarray:
    """Distance of ``n_query`` uniform curve points to the chain through ``nodes_s``."""
    q = curve.at(np.linspace(0.0, curve.length, n_query))
    nodes = curve.at(nodes_s)
    return point_segment_distance(q, nodes[:-1], nodes[1:]).min(axis=1)


def uniform_discretize(curve: Curve, segments: int, fixed: tuple[float, ...] = ()) -> np.ndarray:
    """Node arc lengths for ``segments`` links of (nearly) equal length, with
    the ``fixed`` arc lengths as nodes (links on each side stay equal)."""
    L = curve.length
    cuts = [0.0, *sorted(f for f in fixed if 1e-9 < f < L - 1e-9), L]
    spans = np.diff(cuts)
    # share the links between spans in proportion to their length (largest remainder)
    raw = spans / L * segments
    n = np.maximum(1, np.floor(raw).astype(int))
    while n.sum() < segments:
        n[np.argmax(raw - n)] += 1
    while n.sum() > segments and np.any(n > 1):
        n[np.argmax(np.where(n > 1, n - raw, -np.inf))] -= 1
    out = [np.linspace(a, b, k + 1)[:-1] for a, b, k in zip(cuts[:-1], cuts[1:], n)]
    return np.concatenate([*out, [L]])


def greedy_discretize(
    curve: Curve,
    max_deviation: float = 0.005,
    segments: int | None = None,
    min_segments: int = 1,
    fixed: tuple[float, ...] = (),
) -> np.ndarray:
    """Arc lengths of the chain's nodes (base ... tip), paper's greedy rule.

    Parameters
    ----------
    curve : Curve
        Smoothed centreline.
    max_deviation : float
        Stop when every query point is within this distance of the chain.
    segments : int, optional
        If given, split until exactly this many links instead.
    min_segments : int
        Never return fewer links than this.
    fixed : tuple of float
        Arc lengths that must be nodes (e.g. the probe point), placed first.

    Notes
    -----
    A straight curve has no farthest point to split at; it is divided into
    equal links (``segments`` or ``min_segments`` of them). If a curved cane
    needs more links than its curvature supplies, the longest link is halved.
    """
    L = curve.length
    target = segments if segments is not None else None
    q_s = np.linspace(0.0, L, QUERY_POINTS)
    q = curve.at(q_s)
    chord_dev = point_segment_distance(q, curve.at([0.0]), curve.at([L])).max()
    fixed = tuple(f for f in fixed if 1e-9 < f < L - 1e-9)
    if chord_dev <= STRAIGHT_TOL and not fixed:
        n = target if target is not None else max(1, min_segments)
        return np.linspace(0.0, L, n + 1)

    nodes = sorted([0.0, L, *fixed])
    while True:
        check_deadline()  # thousands of links take minutes: let a job's time limit stop it anywhere
        n_links = len(nodes) - 1
        if target is not None and n_links >= target:
            break
        pts = curve.at(np.array(nodes))
        d = point_segment_distance(q, pts[:-1], pts[1:]).min(axis=1)
        k = int(np.argmax(d))
        if target is None and d[k] <= max_deviation and n_links >= min_segments:
            break
        if d[k] > STRAIGHT_TOL and not np.any(np.isclose(nodes, q_s[k], atol=1e-12)):
            nodes.append(float(q_s[k]))
        else:  # nothing left to resolve: halve the longest link
            arr = np.array(nodes)
            j = int(np.argmax(np.diff(arr)))
            nodes.append(float(0.5 * (arr[j] + arr[j + 1])))
        nodes.sort()
    return np.array(nodes)
