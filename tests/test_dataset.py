"""Bundled synthetic data: labelled, complete, and its truth kept apart."""

import re
from pathlib import Path

import pandas as pd
import pytest

from canebench.data.dataset import load_dataset

REPO = Path(__file__).resolve().parent.parent


def test_bundled_layout_matches_the_field_campaign(bundled_trials):
    assert len(bundled_trials) == 54
    assert {t.bush for t in bundled_trials} == set(range(1, 7))
    for cane_id in {t.cane.id for t in bundled_trials}:
        ts = sorted((t for t in bundled_trials if t.cane.id == cane_id), key=lambda t: t.trial_no)
        gaps = [ts[i].height_mm - ts[i + 1].height_mm for i in range(2)]
        assert all(70 <= g <= 130 for g in gaps), (cane_id, gaps)  # about 100 mm apart, trial 1 highest
    d = pd.Series([t.diameter_mm for t in bundled_trials])
    assert 4.0 <= d.min() and d.max() <= 23.0  # the real table's range 4.4-22.6 mm


def test_scoring_code_never_reads_the_truth():
    # the hidden stiffness truth of the bundled set is read by no code at all; the contact
    # study and the discovery self-test read their truth only to grade answers already made
    graders = {("studies", "contact.py"), ("discovery", "selftest.py")}
    for pkg in ("harness", "backends", "reports"):
        for f in (REPO / pkg).rglob("*.py"):
            text = f.read_text()
            assert "synthetic-truth" not in text, f
            if (f.parent.name, f.name) not in graders:
                assert "truth.json" not in text, f
    # the discovery workflow itself never opens a truth file
    for f in (REPO / "harness" / "discovery").glob("*.py"):
        if f.name != "selftest.py":
            assert "truth" not in f.read_text().replace("truthful", ""), f


def test_synthetic_trial_files_do_not_look_like_field_copies():
    names = [p.name for p in (REPO / "canes" / "synthetic" / "trials").glob("*.csv")]
    assert len(names) == 54
    assert not any(re.fullmatch(r"bush_\d+_branch_\d+_trial_\d+\.csv", n) for n in names)


@pytest.mark.field
def test_field_dataset_builds_straight_canes(field_dir):
    trials = load_dataset(field_dir)
    assert len(trials) == 54
    t = trials[0]
    assert "straight vertical cane" in t.cane.provenance["assumptions"][0]
    assert t.cane.polyline[0].tolist() == [0, 0, 0]


@pytest.mark.field
def test_field_run_scores_real_trials(field_dir, tmp_path):
    from canebench.cli import main

    out = tmp_path / "field"
    assert main(["run", "--field", str(field_dir), "--out", str(out), "--trials", "b1c2*,b4c1t1", "--no-report"]) == 0
    res = pd.read_csv(out / "results.csv")
    # b4c1t1's tared contact force passes 20 gf (its raw reading never does): scored now
    assert (res[res.trial == "b4c1t1"].status == "ok").all() and (res[res.trial == "b4c1t1"].k_field < 0.01).all()
    ok = res[res.status == "ok"]
    assert len(ok) == 8 and ok.k_field.between(0.005, 1.5).all()


def test_bundled_polylines_do_not_fold_and_the_truth_shares_no_chain_code():
    import warnings

    from canebench.data.dataset import bundled_dataset, load_dataset
    from canebench.errors import InputWarning

    with warnings.catch_warnings():
        warnings.simplefilter("error", InputWarning)  # a fold, a unit or an orientation warning fails here
        assert len(load_dataset(bundled_dataset())) == 54
    # the hidden truth is the continuum rod, not the harness's chains or their exact statics
    src = (REPO / "canes" / "generate.py").read_text()
    assert "Rod(" in src and "assemble_chain" not in src and "PinocchioStatic" not in src


def test_an_empty_or_unreadable_dataset_is_an_input_error(tmp_path):
    """A push_points.csv with a header and no rows made `run` fail in its report (max() of nothing)
    and `discover` with an AttributeError; a folder where a file belongs raised IsADirectoryError
    (an input review, session 66). Both now name the file."""
    import shutil

    from canebench.data.dataset import bundled_dataset
    from canebench.errors import InputError

    d = tmp_path / "empty"
    shutil.copytree(bundled_dataset(), d)
    pp = d / "push_points.csv"
    header = pp.read_text().splitlines()[0]
    pp.write_text(header + "\n")
    shutil.rmtree(d / "canes")  # the descriptions would otherwise be strays
    with pytest.raises(InputError, match=r"push_points.csv: field 'rows': no trials"):
        load_dataset(d)
    pp.unlink()
    pp.mkdir()
    with pytest.raises(InputError, match=r"push_points.csv: field '<file>': cannot read"):
        load_dataset(d)


def test_a_record_too_short_to_score_is_unscored_not_failed(bundled_trials, tmp_path):
    """A rig record of two rows has no field slope; the simulation pushes as far as the record and so
    has too few samples too. That is the record's doing: the row is ``unscored`` with the field's
    reason, never ``failed`` (README: that word is kept for the simulation)."""
    import dataclasses

    from canebench.execute.runner import run_trials
    from canebench.model.presets import PRESETS
    from canebench.probe.protocol import PROTOCOLS

    t = bundled_trials[0]
    rig = pd.read_csv(t.csv)
    short = tmp_path / "short.csv"
    rig.iloc[:2].to_csv(short, index=False)
    t2 = dataclasses.replace(t, csv=short)
    res = run_trials([t2], ["pinocchio"], PROTOCOLS["fast"], PRESETS["default"], tmp_path / "run").to_df()
    assert list(res.status) == ["unscored"], res[["status", "reason", "field_reason"]]
    assert res.reason[0].startswith("no field stiffness: ") and res.field_reason[0] in res.reason[0]


def test_a_rig_file_of_another_height_is_warned_about(bundled_trials, tmp_path):
    """The rig writes the push height into every row; a file whose height is not push_points.csv's
    (another trial's, by a mistyped name) warns, naming the file, the column and the trial."""
    import dataclasses
    import warnings

    from canebench.errors import InputWarning
    from canebench.execute.pipeline import field_fit_for

    t = bundled_trials[0]
    other = next(o for o in bundled_trials if abs(o.height_mm - t.height_mm) > 50)
    for trial, warned in ((t, False), (dataclasses.replace(t, csv=other.csv), True)):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            field_fit_for(trial)
        got = [str(w.message) for w in caught if issubclass(w.category, InputWarning)]
        assert bool(got) == warned, got
        if warned:
            assert str(other.csv) in got[0] and "Height (mm)" in got[0] and t.id in got[0]


def test_push_points_pair_with_trials_by_number(tmp_path):
    """push_points.csv's trial number names the push point whose id is that number ("1"), or the one
    id ending in it ("t1", "T01"): a blind test bed wrote "t1" and every set was refused (session 66).
    Two ids ending in the number, or none, stay an error naming the file and field."""
    import shutil

    import yaml

    from canebench.data.dataset import bundled_dataset
    from canebench.errors import InputError

    d = tmp_path / "ds"
    shutil.copytree(bundled_dataset(), d)
    y = d / "canes" / "b1c1.yaml"
    doc = yaml.safe_load(y.read_text())
    before = {t.id: t.cane.push_point(t.push_id).where for t in load_dataset(d) if t.cane.id == "b1c1"}
    for p in doc["push_points"]:
        p["id"] = f"T0{p['id']}"
    y.write_text(yaml.safe_dump(doc))
    after = {t.id: (t.push_id, t.cane.push_point(t.push_id).where) for t in load_dataset(d) if t.cane.id == "b1c1"}
    assert {k: v[1] for k, v in after.items()} == before and after["b1c1t2"][0] == "T02"
    doc["push_points"][1]["id"] = "x1"  # now "T01" and "x1" both end in 1, and nothing in 2
    y.write_text(yaml.safe_dump(doc))
    with pytest.raises(InputError, match=r"b1c1.yaml: field 'push_points'.*trial b1c1t1.*T01, x1 all end in 1"):
        load_dataset(d)
