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
    print("IMU", imu, "\nforce-only", sc["force"], "\n", res.sensitivity.to_string())
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
    assert not r.detected
    # the one knee is where contact starts (3 mm), and it is called the onset
    assert [e["kind"] for e in r.events] in ([], ["onset"])
    assert all(abs(e["displacement_mm"] - 3.0) <= 1.0 for e in r.events)


@pytest.mark.parametrize("seed", range(5))
def test_force_silent_on_a_line_with_correlated_noise(seed):
    # AR(1) noise (rho 0.6, 2.5 gf innovations, like the load cell's ripple) on a straight push:
    # the knee test scales by the long-run variance, so no knee, hence no event at all
    rng = np.random.default_rng(100 + seed)
    x = 0.5 * np.arange(88)
    e = np.zeros(88)
    for i in range(1, 88):
        e[i] = 0.6 * e[i - 1] + rng.normal(0, 2.5 * 9.80665e-3)
    r = detect_force(x, 0.2 * x + e)
    assert not r.detected and r.events == [], r.events


def _line_with(x, slope, **kw):
    return slope * x + np.random.default_rng(kw.get("seed", 1)).normal(0, 0.01, len(x))


def test_force_spike_is_not_a_slip():
    x = 0.5 * np.arange(60)
    f = _line_with(x, 0.08)
    f[20] += 0.6  # one sample 61 gf high, then back on the line: the load cell, not the cane
    r = detect_force(x, f)
    assert [e["kind"] for e in r.events if e["kind"] in ("drop", "spike")] == ["spike"]
    assert not r.detected


def test_force_slip_run_counts_once():
    x = 0.5 * np.arange(60)
    f = _line_with(x, 0.08)
    f[30:] -= 0.25  # a slip spread over two samples: 25 gf + 26 gf, one event of 51 gf
    f[31:] -= 0.25
    r = detect_force(x, f)
    d = [e for e in r.events if e["kind"] == "drop"]
    assert len(d) == 1 and d[0]["index"] == 30 and d[0]["samples"] == 2
    # the fall from the sample before the run to its end: 0.5 N less the 0.08 N the line rose meanwhile
    assert d[0]["drop_gf"] == pytest.approx((0.5 - 0.08) / 9.80665e-3, abs=3)
    assert r.truncate_index == 30


def test_force_dip_is_not_a_contact():
    # the load drops off for 3 mm (the probe slides) and the slope comes back: a dip, not an elbow
    x = 0.5 * np.arange(88)
    f = 0.2 * x
    f[40:47] = f[40] + 0.02 * (x[40:47] - x[40])
    f[47:] = f[46] + 0.2 * (x[47:] - x[46])
    f = f + np.random.default_rng(4).normal(0, 0.01, 88)
    r = detect_force(x, f)
    kinds = [e["kind"] for e in r.events]
    assert "dip" in kinds and "stiffening" not in kinds and not r.detected, r.events


def test_force_obstruction_below_20gf_is_the_onset():
    # the cane carries 10 gf when the second body engages: by the field fit's 20 gf contact
    # threshold nothing was measurable before, so the knee is where contact starts
    x = 0.5 * np.arange(88)
    f = 0.005 * x + 0.2 * np.clip(x - 20, 0, None) + np.random.default_rng(5).normal(0, 0.005, 88)
    r = detect_force(x, f)
    knee = [e for e in r.events if abs(e["displacement_mm"] - 20) <= 1]
    assert knee and knee[0]["kind"] == "onset" and not r.detected
    # the same turn once the cane carries 50 gf is an obstruction
    f2 = f + 0.025 * x
    r2 = detect_force(x, f2)
    st = [e for e in r2.events if e["kind"] == "stiffening"]
    assert len(st) == 1 and abs(st[0]["displacement_mm"] - 20) <= 1 and r2.detected


def test_force_drop():
    x = 0.5 * np.arange(60)
    f = 0.08 * x + np.random.default_rng(0).normal(0, 0.01, 60)
    f[30:] -= 0.5  # a 47 gf slip
    r = detect_force(x, f)
    assert [e["kind"] for e in r.events] == ["drop"] and r.truncate_index == 30


@pytest.fixture(scope="module")
def real(tmp_path_factory):
    d = _field()
    if d is None:
        pytest.skip("field data not found: put it at ../shared/field-data or set CANEBENCH_FIELD_DATA")
    from canebench.studies.contact import contact_study

    out = tmp_path_factory.mktemp("contact-real")
    return contact_study(d, out), out, d


@pytest.mark.field
def test_real_data_counts(real):
    res, out, _ = real
    m = res.meta
    print("force-only on real data:", m["force_events"], "in trials", m["force_event_trials"], "partial",
          m["force_partial"], m["force_partial_by_cause"], "counts", m["counts"], "paper", m["paper"])
    print(res.sensitivity.to_string())
    assert m["primary_method"] == "force" and m["n_trials"] == 54
    ev = res.events
    # the README's elbow: bush 5 cane 2 trial 3 goes from ~0.07 to ~1.9 N/mm near 37 mm
    hit = ev[(ev.trial == "b5c2t3") & (ev.kind == "stiffening")]
    assert len(hit) == 1 and 35 <= hit.displacement_mm.iloc[0] <= 40
    assert hit.slope_after.iloc[0] > 1.0 and hit.slope_before.iloc[0] < 0.2
    assert not (out / "contact_scores.json").exists()
    for f in ("contact_trials.csv", "contact_sensitivity.csv", "contact_events.csv"):
        assert (out / f).exists()


@pytest.mark.field
def test_real_data_partial_trials_follow_the_truncation_rule(real):
    res, _, _ = real
    t = res.trials.set_index("trial")
    ev = res.events
    for tid, row in t.iterrows():
        cut = ev[(ev.trial == tid) & ev.kind.isin(["stiffening", "drop"])]
        assert (row.status == "partial") == (len(cut) > 0)
        if len(cut):
            first = cut.sort_values("index").iloc[0]
            assert row.kept_samples == first["index"] + (0 if first.kind == "drop" else 1)
            assert row.cause == first.kind
    # b5c2t3: the elbow makes the whole trial unscorable (R^2 < 0.8); the partial trial before it is
    assert np.isnan(t.loc["b5c2t3", "k_field_full"]) and t.loc["b5c2t3", "partial_usable"]
    assert 0.03 < t.loc["b5c2t3", "k_field_partial"] < 0.15


@pytest.mark.field
def test_contact_fields_score_partial_trials_to_the_contact(real):
    from canebench.data.dataset import load_dataset
    from canebench.execute.pipeline import field_stage
    from canebench.probe.protocol import PROTOCOLS
    from canebench.studies.contact import contact_fields

    res, _, d = real
    trials = load_dataset(d, "b5c2t3,b3c3t1,b2c1t3")
    whole, part = field_stage(trials), contact_fields(trials)
    t = res.trials.set_index("trial")
    fast = PROTOCOLS["fast"]
    for tid in ("b5c2t3", "b2c1t3"):  # partial: a stiffening elbow, a slip
        assert any(f.startswith("partial trial") for f in part[tid].fit.flags)
        assert part[tid].n_steps(fast) < whole[tid].n_steps(fast)
        assert part[tid].k == pytest.approx(t.loc[tid, "k_field_partial"], rel=1e-9, nan_ok=True)
    # a full trial is fitted exactly as without the rule
    assert t.loc["b3c3t1", "status"] == "full"
    assert part["b3c3t1"].k == whole["b3c3t1"].k
    assert not any(f.startswith("partial trial") for f in part["b3c3t1"].fit.flags)


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


@pytest.mark.parametrize("step", [1, 3, 20])
def test_prefix_cost_equals_ruptures_rbf_cost(step):
    """The constant-time rbf cost is ruptures' own CostRbf (an independent implementation) on every
    segment, on and off its block grid, and binary segmentation finds the same change points with
    either. Tolerance: a block sum is a difference of prefix sums as large as n^2, so it carries a
    rounding of a few n^2 eps; the cost divides it by the segment's length. (A rule of thumb, not a
    bound: at these sizes the worst difference measured was about a third of it.)"""
    import ruptures as rpt
    from ruptures.exceptions import NotEnoughPoints

    from canebench.measure.kernel_cost import CostRbfPrefix

    rng = np.random.default_rng(step)
    for n, d in ((2, 1), (41, 2), (300, 1)):
        x = rng.normal(size=(n, d))
        ref, fast = rpt.costs.CostRbf().fit(x), CostRbfPrefix(step=step).fit(x)
        assert fast.gamma == pytest.approx(ref.gamma, rel=1e-12)
        for s in range(n):
            for e in range(s + 1, n + 1, max(1, n // 17)):
                tol = 8 * np.finfo(float).eps * n * n / (e - s)
                assert abs(fast.error(s, e) - ref.error(s, e)) <= tol
        with pytest.raises(NotEnoughPoints):
            fast.error(5, 5)
    # an instance fitted again takes the new signal's bandwidth (ruptures' keeps its first Gram)
    reused = CostRbfPrefix(step=step).fit(rng.normal(size=50))
    x = 10.0 * rng.normal(size=60)
    assert reused.fit(x).gamma == pytest.approx(rpt.costs.CostRbf().fit(x).gamma, rel=1e-12)
    # a mean shift and a variance change in one channel, as the IMU rule sees them
    x = np.r_[rng.normal(0, 1, 400), rng.normal(2, 1, 300), rng.normal(2, 4, 300)]
    pen = 22.5 * np.log(len(x)) / 10
    jump = max(step, 5)
    a = rpt.Binseg(model="rbf", min_size=jump, jump=jump).fit(x).predict(pen=pen)
    b = rpt.Binseg(custom_cost=CostRbfPrefix(step=step), min_size=jump, jump=jump).fit(x).predict(pen=pen)
    assert a == b and len(a) >= 3
    with pytest.raises(ValueError, match="step"):
        CostRbfPrefix(step=0)
