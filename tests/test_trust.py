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
from canebench.data.cane import cane_from_dict, load_cane
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


# ---------------------------------------------------------------- found in review


def test_bad_rig_csvs_are_refused_before_simulation(dataset, tmp_path, capsys):
    f = dataset / "trials" / "syn_bush1_cane1_trial1.csv"
    for content, expect in ((bytes(range(256)) * 8, "not a text file|malformed"), (b"", "malformed|fewer"),
                            (f.read_bytes().replace(b",-", b",1e400,-", 1), "")):
        f.write_bytes(content)
        code = main(["run", "--field", str(dataset), "--trials", "b1c1t1", "--backends", "pinocchio",
                     "--out", str(tmp_path / "r"), "--no-report", "--quiet"])
        err = capsys.readouterr().err
        assert code == 2 and "syn_bush1_cane1_trial1.csv" in err, err
        assert not (tmp_path / "r" / "results.csv").exists()
    f.unlink()
    assert main(["run", "--field", str(dataset), "--trials", "b1c1t1", "--backends", "pinocchio",
                 "--out", str(tmp_path / "r"), "--quiet"]) == 2
    assert "not found" in capsys.readouterr().err


def test_rig_warnings_are_errors_under_strict(dataset, tmp_path):
    f = dataset / "trials" / "syn_bush1_cane1_trial1.csv"
    df = pd.read_csv(f)
    df["Displacement (mm)"] = df["Displacement (mm)"] / 1000.0  # written in metres
    df.to_csv(f, index=False)
    with pytest.warns(InputWarning, match="metres"):
        load_and_fit = run_trials(load_dataset(dataset, "b1c1t1"), ["pinocchio"], PROTOCOLS["fast"], ModelConfig(),
                                  executor=SerialExecutor())
    assert len(load_and_fit.results) == 1
    assert main(["run", "--field", str(dataset), "--trials", "b1c1t1", "--backends", "pinocchio", "--strict",
                 "--out", str(tmp_path / "r"), "--no-report", "--quiet"]) == 2


def test_huge_integers_and_fractional_trial_numbers_are_named():
    d = base_dict()
    d["polyline"]["points"][3][2] = 10 ** 400
    with pytest.raises(InputError, match=r"polyline.points\[3\]\[2\].*out of range"):
        cane_from_dict(d, "b1c1.yaml")


def test_fractional_trial_numbers_are_refused(dataset):
    pp = dataset / "push_points.csv"
    pp.write_text(pp.read_text().replace("\n1,1,2,", "\n1,1,1.5,", 1))
    with pytest.raises(InputError, match="push_points.csv.*trial.*whole number"):
        load_dataset(dataset)


def test_extents_are_checked_on_the_smoothed_centreline():
    d = base_dict("b2c2")
    pts = np.array(d["polyline"]["points"])
    raw_len = float(np.linalg.norm(np.diff(pts, axis=0), axis=1).sum())
    d["calipers"][0] = {"s": raw_len - 1e-4, "diameter": 0.01}  # on the raw polyline, past the smoothed end
    cane = None
    try:
        cane = cane_from_dict(d, "b2c2.yaml")
    except InputError as exc:
        assert "calipers[0].s" in str(exc)
    if cane is not None:  # accepted at load: then the chain must build too
        from canebench.model.chain import build_chain

        build_chain(cane, cane.push_points[0].id)


def test_set_values_get_the_unit_checks_and_unknown_effects_are_refused(tmp_path, capsys):
    with pytest.warns(InputWarning, match="modulus_pa.*GPa"):
        ModelConfig().with_overrides({"modulus_pa": "4.57"})
    assert main(["run", "--trials", "b1c1t1", "--backends", "pinocchio", "--set", "modulus_pa=4.57", "--strict",
                 "--out", str(tmp_path / "r"), "--quiet"]) == 2
    with pytest.raises(InputError, match="effects.*wind"):
        ModelConfig().with_overrides({"effects": "wind,snow"})
    assert ModelConfig(modulus_pa=3_000_000_000) == ModelConfig(modulus_pa=3e9)


def test_resume_runs_timed_out_jobs_again(tmp_path, bundled_trials):
    from canebench.execute.pipeline import make_jobs
    from canebench.execute.runner import run_jobs

    t = [t for t in bundled_trials if t.id == "b1c1t1"]
    jobs = make_jobs(t, ["pinocchio"], PROTOCOLS["fast"], ModelConfig())
    first = run_jobs(jobs, tmp_path, SerialExecutor(), timeout_s=1e-4)
    assert first.results.status.iloc[0] == "timeout"
    again = run_jobs(jobs, tmp_path, SerialExecutor(), timeout_s=600)
    assert again.n_reused == 0 and again.results.status.iloc[0] == "ok"


def test_the_beam_takes_the_twist_option_and_duplicate_backends_run_once(tmp_path):
    out = tmp_path / "r"
    assert main(["run", "--trials", "b1c1t1", "--backends", "pinocchio,beam,pinocchio", "--set", "twist_joint=true",
                 "--out", str(out), "--no-report", "--quiet"]) == 0
    res = pd.read_csv(out / "results.csv")
    assert sorted(res.backend) == ["beam", "pinocchio"] and (res.status == "ok").all()


def test_an_unreachable_scheduler_is_an_input_error(tmp_path, capsys):
    assert main(["run", "--trials", "b1c1t1", "--backends", "pinocchio", "--executor", "dask", "--scheduler",
                 "tcp://127.0.0.1:9", "--out", str(tmp_path / "r"), "--quiet"]) == 2
    assert "--scheduler" in capsys.readouterr().err
