import numpy as np
import pytest

from canebench.model.geometry import Curve, chain_deviation, chaikin, greedy_discretize


def test_chaikin_one_iteration_by_hand():
    p = np.array([[0.0, 0, 0], [1.0, 0, 0], [1.0, 1.0, 0]])
    out = chaikin(p, iterations=1, strength=0.25)
    # segment 1 -> (0.25,0,0),(0.75,0,0); segment 2 -> (1,0.25,0),(1,0.75,0); ends kept
    expect = np.array([[0, 0, 0], [0.75, 0, 0], [1, 0.25, 0], [1, 1, 0]], float)
    np.testing.assert_allclose(out, expect)


def test_chaikin_keeps_ends_and_smooths():
    rng = np.random.default_rng(0)
    p = np.cumsum(rng.normal(size=(8, 3)), axis=0)
    out = chaikin(p, 5, 0.35)
    np.testing.assert_allclose(out[0], p[0])
    np.testing.assert_allclose(out[-1], p[-1])
    turn = lambda q: np.abs(np.diff(np.diff(q, axis=0), axis=0)).max()
    assert turn(out) < turn(p)


def arc(radius: float, angle: float, n: int = 400) -> Curve:
    t = np.linspace(0, angle, n)
    return Curve.from_points(np.column_stack([radius * (1 - np.cos(t)), np.zeros(n), radius * np.sin(t)]))


@pytest.mark.parametrize("radius,angle", [(0.8, 1.2), (2.0, 0.6), (0.5, 2.5)])
def test_greedy_meets_5mm_bound_and_is_minimal(radius, angle):
    c = arc(radius, angle)
    nodes = greedy_discretize(c, 0.005)
    assert chain_deviation(c, nodes).max() <= 0.005
    # sagitta bound: a chord over angle phi deviates R(1-cos(phi/2)); the fewest
    # equal chords meeting 5 mm is a lower bound on any chain meeting it
    phi_max = 2 * np.arccos(1 - 0.005 / radius)
    assert len(nodes) - 1 >= int(np.ceil(angle / phi_max))
    # and greedy is no worse than twice that bound for a circle
    assert len(nodes) - 1 <= 2 * int(np.ceil(angle / phi_max))


@pytest.mark.parametrize("n", [3, 4, 7, 10, 20, 40])
def test_fixed_segment_counts(n):
    c = arc(0.9, 1.0)
    nodes = greedy_discretize(c, 0.005, segments=n)
    assert len(nodes) == n + 1
    assert np.all(np.diff(nodes) > 0) and nodes[0] == 0 and np.isclose(nodes[-1], c.length)


def test_straight_cane_is_split_evenly():
    c = Curve.from_points(np.array([[0, 0, 0], [0, 0, 1.0]]))
    np.testing.assert_allclose(greedy_discretize(c, 0.005, segments=10), np.linspace(0, 1, 11))
    assert len(greedy_discretize(c, 0.005, min_segments=3)) == 4


def test_min_segments_respected_on_gentle_curve():
    c = arc(50.0, 0.02)  # nearly straight: one link meets 5 mm
    assert len(greedy_discretize(c, 0.005, min_segments=1)) == 2
    assert len(greedy_discretize(c, 0.005, min_segments=3)) == 4


def test_bundled_canes_within_5mm(bundled_trials):
    from canebench.model.chain import build_chain

    for t in bundled_trials[::3]:
        ch = build_chain(t.cane, t.push_id)
        from canebench.model.chain import cane_curve
        from canebench.model.config import ModelConfig

        curve = cane_curve(t.cane, ModelConfig())
        assert chain_deviation(curve, np.array(ch.meta["nodes_s"])).max() <= 0.005
        assert ch.n_links >= 3


def test_a_centred_chord_is_the_tangent_of_a_circle():
    # on a circle the chord from s - w to s + w is parallel to the tangent at s (symmetry), so
    # the only error left is the polyline's: 400 points on a 0.8 m radius put it below 1e-4 rad
    c = arc(0.8, 1.2)
    for s in (0.3, 0.5, 0.7):
        t_exact = np.array([np.sin(s / 0.8), 0.0, np.cos(s / 0.8)])
        assert np.degrees(np.arccos(min(1.0, c.chord_tangent(s, 0.15) @ t_exact))) < 0.01
    np.testing.assert_array_equal(c.chord_tangent(0.5, 0.0), c.tangent(0.5))


def test_a_chord_over_a_few_clicks_averages_the_click_noise():
    # a straight 1.2 m cane clicked every ~110 mm with 2 mm of noise (as canes/README.md
    # describes): one segment's direction is off by about 2 * 2 / 110 rad ~ 1.5 deg rms, the
    # chord over +-150 mm by the noise at two interpolated points over 300 mm, ~3x less
    rng = np.random.default_rng(3)
    err_seg, err_chord = [], []
    for _ in range(200):
        z = np.linspace(0.0, 1.2, 12)
        p = np.column_stack([np.zeros(12), np.zeros(12), z]) + np.vstack(
            [np.zeros(3), rng.normal(0.0, 0.002, (11, 3))])
        c = Curve.from_points(p)
        s = rng.uniform(0.4, 0.8) * c.length
        ang = lambda t: np.degrees(np.arccos(min(1.0, abs(t[2]))))
        err_seg.append(ang(c.tangent(s)))
        err_chord.append(ang(c.chord_tangent(s, 0.15)))
    rms = lambda e: float(np.sqrt(np.mean(np.square(e))))
    assert rms(err_chord) < rms(err_seg) / 2
