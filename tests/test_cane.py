"""Cane description validation: every error names the file and the field."""

import copy
from pathlib import Path

import numpy as np
import pytest
import yaml

from canebench.data.cane import cane_from_dict, load_cane
from canebench.model.config import ModelConfig
from canebench.errors import InputError

GOOD = {
    "id": "c1",
    "polyline": {"raw": True, "points": [[0, 0, 0], [0.02, 0, 0.5], [0.08, 0.01, 1.0]]},
    "calipers": [{"height": 0.5, "diameter": 0.010}, {"s": 0.7, "diameter": 0.008}],
    "push_points": [{"id": "1", "height": 0.8, "direction": [0, 1, 0]}],
    "material": {"flexural_modulus": 4.57e9},
}


def bad(path_fn, value):
    d = copy.deepcopy(GOOD)
    path_fn(d, value)
    return d


@pytest.mark.parametrize("mutate,field", [
    (lambda d: d.pop("id"), "id"),
    (lambda d: d["calipers"][1].__setitem__("diameter", float("nan")), "calipers[1].diameter"),
    (lambda d: d["calipers"][0].__setitem__("diameter", -0.01), "calipers[0].diameter"),
    (lambda d: d["calipers"][0].__setitem__("diameter", 0), "calipers[0].diameter"),
    (lambda d: d["calipers"][0].__setitem__("diameter", "thick"), "calipers[0].diameter"),
    (lambda d: d["polyline"]["points"].__setitem__(1, [0, 0, 0]), "polyline.points[1]"),
    (lambda d: d["polyline"].__setitem__("points", [[0, 0, 0]]), "polyline.points"),
    (lambda d: d["polyline"]["points"].__setitem__(2, [0, 1]), "polyline.points[2]"),
    (lambda d: d["material"].__setitem__("flexural_modulus", 0), "material.flexural_modulus"),
    (lambda d: d["push_points"][0].pop("height"), "push_points[0]"),
    (lambda d: d["push_points"].append({"id": "1", "s": 0.2}), "push_points[1].id"),
    (lambda d: d["push_points"][0].__setitem__("direction", [0, 0, 1]), "push_points[0].direction"),
    # a push at the clamp deflects nothing (every engine failed on it, each in its own words)
    (lambda d: d["push_points"][0].__setitem__("height", 0.0), "push_points[0].height"),
    (lambda d: d["push_points"][0].update(s=0.0005) or d["push_points"][0].pop("height"), "push_points[0].s"),
    # assumptions are sentences: a number crashed the run, a string was split into characters
    (lambda d: d.__setitem__("provenance", {"assumptions": 5}), "provenance.assumptions"),
    (lambda d: d.__setitem__("provenance", {"assumptions": ["ok", 3]}), "provenance.assumptions"),
])
def test_invalid_descriptions_name_the_field(mutate, field):
    d = copy.deepcopy(GOOD)
    mutate(d)
    with pytest.raises(InputError) as e:
        cane_from_dict(d, "my_cane.yaml")
    assert e.value.field == field
    assert "my_cane.yaml" in str(e.value)


def test_push_point_above_cane_is_an_error_at_load():
    d = copy.deepcopy(GOOD)
    d["push_points"][0]["height"] = 3.0
    with pytest.raises(InputError, match=r"c.yaml: field 'push_points\[0\]\.height'"):
        cane_from_dict(d, "c.yaml")


def test_malformed_yaml_names_file_and_line(tmp_path: Path):
    p = tmp_path / "broken.yaml"
    p.write_text("id: x\npolyline: [[0, 0, 0], [1, 2\ncalipers: {\n")
    with pytest.raises(InputError) as e:
        load_cane(p)
    assert "broken.yaml" in str(e.value) and "line" in e.value.field


def test_a_key_given_twice_is_an_error_not_the_last_one_kept(tmp_path: Path):
    """PyYAML keeps the last of two equal keys: a second ``calipers:`` block replaced the measured
    calipers without a word (an input review, session 66)."""
    p = tmp_path / "twice.yaml"
    p.write_text(yaml.safe_dump(GOOD) + "calipers: [{height: 0.2, diameter: 0.02}]\n")
    assert yaml.safe_load(p.read_text())["calipers"][0]["diameter"] == 0.02  # what PyYAML alone does
    with pytest.raises(InputError, match="twice.yaml.*key 'calipers' given twice"):
        load_cane(p)
    # a key that overrides a merged one (YAML's <<) is no duplicate; equal keys in two mappings neither
    from canebench.data.strict_yaml import load_yaml

    assert load_yaml("b: &b {a: 1, c: 2}\nx: {<<: *b, c: 3}\n")["x"] == {"a": 1, "c": 3}
    assert load_yaml("- {a: 1}\n- {a: 2}\n") == [{"a": 1}, {"a": 2}]
    # one sentence alone is a list of one
    one = {**GOOD, "provenance": {"assumptions": "straight cane"}}
    assert cane_from_dict(one, "x").provenance["assumptions"] == ["straight cane"]


def test_round_trip_through_yaml(tmp_path: Path):
    from canebench.data.cane import cane_to_dict

    c = cane_from_dict(GOOD, "x")
    p = tmp_path / "c.yaml"
    p.write_text(yaml.safe_dump(cane_to_dict(c)))
    c2 = load_cane(p)
    np.testing.assert_allclose(c2.polyline, c.polyline)
    assert c2.calipers == c.calipers and c2.push_points == c.push_points


def test_bundled_descriptions_load_and_are_labelled_synthetic(bundled_trials):
    canes = {t.cane.id: t.cane for t in bundled_trials}
    assert len(canes) == 18 and len(bundled_trials) == 54
    for c in canes.values():
        assert c.provenance["synthetic"] is True
        assert any("SYNTHETIC" in a for a in c.provenance["assumptions"])
        assert len(c.calipers) == 3 and len(c.push_points) == 3


def test_config_overrides_are_typed_and_validated():
    c = ModelConfig().with_overrides({"modulus_pa": "3e9", "segments": "12",
                                      "effects": "modulus_scale(scale=2), root_compliance(k_root=5)"})
    assert c.modulus_pa == 3e9 and c.segments == 12
    assert [(e.name, dict(e.params)) for e in c.effects] == [("modulus_scale", {"scale": 2.0}),
                                                            ("root_compliance", {"k_root": 5.0})]
    with pytest.raises(InputError, match="effects"):
        ModelConfig().with_overrides({"effects": "test_a"})
    with pytest.raises(InputError, match="k_roo"):
        ModelConfig().with_overrides({"effects": "root_compliance(k_roo=5)"})
    with pytest.raises(InputError, match="k_root"):
        ModelConfig().with_overrides({"effects": "root_compliance(k_root=-5)"})
    assert ModelConfig().with_overrides({"segments": "none"}).segments is None
    with pytest.raises(InputError, match="diameter_factor"):
        ModelConfig().with_overrides({"diameter_factor": "1.5"})
    with pytest.raises(InputError, match="modulus_pa"):
        ModelConfig().with_overrides({"modulus_pa": "soft"})
    with pytest.raises(InputError, match="unknown model setting"):
        ModelConfig().with_overrides({"modulus": "3e9"})
    assert ModelConfig().with_overrides({"probe_tangent_window_m": "0"}).probe_tangent_window_m == 0.0
    for bad in ("-0.1", "nan"):
        with pytest.raises(InputError, match="probe_tangent_window_m"):
            ModelConfig().with_overrides({"probe_tangent_window_m": bad})


def test_a_height_an_arched_cane_reaches_twice_is_warned_about():
    """An arch reaches a height on the way up and on the way down; the first crossing is taken, so a
    push meant for the far limb would be scored on the near one (3 times stiffer in an input review's
    case). A height given so warns with both arc lengths; the same place given by s does not."""
    import warnings

    from canebench.errors import InputWarning

    arch = copy.deepcopy(GOOD)
    arch["polyline"] = {"raw": False, "points": [[0, 0, 0], [0, 0, 0.9], [0.3, 0, 1.2], [0.6, 0, 0.9], [0.7, 0, 0.5]]}
    arch["push_points"] = [{"id": "1", "height": 1.0, "direction": [0, 1, 0]}]

    def warned(d):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            cane_from_dict(d, "arch.yaml")
        return [str(w.message) for w in caught if issubclass(w.category, InputWarning) and "reached at" in str(w.message)]

    got = warned(arch)
    assert len(got) == 1 and "push_points[0].height" in got[0] and "arch.yaml" in got[0], got
    arch["push_points"] = [{"id": "1", "s": 1.9, "direction": [0, 1, 0]}]
    assert warned(arch) == []
    assert warned(GOOD) == []


def test_a_push_near_a_drooping_tip_is_not_taken_for_the_clamp():
    """The clamp check resolves a push height to where the chain takes it (the first crossing), not
    to the lowest point: a tip that droops below the base is pushed far from the clamp."""
    droop = copy.deepcopy(GOOD)
    droop["polyline"] = {"raw": False, "points": [[0, 0, 0.05], [0, 0, 0.9], [0.4, 0, 1.1], [0.8, 0, 0.0]]}
    droop["calipers"] = [{"s": 0.3, "diameter": 0.010}, {"s": 0.9, "diameter": 0.008}]
    droop["push_points"] = [{"id": "1", "s": 1.9, "direction": [0, 1, 0]}]
    cane_from_dict(droop, "droop.yaml")  # near the tip, below the base's height: fine
    droop["push_points"] = [{"id": "1", "height": 0.05, "direction": [0, 1, 0]}]
    with pytest.raises(InputError, match=r"push_points\[0\]\.height.*clamped base"):
        cane_from_dict(droop, "droop.yaml")
