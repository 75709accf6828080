"""Flexural modulus study: formula, slope rule, recovery of the SYNTHETIC set,
Welch tests, input validation and the modulus distributions."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from canebench.data.bending import bundled_bending_dataset, read_bending_dataset
from canebench.errors import InputError
from canebench.model.distributions import MODULUS_DISTRIBUTIONS, ModulusDistribution, distributions_from_result
from canebench.studies.modulus import (fit_slope, flexural_modulus, modulus_section_html, modulus_study, welch,
                                       welch_tests)

REPO = Path(__file__).resolve().parent.parent
DATA = REPO / "canes" / "modulus-synthetic"
TRUTH = REPO / "canes" / "modulus-synthetic-truth" / "truth.json"
STEP = 1 / 12 * 1e-3  # 50 mm/min at 10 Hz, in m


@pytest.fixture(scope="session")
def study(tmp_path_factory):
    """The study on a copy of the bundled folder (nothing of the truth anywhere near it)."""
    data = tmp_path_factory.mktemp("data") / "modulus"
    shutil.copytree(DATA, data)
    out = tmp_path_factory.mktemp("out")
    return modulus_study(data, out), out


@pytest.fixture(scope="session")
def truth():
    return json.loads(TRUTH.read_text())


# ------------------------------------------------------------------ formula and slope rule


def test_formula_matches_hand_computed_closed_form():
    # E = L^3 m / (12 pi r^4); L = 0.2 m, m = 1000 N/m, r = 4 mm:
    # 0.008 * 1000 / (37.699112 * 2.56e-10) = 8 / 9.650973e-9 = 8.28932e8 Pa
    assert flexural_modulus(0.2, 1000.0, 0.004) == pytest.approx(8.28932e8, rel=1e-5)
    # and against the beam: midspan deflection F L^3 / (48 E I), I = pi r^4 / 4
    E, L, r, F = 4.57e9, 0.2032, 0.0045, 10.0
    deflection = F * L**3 / (48 * E * np.pi * r**4 / 4)
    assert flexural_modulus(L, F / deflection, r) == pytest.approx(E, rel=1e-12)


def _linear_then_soft(k: float, cap_soft: float = 0.5, limit: float = 28.0) -> tuple[np.ndarray, np.ndarray]:
    x = np.arange(0, 2000) * STEP
    f = np.where(x <= 20 / k, k * x, 20 + cap_soft * k * (x - 20 / k))
    n = int(np.argmax(f >= limit)) + 1
    return x[:n], f[:n]


def test_slope_rule_20N_cap_on_a_linear_curve():
    k = 4000.0  # N/m: 20 N at 5 mm, then half as stiff up to 28 N
    x, f = _linear_then_soft(k)
    fit = fit_slope(x, f)
    assert fit.method == "20N" and fit.linear and fit.ratio == pytest.approx(1.0)
    assert fit.slope_n_per_m == pytest.approx(k, rel=1e-9)
    assert np.polyfit(x, f, 1)[0] < 0.95 * k  # the whole curve would not do


def test_slope_rule_10mm_for_a_curve_that_never_reaches_20N():
    # F = k0 (x - a x^2) on an even grid from 0 to D = 10 mm: the least-squares
    # slope is k0 (1 - a D) exactly (x^2 regressed on x over a symmetric grid has slope 2 mean(x) = D)
    k0, a = 900.0, 25.0
    x = np.arange(0, 181) * STEP  # to 15 mm
    fit = fit_slope(x, k0 * (x - a * x**2))
    assert fit.method == "10mm" and not fit.linear and "did not reach 20 N" in fit.reason
    assert fit.fit_max_disp_m == pytest.approx(0.010)
    assert fit.slope_n_per_m == pytest.approx(k0 * (1 - a * 0.010), rel=1e-9)


def test_slope_rule_10mm_for_a_curve_bent_below_20N():
    k0, a = 2500.0, 25.0  # passes 20 N near 12 mm, tangent slope down 40 % by then
    x = np.arange(0, 181) * STEP
    fit = fit_slope(x, k0 * (x - a * x**2))
    assert fit.method == "10mm" and fit.ratio < 0.9 and "curved" in fit.reason
    assert fit.slope_n_per_m == pytest.approx(k0 * (1 - a * 0.010), rel=1e-9)


def _write_dataset(root: Path, curves: dict[str, list[tuple[np.ndarray, np.ndarray]]],
                   samples_text: str | None = None) -> Path:
    (root / "tests").mkdir(parents=True, exist_ok=True)
    rows = ["sample_id,season,variety,age,span_mm," + ",".join(f"caliper_{i}_mm" for i in range(1, 7))]
    for i, sid in enumerate(curves):
        rows.append(f"{sid},{'dormant' if i % 2 else 'fruiting'},Duke,1-year,203.2,8,8,8,8,8,8")
    (root / "samples.csv").write_text(samples_text or "\n".join(rows) + "\n")
    for sid, tests in curves.items():
        for k, (x, f) in enumerate(tests, start=1):
            body = "\n".join(f"{a * 1e3:.6f},{b:.6f}" for a, b in zip(x, f))
            (root / "tests" / f"{sid}_test{k}.csv").write_text(f"displacement_mm,force_n\n{body}\n")
    return root


def test_one_curved_test_puts_the_whole_sample_on_the_10mm_rule(tmp_path):
    lin = _linear_then_soft(3000.0)
    x = np.arange(0, 181) * STEP
    curved = (x, 2500.0 * (x - 25.0 * x**2))
    res = modulus_study(_write_dataset(tmp_path, {"a": [lin, lin, curved], "b": [lin, lin, lin]}))
    df = res.to_df().set_index(["sample_id", "test"])
    assert (df.loc["a", "method"] == "10mm").all() and (df.loc["b", "method"] == "20N").all()
    assert list(df.loc["a", "test_linear"]) == [True, True, False]
    e = flexural_modulus(0.2032, 3000.0, 0.004) * 1e-9
    assert df.loc["b", "E_gpa"].to_numpy() == pytest.approx([e] * 3, rel=1e-6)


# ------------------------------------------------------------------ recovery of the synthetic set


def test_recovers_every_sample_and_test_of_the_generator(study, truth):
    """Per sample within 1 % of the generator's E (measured: 0.15 %), per test
    within 1.5 % (measured: 0.5 %): 0.03 N load-cell noise and 0.01 N / 0.001 mm
    rounding on fits over 17-180 readings. The rule picked matches the truth's."""
    res, _ = study
    smp = res.samples.set_index("sample_id")
    assert len(smp) == len(truth["samples"]) == 59
    for sid, t in truth["samples"].items():
        assert smp.loc[sid, "E_gpa"] == pytest.approx(t["E_gpa"], rel=0.01), sid
        assert smp.loc[sid, "method"] == ("20N" if t["linear"] else "10mm"), sid
    tests = res.to_df()
    want = [truth["samples"][s]["E_tests_gpa"][k - 1] for s, k in zip(tests.sample_id, tests.test)]
    assert tests.E_gpa.to_numpy() == pytest.approx(want, rel=0.015)
    assert {"did not reach 20 N", "curved below 20 N", "linear to 20 N"} <= {r.split(" (")[0] for r in tests.reason}


def test_recovers_the_papers_published_numbers(study):
    """Season and Duke means within 0.02 GPa of the paper, the range within
    0.05 GPa, the season p within 0.001-0.002 (paper 0.0015), and the paper's
    pattern of significant and non-significant pairs."""
    res, _ = study
    g = res.groups
    season = g[g.grouping == "season"].set_index("season")
    assert season.loc["dormant", ["n_samples", "mean_gpa"]].tolist() == [19, pytest.approx(4.57, abs=0.02)]
    assert season.loc["fruiting", ["n_samples", "mean_gpa"]].tolist() == [40, pytest.approx(3.00, abs=0.02)]
    duke = g[(g.grouping == "season x variety") & (g.variety == "Duke")].set_index("season")
    assert duke.loc["dormant", "mean_gpa"] == pytest.approx(4.33, abs=0.02)
    assert duke.loc["fruiting", "mean_gpa"] == pytest.approx(3.59, abs=0.02)
    allg = g[g.grouping == "all"].iloc[0]
    assert (allg.min_gpa, allg.max_gpa) == (pytest.approx(1.82, abs=0.05), pytest.approx(8.05, abs=0.05))
    tt = res.ttests
    assert 0.001 <= tt[tt.family == "season"].p.iloc[0] <= 0.002
    claimed = tt[tt.paper != ""]
    assert len(claimed) == 1 + 1 + 3 + 3
    assert (claimed.significant == claimed.paper.str.startswith(("significant", "p = "))).all()


def test_files_and_report_section(study):
    res, out = study
    for name in ("modulus.csv", "modulus_samples.csv", "modulus_groups.csv", "modulus_tests.csv",
                 "modulus_meta.json", "modulus_by_season.png", "modulus_fruiting.png"):
        assert (out / name).is_file() and out / name in res.files, name
    assert len(pd.read_csv(out / "modulus.csv")) == 177
    page = modulus_section_html(out)
    assert "SYNTHETIC" in page and "modulus_fruiting.png" in page and "Welch" in page and "0.0015" in page


def test_bundled_set_is_labelled_and_is_what_the_generator_writes(tmp_path, truth):
    from canebench.canes.generate_modulus import generate

    for p in [DATA / "samples.csv", *(DATA / "tests").glob("*.csv")]:
        assert p.read_text().startswith("# SYNTHETIC"), p
    assert set(pd.read_csv(DATA / "samples.csv", comment="#").notes) == {"SYNTHETIC"}
    assert bundled_bending_dataset() == DATA.resolve()
    out = generate(tmp_path / "regen", seed=truth["seed"])
    for p in [DATA / "samples.csv", *(DATA / "tests").glob("*.csv")]:
        assert (out / p.relative_to(DATA)).read_text() == p.read_text(), p
    # to 1e-12: the last digit of a float moves with the CPU's vector paths (the CSVs, rounded, match exactly)
    _assert_same(json.loads((out / "truth" / "truth.json").read_text()), truth)


def _assert_same(a, b, where="truth"):
    """``a == b`` for a JSON document, but floats to 1e-12: the last digit moves with the CPU's vector paths."""
    assert type(a) is type(b) or {type(a), type(b)} <= {int, float}, where
    if isinstance(a, dict):
        assert a.keys() == b.keys(), where
        for k in a:
            _assert_same(a[k], b[k], f"{where}.{k}")
    elif isinstance(a, list):
        assert len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b)):
            _assert_same(x, y, f"{where}[{i}]")
    elif isinstance(a, float):
        assert a == pytest.approx(b, rel=1e-12, abs=0), where
    else:
        assert a == b, where


# ------------------------------------------------------------------ t-tests


def test_welch_flags_a_large_difference_and_not_identical_groups():
    rng = np.random.default_rng(3)
    a = pd.Series(rng.normal(4.5, 0.5, 15))
    assert welch(a, a + 2.0)[2] < 1e-6
    assert welch(a, a.copy())[2] == pytest.approx(1.0)
    smp = pd.DataFrame({"season": ["fruiting"] * 30, "variety": ["A"] * 10 + ["B"] * 10 + ["C"] * 10,
                        "age": ["1-year"] * 30, "E_gpa": np.r_[a[:10], a[:10] + 3.0, a[:10]]})
    tt = welch_tests(smp).set_index(["group_a", "group_b"])
    assert tt.loc[("A", "B"), "significant"] and tt.loc[("B", "C"), "significant"]
    assert not tt.loc[("A", "C"), "significant"] and tt.loc[("A", "C"), "p"] == pytest.approx(1.0)


# ------------------------------------------------------------------ validation


def _good(tmp_path: Path) -> Path:
    return _write_dataset(tmp_path, {"a": [_linear_then_soft(3000.0)]})


@pytest.mark.parametrize("edit, match", [
    (lambda t: t.replace(",caliper_3_mm", ",caliper_x"), r"samples.csv: field 'caliper_3_mm': missing column"),
    (lambda t: t.replace("203.2", "nan"), r"samples.csv: field 'span_mm': line 2: not a finite number"),
    (lambda t: t.replace("203.2", "-203.2"), r"samples.csv: field 'span_mm': line 2: must be > 0"),
    (lambda t: t.replace("203.2,8,8", "203.2,8,-8"), r"samples.csv: field 'caliper_2_mm': line 2: must be > 0"),
    (lambda t: t.replace("Duke", ""), r"samples.csv: field 'variety': line 2: empty"),
    (lambda t: t + t.splitlines()[1] + "\n", r"samples.csv: field 'sample_id': line 3: 'a' also used"),
])
def test_samples_csv_errors_name_file_line_and_column(tmp_path, edit, match):
    root = _good(tmp_path)
    (root / "samples.csv").write_text(edit((root / "samples.csv").read_text()))
    with pytest.raises(InputError, match=match):
        read_bending_dataset(root)


def test_test_csv_errors_name_file_line_and_column(tmp_path):
    root = _good(tmp_path)
    p = root / "tests" / "a_test1.csv"
    lines = p.read_text().splitlines()
    p.write_text("\n".join(lines[:5] + [lines[5].split(",")[0] + ",nan"] + lines[6:]) + "\n")
    with pytest.raises(InputError, match=r"a_test1.csv: field 'force_n': line 6: not a finite number"):
        read_bending_dataset(root)
    p.write_text("# comment\n" + "\n".join(lines[:4] + ["0.0,1.0"] + lines[5:]) + "\n")
    with pytest.raises(InputError, match=r"a_test1.csv: field 'displacement_mm': line 6: displacement decreases"):
        read_bending_dataset(root)
    p.write_text("\n".join(x.split(",")[0] for x in lines) + "\n")
    with pytest.raises(InputError, match=r"a_test1.csv: field 'force_n': missing column"):
        read_bending_dataset(root)
    p.write_text("\n".join(lines) + "\n")
    (root / "tests" / "zz_test1.csv").write_text(p.read_text())
    with pytest.raises(InputError, match=r"zz_test1.csv: field '<file name>': sample 'zz' is not in samples.csv"):
        read_bending_dataset(root)
    (root / "tests" / "zz_test1.csv").unlink()
    p.unlink()
    with pytest.raises(InputError, match=r"samples.csv:2: field 'sample_id': sample 'a' has no test file"):
        read_bending_dataset(root)


# ------------------------------------------------------------------ distributions


@pytest.mark.parametrize("name", ["dormant", "fruiting", "dormant-duke", "fruiting-duke", "all"])
def test_paper_distributions_sample_within_bounds_with_the_stated_mean(name):
    d = MODULUS_DISTRIBUTIONS[name]
    x = d.sample(200_000, np.random.default_rng(7))
    assert x.min() >= d.lower_pa and x.max() <= d.upper_pa
    assert (d.lower_pa, d.upper_pa) == (pytest.approx(1.82e9), pytest.approx(8.05e9))
    # standard error sd / sqrt(2e5) is under 0.1 % of the mean; 0.5 % is 5+ standard errors
    assert x.mean() == pytest.approx(d.mean_pa, rel=5e-3) and x.std() == pytest.approx(d.sd_pa, rel=1e-2)
    assert d.frozen().mean() == pytest.approx(d.mean_pa, rel=1e-12) and d.frozen().std() == pytest.approx(d.sd_pa)
    assert d.ppf(0.0) == pytest.approx(d.lower_pa) and d.ppf(1.0) == pytest.approx(d.upper_pa)
    assert "paper" in d.provenance and json.dumps(d.to_dict())


def test_paper_means_and_tags():
    m = {n: MODULUS_DISTRIBUTIONS[n].mean_pa / 1e9 for n in ("dormant", "fruiting", "dormant-duke", "fruiting-duke")}
    assert m == pytest.approx({"dormant": 4.57, "fruiting": 3.00, "dormant-duke": 4.33, "fruiting-duke": 3.59})
    assert MODULUS_DISTRIBUTIONS.names("paper", "variety:duke") == ["dormant-duke", "fruiting-duke"]


def test_distributions_fitted_from_a_study(study):
    res, out = study
    for reg in (distributions_from_result(res), distributions_from_result(out)):
        g = res.samples[(res.samples.season == "fruiting") & (res.samples.variety == "Liberty")].E_gpa
        d = reg["fruiting-liberty"]
        assert d.mean_pa == pytest.approx(g.mean() * 1e9) and d.sd_pa == pytest.approx(g.std() * 1e9)
        assert d.n == 14 and "SYNTHETIC" in d.provenance
        assert "fruiting-liberty" in reg.names("fitted", "season:fruiting", "variety:liberty")
        x = d.sample(50_000, 1)
        assert x.min() >= d.lower_pa and x.max() <= d.upper_pa and x.mean() == pytest.approx(d.mean_pa, rel=5e-3)
        assert {"dormant", "fruiting", "fruiting-duke", "fruiting-age-new"} <= set(reg)


def test_impossible_distribution_is_refused():
    with pytest.raises(InputError, match="sd_pa.*too large"):
        ModulusDistribution("x", 3e9, 3e9, 1.82e9, 8.05e9, "test")
    with pytest.raises(InputError, match="mean_pa.*not inside"):
        ModulusDistribution("x", 9e9, 1e9, 1.82e9, 8.05e9, "test")
