"""Contact detection: IMU rule on the SYNTHETIC contact set, force-only detector, real-data counts."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

from canebench.data.imu import read_imu_csv
from canebench.errors import InputError
from canebench.measure.contact import detect_force

REPO = Path(__file__).resolve().parents[1]
SYN = REPO / "canes" / "synthetic-contact"


def _field() -> Path | None:
    env = os.environ.get("CANEBENCH_FIELD_DATA")
    d = Path(env) if env else Path(__file__).resolve().parents[1].parent / "shared" / "field-data"
    return d if (d / "push_points.csv").exists() else None


@pytest.fixture(scope="module")
def synthetic(tmp_path_factory):
    from canebench.studies.contact import contact_study

    out = tmp_path_factory.mktemp("contact")
    return contact_study(SYN, out), out


def test_imu_detection_on_synthetic(synthetic):
    res, out = synthetic
    sc = json.loads((out / "contact_scores.json").read_text())
    imu = sc["imu"]
    print("IMU", imu, "\nforce-only", sc["force"])
    assert imu["precision"] >= 0.9 and imu["recall"] >= 0.9
    assert imu["median_timing_error_s"] < 1.0
    assert sorted(imu["excluded_detected"]) == imu["excluded_true"]
    assert {"precision", "recall", "median_timing_error_s"} <= set(sc["force"])
    df = res.to_df()
    assert {"trial", "detected", "contact_time_s", "method"} <= set(df.columns)
    assert (out / "contact.csv").exists() and (out / "contact_example.png").exists()
    from canebench.studies.contact import contact_section_html

    assert "Field trial contact detection" in contact_section_html(out)


def test_force_elbow_by_hand():
    rng = np.random.default_rng(3)
    x = 0.5 * np.arange(80)
    f = 0.05 * np.clip(x - 4, 0, None) + 1.0 * np.clip(x - 25, 0, None) + rng.normal(0, 0.02, 80) - 0.4
    r = detect_force(x, f)
    st = [e for e in r.events if e["kind"] == "stiffening"]
    assert len(st) == 1 and abs(st[0]["displacement_mm"] - 25.0) <= 0.5
    assert r.detected and abs(r.truncate_index - 50) <= 1


@pytest.mark.parametrize("seed", range(5))
def test_force_silent_on_noisy_line(seed):
    rng = np.random.default_rng(seed)
    x = 0.5 * np.arange(88)
    f = 0.1 * np.clip(x - 3, 0, None) + rng.normal(0, 0.025, 88)
    r = detect_force(x, f)
    assert not r.detected and r.events == []


def test_force_drop():
    x = 0.5 * np.arange(60)
    f = 0.08 * x + np.random.default_rng(0).normal(0, 0.01, 60)
    f[30:] -= 0.5  # a 47 gf slip
    r = detect_force(x, f)
    assert [e["kind"] for e in r.events] == ["drop"] and r.truncate_index == 30


@pytest.mark.field
def test_real_data_counts(tmp_path):
    d = _field()
    if d is None:
        pytest.skip("field data not found: put it at ../shared/field-data or set CANEBENCH_FIELD_DATA")
    from canebench.studies.contact import contact_study

    res = contact_study(d, tmp_path)
    m = res.meta
    print("force-only on real data:", m["force_events"], "partial", m["force_partial"], "counts", m["counts"],
          "paper", m["paper"])
    assert m["primary_method"] == "force" and m["n_trials"] == 54
    ev = res.events
    hit = ev[(ev.trial == "b5c2t3") & (ev.kind == "stiffening")]
    assert len(hit) and 30 <= hit.displacement_mm.iloc[0] <= 45  # the README's elbow near 40 mm
    assert m["force_events"]["stiffening"] >= 5
    assert not (tmp_path / "contact_scores.json").exists()


def test_imu_validation_names_file_and_field(tmp_path):
    p = tmp_path / "t.imu.csv"
    cols = "time_s,pushed_x,pushed_y,pushed_z,left_x,left_y,left_z,right_x,right_y,right_z"
    rows = [f"{i / 40:.3f}," + ",".join(["0.1"] * 9) for i in range(50)]
    p.write_text(cols.replace(",right_z", "") + "\n" + "\n".join(r.rsplit(",", 1)[0] for r in rows))
    with pytest.raises(InputError, match=r"t\.imu\.csv.*'right_z'.*missing"):
        read_imu_csv(p)
    bad = rows.copy()
    bad[7] = bad[7].split(",")[0] + ",x," + ",".join(["0.1"] * 8)
    p.write_text(cols + "\n" + "\n".join(bad))
    with pytest.raises(InputError, match=r"t\.imu\.csv.*'pushed_x'.*row 9"):
        read_imu_csv(p)
    bad = rows.copy()
    bad[10] = "0.300" + bad[10][5:]
    p.write_text(cols + "\n" + "\n".join(bad))
    with pytest.raises(InputError, match=r"t\.imu\.csv.*'time_s'.*row 13: time does not increase"):
        read_imu_csv(p)
