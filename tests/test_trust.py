"""No silent wrong answers: impossible results fail, bad input is refused or questioned.

Each test reproduces one way the harness used to answer wrongly or crash.
"""

from __future__ import annotations

import json
import shutil
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

from canebench.cli import main
from canebench.data.cane import cane_from_dict, cane_to_dict, load_cane
from canebench.data.dataset import bundled_dataset, load_dataset
from canebench.errors import InputError, InputWarning
from canebench.execute.executors import SerialExecutor
from canebench.execute.runner import run_trials
from canebench.model.config import ModelConfig
from canebench.probe.protocol import PROTOCOLS


@pytest.fixture
def dataset(tmp_path) -> Path:
    """A private copy of the bundled dataset to damage."""
    d = tmp_path / "data"
    shutil.copytree(bundled_dataset(), d)
    return d


def edit_cane(d: Path, cid: str, fn) -> Path:
    p = d / "canes" / f"{cid}.yaml"
    data = yaml.safe_load(p.read_text())
    fn(data)
    p.write_text(yaml.safe_dump(data))
    return p


def base_dict(cid: str = "b1c1") -> dict:
    return yaml.safe_load((bundled_dataset() / "canes" / f"{cid}.yaml").read_text())


# ---------------------------------------------------------------- results that must never be ok


def test_diameters_in_mm_are_refused_and_never_ok(dataset):
    edit_cane(dataset, "b1c1", lambda d: [c.update(diameter=c["diameter"] * 1000) for c in d["calipers"]])
    with pytest.raises(InputError, match=r"calipers\[0\].diameter.*millimetres"):
        load_dataset(dataset, "b1c1t1")
    # a factor that passes the hard bound (cm read as m) is questioned, and the engines must not say ok
    edit_cane(dataset, "b1c1", lambda d: [c.update(diameter=c["diameter"] / 100) for c in d["calipers"]])
    with pytest.warns(InputWarning, match="diameter"):
        trials = load_dataset(dataset, "b1c1t1")
    res = run_trials(trials, ["mujoco", "pinocchio"], PROTOCOLS["fast"], ModelConfig(),
                     executor=SerialExecutor()).results
    assert (res.status == "failed").all(), res[["backend", "status", "reason"]]


def test_a_probe_that_does_not_follow_its_setpoint_fails(bundled_trials):
    t = [t for t in bundled_trials if t.id == "b1c1t1"]
    res = run_trials(t, ["mujoco"], PROTOCOLS["fast"], ModelConfig(modulus_pa=1e14),
                     executor=SerialExecutor()).results
    r = res.iloc[0]
    assert r.status == "failed" and ("setpoint" in r.reason or "limit" in r.reason or "covered" in r.reason)


def test_a_simulation_failure_is_not_blamed_on_the_field(bundled_trials):
    t = [t for t in bundled_trials if t.id == "b1c1t1"]
    res = run_trials(t, ["pinocchio"], PROTOCOLS["fast"], ModelConfig(modulus_pa=1e3),
                     executor=SerialExecutor()).results
    r = res.iloc[0]
    assert r.field_usable and r.k_field > 0
    assert r.status == "failed" and "field" not in r.reason


# ---------------------------------------------------------------- input refused or questioned


def test_unknown_key_is_an_error_with_a_suggestion():
    d = base_dict()
    d["material"] = {"flexural_modulos": 3e9}
    with pytest.raises(InputError, match=r"material.flexural_modulos.*did you mean 'flexural_modulus'"):
        cane_from_dict(d, "b1c1.yaml")
    d = base_dict()
    d["calipers"][0]["diamter"] = 0.01
    with pytest.raises(InputError, match=r"calipers\[0\].diamter"):
        cane_from_dict(d, "b1c1.yaml")


def test_cane_ids_must_match_push_points_and_be_unique(dataset):
    edit_cane(dataset, "b1c1", lambda d: d.update(id="b9c9"))
    with pytest.raises(InputError, match="b9c9.*matches no bush/cane"):
        load_dataset(dataset)
    edit_cane(dataset, "b1c1", lambda d: d.update(id="b1c2"))
    with pytest.raises(InputError, match="also used by"):
        load_dataset(dataset)


def test_implausible_magnitudes_warn_and_strict_refuses(dataset, tmp_path):
    edit_cane(dataset, "b1c1", lambda d: d.setdefault("material", {}).update(flexural_modulus=4.57))
    with pytest.warns(InputWarning, match="flexural_modulus.*GPa"):
        load_dataset(dataset, "b1c1t1")
    code = main(["run", "--field", str(dataset), "--trials", "b1c1t1", "--backends", "pinocchio", "--strict",
                 "--out", str(tmp_path / "r"), "--no-report", "--quiet"])
    assert code == 2 and not (tmp_path / "r" / "results.csv").exists()


def test_positions_in_mm_warn():
    d = base_dict()
    d["polyline"]["points"] = [[v * 1000 for v in p] for p in d["polyline"]["points"]]
    for c in d["calipers"] + d["push_points"]:
        for k in ("s", "height"):
            if k in c:
                c[k] *= 1000
    with pytest.warns(InputWarning, match="millimetres"):
        cane_from_dict(d, "mm.yaml")


def test_tip_first_and_folded_polylines_warn():
    d = base_dict()
    d["polyline"]["points"] = d["polyline"]["points"][::-1]
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        try:
            cane_from_dict(d, "reversed.yaml")
        except InputError:
            pass  # heights may fall outside a reversed cane; the warning must come first
    assert any("tip first" in str(x.message) for x in w)
    d = base_dict()
    pts = d["polyline"]["points"]
    a, b = np.array(pts[2]), np.array(pts[3])
    pts.insert(3, list(a + 0.5 * (a - b)))  # a hairpin: forward, back, forward
    with pytest.warns(InputWarning, match=r"doubles back.*turning angle 180"):
        cane_from_dict(d, "hairpin.yaml")


def test_push_points_and_calipers_beyond_the_cane_are_errors_at_load():
    d = base_dict()
    d["push_points"][0] = {"id": "1", "s": 5.0}
    with pytest.raises(InputError, match=r"push_points\[0\].s.*beyond the cane's length"):
        cane_from_dict(d, "b1c1.yaml")
    d = base_dict()
    d["calipers"][0] = {"height": 3.0, "diameter": 0.01}
    with pytest.raises(InputError, match=r"calipers\[0\].height.*outside"):
        cane_from_dict(d, "b1c1.yaml")


def test_binary_files_and_out_of_range_numbers_are_named(tmp_path, dataset):
    p = tmp_path / "bin.yaml"
    p.write_bytes(bytes(range(256)) * 4)
    with pytest.raises(InputError, match="bin.yaml.*not a text file"):
        load_cane(p)
    (dataset / "push_points.csv").write_bytes(b"\xff\xfe\x00bush" + bytes(range(200)))
    with pytest.raises(InputError, match="push_points.csv"):
        load_dataset(dataset)
    d = base_dict()
    d["polyline"]["points"][3][2] = 1e300
    with pytest.raises(InputError, match=r"polyline.points\[3\]\[2\].*out of range"):
        cane_from_dict(d, "b1c1.yaml")


@pytest.mark.parametrize("setting", ["stiffness_formula=dual-length", "node_at_push=ture", "segments=3.5",
                                     "modulus_pa=nan", "no_such_setting=1"])
def test_set_values_are_checked_before_any_simulation(tmp_path, capsys, setting):
    code = main(["run", "--trials", "b1c1t1", "--backends", "pinocchio", "--set", setting,
                 "--out", str(tmp_path / "r"), "--no-report", "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and setting.split("=")[0] in err
    assert not (tmp_path / "r" / "results.csv").exists()


def test_bad_out_is_one_line(tmp_path, capsys):
    f = tmp_path / "a_file"
    f.write_text("x")
    assert main(["run", "--trials", "b1c1t1", "--backends", "pinocchio", "--out", str(f), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--out" in err[0]
    assert main(["run", "--trials", "b1c1t1", "--backends", "pinocchio", "--out", "/proc/canebench-out",
                 "--quiet"]) == 2


def test_provenance_tells_the_configured_modulus(tmp_path):
    out = tmp_path / "r"
    assert main(["run", "--trials", "b1c1t1", "--backends", "pinocchio", "--set", "modulus_pa=3e9",
                 "--out", str(out), "--no-report", "--quiet"]) == 0
    meta = json.loads((out / "run.json").read_text())
    text = json.dumps(meta["assumptions"]) + (out / "results.csv").read_text()
    assert "4.57" not in text and "3e+09 Pa" in text


@pytest.mark.slow  # the generator computes every trial's truth: about 100 s
def test_generate_writes_nothing_outside_its_folder(tmp_path):
    out = tmp_path / "gen" / "set"
    before = set(tmp_path.rglob("*"))
    assert main(["generate", "--out", str(out), "--seed", "3"]) == 0
    new = set(tmp_path.rglob("*")) - before
    assert new and all(p == out.parent or out in (p, *p.parents) for p in new), sorted(new)


# ---------------------------------------------------------------- straight-cane assumption everywhere


@pytest.mark.field
def test_straight_cane_assumption_in_every_output(field_dir, tmp_path):
    out = tmp_path / "r"
    assert main(["run", "--field", str(field_dir), "--trials", "b1c1t1", "--backends", "pinocchio",
                 "--out", str(out), "--quiet"]) == 0
    for f in ("results.csv", "field.csv"):
        assert pd.read_csv(out / f).assumptions.str.contains("straight vertical cane").all(), f


def test_mujoco_log_lands_in_the_run_folder(tmp_path, monkeypatch):
    # a floppy, undamped cane makes MuJoCo warn (bad acceleration) and write its log
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    monkeypatch.chdir(cwd)
    out = tmp_path / "run"
    code = main(["run", "--trials", "b1c1t1", "--backends", "mujoco", "--set", "modulus_pa=1e3", "--set",
                 "damping=1e-9", "--out", str(out), "--no-report", "--quiet"])
    assert code == 1  # every job failed, and said why
    assert "BADQACC" in pd.read_csv(out / "results.csv").reason.iloc[0]
    assert (out / "MUJOCO_LOG.TXT").exists() and not (cwd / "MUJOCO_LOG.TXT").exists()


def test_quasi_static_answers_are_labelled(bundled_trials, capsys):
    t = [t for t in bundled_trials if t.id == "b1c1t1"]
    res = run_trials(t, ["pybullet", "mujoco", "pinocchio"], PROTOCOLS["fast"], ModelConfig(),
                     executor=SerialExecutor()).results.set_index("backend")
    assert res.answer.to_dict() == {"pybullet": "quasi-static", "mujoco": "dynamic", "pinocchio": "static"}
    assert main(["backends"]) == 0
    assert "fast: answer=quasi-static" in capsys.readouterr().out
