"""The rod on deliberately kinked polylines (its rest shape for digitized
canes) against closed forms.

A polyline rod is straight between vertices with a kink of its stress-free
shape at each vertex; its small-deflection compliance is Castigliano's sum
over the straight segments, where the moment of a tip load is linear along
each segment, so with constant EI each segment's integral of
m . C^-1 m (C^-1 = (1/EI)(I + nu t t^T)) is a quadratic's, which Simpson's
rule gives exactly: closed forms for any polyline (:func:`polyline_compliance`),
and the textbook ones for the L-frame (reference-values.md sec. 1 by
superposition). Every case runs twice: as the rod meshes a polyline (a
vertex turning by more than 10 degrees becomes a mesh node), and with no
vertex as a node (``kink_node_deg=inf``), all kinks inside elements (several
per element on the sampled quarter circle) and integrated with the
moment-matched coefficients alone.

Tolerances: 1e-3 against the closed forms on kinked polylines, the issue's
acceptance bound for the beam reference (measured errors are 1e-7 to 1e-5,
the mesh being refined until the stiffness changes < 1e-4); 1e-4 on straight
rods given as polylines, as for the straight closed forms in test_rod.py;
the quarter-circle polygon differs from the circle itself by ~1e-5 (its
segments subtend 0.35 degrees).
"""

import numpy as np
import pytest

from canebench.backends.rod import Rod, RodSpec, _rotate, polyline_spec

N = 48  # the beam backend's default mesh
EI, NU = 1.0, 0.3


def const(v):
    return lambda s: np.full(len(np.atleast_1d(s)), float(v))


def polyline_compliance(points, s_probe, u, ei=EI, nu=NU):
    """Exact small-deflection compliance along u of a constant-EI polyline rod
    clamped at points[0], unit force along u at arc length s_probe."""
    P = np.asarray(points, float)
    u = np.asarray(u, float) / np.linalg.norm(u)
    seg = np.linalg.norm(np.diff(P, axis=0), axis=1)
    S = np.concatenate([[0.0], np.cumsum(seg)])
    j = min(np.searchsorted(S, s_probe, side="right") - 1, len(seg) - 1)
    rp = P[j] + (s_probe - S[j]) * (P[j + 1] - P[j]) / seg[j]
    total = 0.0
    for i in range(j + 1):
        t = (P[i + 1] - P[i]) / seg[i]
        length = seg[i] if i < j else s_probe - S[j]

        def f(x):
            m = np.cross(rp - (P[i] + x * t), u)
            return (m @ m + nu * (t @ m) ** 2) / ei

        total += length / 6 * (f(0.0) + 4 * f(length / 2) + f(length))  # exact for a quadratic
    return total


ALIGN = pytest.mark.parametrize("kink_nodes", [None, np.inf], ids=["sharp-vertices-as-nodes", "no-vertex-nodes"])


def compliance(spec, s_probe, u, n=N, P=1e-7, kink_nodes=None):
    """The rod's small-deflection compliance along u (force control, tiny load)."""
    rod = Rod(spec, s_probe, u, n, kink_node_deg=kink_nodes)
    st = rod.solve_force(P)
    return (st["r_probe"][0] - rod.p0) @ (np.asarray(u) / np.linalg.norm(u)) / P


def on_polyline(points, s):
    P = np.asarray(points, float)
    S = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(P, axis=0), axis=1))])
    return np.array([np.interp(s, S, P[:, k]) for k in range(3)]).T


# ---------------------------------------------------------------- L-frame

A, B = 0.37, 0.63  # the kink at s = 0.37: inside an element at 48 (and 37) elements
L_FRAME = [[0, 0, 0], [A, 0, 0], [A, B, 0]]


@ALIGN
@pytest.mark.parametrize("c", [B, 0.4])  # probe at the tip, or 0.4 along the second arm
@pytest.mark.parametrize("u,closed_form", [
    # perpendicular to the second arm, in plane: its bending, plus the first arm bent by the constant P c
    ([1.0, 0, 0], lambda c: (c**3 / 3 + c**2 * A) / EI),
    # along the second arm: only the first arm bends (the second is inextensible)
    ([0, 1.0, 0], lambda c: A**3 / (3 * EI)),
    # out of plane: both arms bend, and the first twists under P c (GJ = EI / (1 + nu))
    ([0, 0, 1.0], lambda c: (A**3 + c**3) / (3 * EI) + c**2 * A * (1 + NU) / EI),
])
def test_l_frame_against_superposition(c, u, closed_form, kink_nodes):
    spec = polyline_spec(L_FRAME, const(EI), nu=NU)
    assert compliance(spec, A + c, u, kink_nodes=kink_nodes) == pytest.approx(closed_form(c), rel=1e-3)


def test_l_frame_rest_shape_is_the_polyline_at_any_mesh():
    spec = polyline_spec(L_FRAME, const(EI), nu=NU)
    for n in (2, 3, 5, 48):
        for sp in (A + B, A + 0.4, 0.2):
            rod = Rod(spec, sp, [0, 0, 1.0], n, kink_node_deg=np.inf)  # the kink inside an element
            np.testing.assert_allclose(rod.p0, on_polyline(L_FRAME, sp), atol=1e-14)
            r = rod._integrate(np.zeros((1, 3)), np.zeros(1), keep=True)["r"][0]
            np.testing.assert_allclose(r, on_polyline(L_FRAME, rod.mesh), atol=1e-14)


# ---------------------------------------------------------------- straight polylines

def noisy_straight(L, direction, seed=0):
    """A straight line as a polyline: collinear vertices at random spacing,
    some a micrometre apart."""
    rng = np.random.default_rng(seed)
    s = np.sort(np.concatenate([rng.uniform(0, L, 40), [0.3 * L + 1e-6, 0.3 * L + 2e-6, 0.8 * L - 1e-7]]))
    s = np.concatenate([[0.0], s, [L]])
    d = np.asarray(direction, float) / np.linalg.norm(direction)
    return s[:, None] * d[None, :]


def test_noisy_straight_polyline_is_the_straight_cantilever_tapered():
    """reference-values sec. 1, tapered solid circular section, tip load."""
    E, L, d0, r = 4.57e9, 1.2, 0.012, 0.5
    d1 = r * d0
    ei = lambda s: E * np.pi * (d0 + (d1 - d0) * np.asarray(s) / L) ** 4 / 64
    pts = noisy_straight(L, [0, 0, 1.0])
    spec = polyline_spec(pts, ei)
    assert spec.length == pytest.approx(L, rel=1e-15)
    P = 1e-4
    rod = Rod(spec, L, [1.0, 0, 0], N)
    st = rod.solve_force(P)
    assert st["r_end"][0][0] == pytest.approx(64 * P * L**3 / (3 * np.pi * E * d0**3 * d1), rel=1e-4)
    t = _rotate(st["q_end"][0][:, None], np.array([[0.0], [0.0], [1.0]]))[:, 0]
    ei0 = ei(0.0)
    assert np.arctan2(t[0], t[2]) == pytest.approx(P * L**2 / (2 * ei0) * (2 * r + 1) / (3 * r**2), rel=1e-4)


@pytest.mark.parametrize("a_frac", [0.3, 0.61])
def test_noisy_straight_polyline_load_at_a(a_frac):
    L, P = 1.0, 1e-6
    a = a_frac * L
    pts = noisy_straight(L, [1.0, 2.0, -0.5], seed=1)
    u = np.cross(pts[-1], [0, 0, 1.0])
    u /= np.linalg.norm(u)
    rod = Rod(polyline_spec(pts, const(1.0)), a, u, N)
    st = rod.solve_force(P)
    assert (st["r_probe"][0] - rod.p0) @ u == pytest.approx(P * a**3 / 3, rel=1e-4)
    assert (st["r_end"][0] - pts[-1]) @ u == pytest.approx(P * a**2 * (3 * L - a) / 6, rel=1e-4)


def test_noisy_straight_polyline_large_deflection_elastica():
    """reference-values sec. 2 (Bisshopp-Drucker / Mattiasson) through the polyline path."""
    table = {1: (0.05643, 0.301721, 0.461352), 5: (0.3876, 0.713792, 1.215368), 10: (0.5550, 0.810609, 1.430286)}
    rod = Rod(polyline_spec(noisy_straight(1.0, [1.0, 0, 0], seed=2), const(1.0)), 1.0, [0, 0, -1.0], 200)
    for alpha in np.unique(np.concatenate([np.linspace(0.25, 10, 40), list(table)])):
        st = rod.solve_force(alpha)
        if alpha in table:
            dx, y, th = table[alpha]
            t = _rotate(st["q_end"][0][:, None], np.array([[1.0], [0.0], [0.0]]))[:, 0]
            assert 1 - st["r_end"][0][0] == pytest.approx(dx, abs=1e-4)
            assert -st["r_end"][0][2] == pytest.approx(y, abs=1e-4)
            assert np.arctan2(-t[2], t[0]) == pytest.approx(th, abs=1e-4)


# ---------------------------------------------------------------- zig-zags and hairpins

ZIGZAG = [[0, 0, 0], [0.12, 0, 0.2], [-0.05, 0.03, 0.41], [0.1, 0.0, 0.63], [-0.02, -0.04, 0.8], [0.03, 0, 1.0]]
# folds back twice (turning angles ~170 degrees), like the digitized canes' hairpins
HAIRPIN = [[0, 0, 0], [0, 0, 0.5], [0.015, 0.004, 0.4], [0.03, 0, 1.0]]


def turning_angles(points):
    d = np.diff(np.asarray(points, float), axis=0)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return np.degrees(np.arccos(np.clip((d[1:] * d[:-1]).sum(axis=1), -1, 1)))


def test_the_test_polylines_are_kinked():
    assert turning_angles(ZIGZAG).min() > 35
    assert turning_angles(HAIRPIN).min() > 165


@ALIGN
@pytest.mark.parametrize("points", [ZIGZAG, HAIRPIN], ids=["zigzag", "hairpin"])
@pytest.mark.parametrize("u", [[1.0, 0, 0], [0, 1.0, 0], [0.3, -0.5, 0.8]])
@pytest.mark.parametrize("probe", ["tip", "inside"])
def test_kinked_polyline_against_castigliano(points, u, probe, kink_nodes):
    spec = polyline_spec(points, const(EI), nu=NU)
    sp = spec.length if probe == "tip" else 0.55 * spec.length
    assert compliance(spec, sp, u, kink_nodes=kink_nodes) == pytest.approx(polyline_compliance(points, sp, u),
                                                                           rel=1e-3)


@pytest.mark.parametrize("points", [ZIGZAG, HAIRPIN], ids=["zigzag", "hairpin"])
def test_kinked_rest_shape_exact_at_coarse_meshes(points):
    spec = polyline_spec(points, const(EI), nu=NU)
    for n in (2, 7, 48):
        rod = Rod(spec, 0.55 * spec.length, [1.0, 0, 0], n, kink_node_deg=np.inf)
        np.testing.assert_allclose(rod.p0, on_polyline(points, 0.55 * spec.length), atol=1e-14)


@pytest.mark.parametrize("points", [ZIGZAG, HAIRPIN], ids=["zigzag", "hairpin"])
def test_kinked_large_deflection_matches_vertex_aligned_mesh(points):
    """No closed form under large loads, but a mesh through every vertex
    integrates each straight segment with constant coefficients (classical
    RK4 on a smooth problem): the coarse mesh with every kink inside an
    element (moment-matched coefficients alone) must agree."""
    spec = polyline_spec(points, const(EI), nu=NU)
    sp = spec.length
    vertices = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(spec.polyline, axis=0), axis=1))])
    coarse = Rod(spec, sp, [1.0, 0.5, 0], N, kink_node_deg=np.inf)
    aligned = Rod(spec, sp, [1.0, 0.5, 0], mesh=np.union1d(vertices, np.linspace(0, sp, 97))).refined()
    k = coarse.linear_stiffness()
    for d in np.linspace(0.01, 0.15, 8):  # up to 15 % of the length
        f_coarse, f_aligned = coarse.solve_displacement(d), aligned.solve_displacement(d)
        assert f_coarse == pytest.approx(f_aligned, rel=1e-4)
    assert abs(f_coarse / (k * d) - 1) > 0.02  # geometric nonlinearity well above the tolerance


# ---------------------------------------------------------------- sampled quarter circle

@ALIGN
def test_sampled_quarter_circle_against_curved_beam_closed_forms(kink_nodes):
    """reference-values sec. 3 on the quarter circle given as 257 jittered
    vertices: five or so kinks inside every element."""
    R, nu = 1.0, 0.3
    rng = np.random.default_rng(3)
    th = np.concatenate([[0.0], np.sort(rng.uniform(0, np.pi / 2, 255)), [np.pi / 2]])
    pts = np.column_stack([R * np.sin(th), R * (1 - np.cos(th)), 0 * th])
    spec = polyline_spec(pts, const(1.0), nu=nu)
    for u, expected in (([1.0, 0, 0], np.pi / 4), ([0, 1.0, 0], 3 * np.pi / 4 - 2),
                        ([0, 0, 1.0], np.pi / 4 + (3 * np.pi / 4 - 2) * (1 + nu))):
        assert compliance(spec, spec.length, u, kink_nodes=kink_nodes) == pytest.approx(expected * R**3, rel=1e-3)


def test_polyline_spec_tangent_and_length():
    spec = polyline_spec([[0, 0, 0], [0, 0, 0], [1, 0, 0], [1, 2, 0]], const(1.0))  # a repeated vertex is dropped
    assert spec.length == pytest.approx(3.0)
    np.testing.assert_allclose(spec.tangent(np.array([0.5, 1.0, 2.5])), [[1, 0, 0], [0, 1, 0], [0, 1, 0]])
    with pytest.raises(ValueError):
        Rod(RodSpec(2.0, spec.tangent, const(1.0), polyline=spec.polyline), 1.0, [0, 0, 1.0])


def test_sharp_vertices_become_mesh_nodes():
    spec = polyline_spec(HAIRPIN, const(EI), nu=NU)
    S = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(spec.polyline, axis=0), axis=1))])
    rod = Rod(spec, 0.55 * spec.length, [1.0, 0, 0], N)
    assert set(S[1:-1]) <= set(rod.mesh) and len(rod.h) == N + 2
    assert len(Rod(spec, 0.55 * spec.length, [1.0, 0, 0], N, kink_node_deg=np.inf).h) == N
    assert len(rod.refined().h) == 2 * len(rod.h) and set(rod.mesh) <= set(rod.refined().mesh)
