import numpy as np
import pytest

from canebench.model.diameter import fit_diameter


def test_exact_line_recovered():
    s = np.array([0.5, 0.6, 0.7])
    d = 0.02 - 0.01 * s
    f = fit_diameter(s, d, 1.0)
    assert f.slope == pytest.approx(-0.01)
    np.testing.assert_allclose(f(np.array([0.0, 1.0])), [0.02, 0.01])


def test_least_squares_against_numpy_polyfit():
    rng = np.random.default_rng(1)
    s = rng.uniform(0.3, 0.9, 5)
    d = 0.015 - 0.008 * s + rng.normal(0, 3e-4, 5)
    b, a = np.polyfit(s, d, 1)
    f = fit_diameter(s, d)
    assert f.slope == pytest.approx(b)
    assert f(0.0) == pytest.approx(a)


@pytest.mark.parametrize("factor", [0.0, 0.25, 0.5, 1.0])
def test_factor_scales_slope_about_centroid(factor):
    s = np.array([0.55, 0.65, 0.78])
    d = np.array([0.012, 0.010, 0.0085])
    f = fit_diameter(s, d, factor)
    assert f(s.mean()) == pytest.approx(d.mean())  # the centroid is the anchor
    full = fit_diameter(s, d, 1.0)
    assert (f(0.0) - f(1.0)) == pytest.approx(factor * (full(0.0) - full(1.0)))
    if factor == 0.0:
        np.testing.assert_allclose(f(np.linspace(0, 1, 5)), d.mean())


def test_single_caliper_is_constant():
    f = fit_diameter(np.array([0.7]), np.array([0.01]))
    np.testing.assert_allclose(f(np.array([0.0, 1.2])), 0.01)
