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


def _with_calipers(tmp_path, calipers):
    """The bundled cane b1c1 (pushes at 0.634-0.802 m, tip near 1.07 m) with ``calipers`` (height, d)."""
    import yaml

    from canebench.data.cane import load_cane
    from canebench.data.dataset import bundled_dataset

    doc = yaml.safe_load((bundled_dataset() / "canes" / "b1c1.yaml").read_text())
    doc["calipers"] = [{"height": h, "diameter": d} for h, d in calipers]
    path = tmp_path / "b1c1.yaml"
    path.write_text(yaml.safe_dump(doc))
    return load_cane(path), path


def test_a_calipers_line_that_gives_no_cane_at_the_push_is_refused_naming_the_file(tmp_path):
    """Calipers near the ground of a flared cane (30, 20, 13.5 mm at 0.05-0.30 m) give a line that
    crosses zero near 0.5 m, below every push: the chain of such a cane is thread and its stiffness
    no answer, so it is refused with the file, the field and the push. A line that ends above the
    push (on the way to the tip) is only clamped there, with a warning, as before: it changes the
    weight beyond the push, not the bending between base and push."""
    from canebench.errors import InputError
    from canebench.model.chain import build_chain
    from canebench.model.config import ModelConfig

    cane, path = _with_calipers(tmp_path, [(0.05, 0.030), (0.20, 0.020), (0.30, 0.0135)])
    for push in ("1", "3"):
        with pytest.raises(InputError) as exc:
            build_chain(cane, push, ModelConfig())
        msg = str(exc.value)
        assert str(path) in msg and "'calipers'" in msg and f"push point {push}" in msg, msg
        assert "below the 1 mm floor" in msg
    # the same calipers with a diameter factor of 0 (the centroid's diameter everywhere) are a cane
    assert build_chain(cane, "1", ModelConfig(diameter_factor=0.0)).n_links > 0
    # steep calipers at the pushes: positive at every push, below the floor before the tip
    cane, _ = _with_calipers(tmp_path, [(0.802, 0.0060), (0.717, 0.0099), (0.634, 0.0140)])
    chain = build_chain(cane, "1", ModelConfig())
    assert any("were clamped" in w for w in chain.meta["warnings"])
