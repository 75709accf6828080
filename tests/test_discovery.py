"""The discovery workflow: effects on every engine, the screen, model files, onsets, naming on hidden data."""

from __future__ import annotations

import html
import json
import math
import warnings

import numpy as np
import pandas as pd
import pytest

from canebench.errors import InputError
from canebench.model.chain import build_chain
from canebench.model.config import ModelConfig
from canebench.studies.convergence import straight_cantilever

E, L, D = 4.57e9, 1.2, 0.012
I_AREA = math.pi * D**4 / 64


def _cantilever_k(extra_compliance: float = 0.0) -> float:
    return 1.0 / (L**3 / (3 * E * I_AREA) + extra_compliance)


@pytest.fixture(scope="module")
def cantilever():
    return straight_cantilever(False)


def _cfg(*effects: str) -> ModelConfig:
    return ModelConfig(effects=effects, gravity=0.0, stiffness_formula="dual_length", discretization="uniform",
                       segments=40)


def test_root_compliance_reaches_beam_and_chain_as_the_closed_form(cantilever):
    """Tip of a uniform cantilever on a root spring: C = L^3/3EI + L^2/k_root (Euler-Bernoulli, exact)."""
    from canebench.backends.beam_backend import BeamStatic
    from canebench.backends.pinocchio_backend import rest_linear_stiffness

    k_root = 50.0
    chain = build_chain(cantilever, cantilever.push_points[0].id, _cfg(f"root_compliance(k_root={k_root})"))
    exact = _cantilever_k(L**2 / k_root)
    # the beam is converged to 1e-4 by construction; the 40-link chain's own error is 3e-4 at the tip
    assert BeamStatic(chain).linear_stiffness() == pytest.approx(exact, rel=2e-4)
    assert rest_linear_stiffness(chain) == pytest.approx(exact, rel=1e-3)
    plain = build_chain(cantilever, cantilever.push_points[0].id, _cfg())
    assert 1 / chain.stiffness[0] == pytest.approx(1 / plain.stiffness[0] + 1 / k_root, rel=1e-12)


def test_modulus_misalignment_and_flare_change_every_model_alike(cantilever):
    from canebench.backends.beam_backend import BeamStatic
    from canebench.backends.pinocchio_backend import rest_linear_stiffness

    pid = cantilever.push_points[0].id
    k0 = BeamStatic(build_chain(cantilever, pid, _cfg())).linear_stiffness()
    assert k0 == pytest.approx(_cantilever_k(), rel=2e-4)
    ks = BeamStatic(build_chain(cantilever, pid, _cfg("modulus_scale(scale=1.7)"))).linear_stiffness()
    assert ks / k0 == pytest.approx(1.7, rel=1e-6)
    # a straight cantilever pushed at pitch a: axially rigid, so F = k d / cos^2 a
    for a in (10.0, 25.0):
        c = build_chain(cantilever, pid, _cfg(f"probe_misalignment(angle_deg={a})"))
        assert BeamStatic(c).linear_stiffness() / k0 == pytest.approx(1 / math.cos(math.radians(a)) ** 2, rel=1e-3)
    c = build_chain(cantilever, pid, _cfg("base_flare(excess_mm=6, length_mm=100)"))
    kb, kc = BeamStatic(c).linear_stiffness(), rest_linear_stiffness(c)
    assert kb > 1.3 * k0  # a thicker base stiffens the cantilever...
    assert kc == pytest.approx(kb, rel=2e-3)  # ...in the chain as in the beam


def test_screen_is_the_beams_linear_stiffness_with_every_effect():
    from canebench.backends.beam_backend import BeamStatic
    from canebench.data.dataset import bundled_dataset, load_dataset
    from canebench.discovery.screen import trial_geometry
    from canebench.model.presets import PRESETS

    cfg = PRESETS["beam-consistent"].replace(gravity=0.0)
    eff = ("root_compliance(k_root=20)", "base_flare(excess_mm=4, length_mm=80)",
           "probe_misalignment(angle_deg=15)", "modulus_scale(scale=1.3)")
    for t in load_dataset(bundled_dataset(), "b2c1t1,b5c3t3"):
        g = trial_geometry(t, cfg)
        for e in ((), eff):
            c = cfg.replace(effects=e)
            cc, _ = g.compliance(c.applied_effects(t.cane.id, t.id) if e else None)
            kb = BeamStatic(build_chain(t.cane, t.push_id, c)).linear_stiffness()
            # two independent small-deflection solutions of one rod: quadrature vs RK4 shooting (1e-4 mesh)
            assert 1 / cc == pytest.approx(kb, rel=2e-4)


def test_screen_prediction_is_the_engines_answer_for_every_screened_effect():
    """The vectorised screen the selection uses (ScreenSet, k in N/mm) against Pinocchio: the
    rig through the whole pipeline (it acts on the measured trace), the rest against the exact
    linear statics of the effect's chain. Catches unit slips between the screen and the
    pipeline (the rig's series compliance is in m/N, stiffness in N/mm)."""
    from canebench.backends.pinocchio_backend import rest_linear_stiffness
    from canebench.data.dataset import bundled_dataset, load_dataset
    from canebench.discovery.screen import trial_geometry
    from canebench.discovery.screenset import Anchored, ScreenSet
    from canebench.execute.executors import make_executor
    from canebench.execute.runner import run_trials
    from canebench.model.effects import EffectSpec
    from canebench.model.presets import PRESETS
    from canebench.probe.protocol import PROTOCOLS

    # without gravity: the screen is the linear stiffness about the unloaded cane
    cfg = PRESETS["beam-consistent"].replace(gravity=0.0)
    trials = load_dataset(bundled_dataset(), "b2c1t1,b4c2t3,b5c3t3")
    ss = ScreenSet.build([trial_geometry(t, cfg) for t in trials])
    by_id = {t.id: t for t in trials}
    ex = make_executor("serial", 1, None)

    def run(c):
        return run_trials(trials, ["pinocchio"], PROTOCOLS["fast"], c, executor=ex).to_df().set_index(
            "trial").k_sim.reindex(ss.trials).to_numpy(float)

    k0 = run(cfg)
    e = "rig_compliance(k_rig=150)"
    pred = np.exp(Anchored(ss, np.log(k0)).predict((EffectSpec.parse(e),)))
    k1 = run(cfg.replace(effects=(e,)))
    assert abs(np.log(k1 / k0)).max() > 0.05  # large enough to test
    # 2 %: the probe's trace is fitted over a finite push (test below)
    np.testing.assert_allclose(pred, k1, rtol=0.02, err_msg=e)

    def lin(c):
        return np.array([rest_linear_stiffness(build_chain(by_id[t].cane, by_id[t].push_id, c)) for t in ss.trials])

    l0 = lin(cfg)
    for e in ("root_compliance(k_root=40)", "modulus_scale(scale=0.6)", "base_flare(excess_mm=5, length_mm=120)",
              "probe_misalignment(angle_deg=-20)"):
        l1 = lin(cfg.replace(effects=(e,)))
        ratio = np.exp(Anchored(ss, np.zeros(len(l0))).predict((EffectSpec.parse(e),)))
        assert abs(np.log(l1 / l0)).max() > 0.05, e
        # the 20-link chain against the beam quadrature: 2e-3 as in the tests above, except where a
        # soft root dominates (k drops ~10x at k_root = 40): the chain's root spring sits at its
        # first joint and measures 0.6 % stiffer than the beam's root there
        np.testing.assert_allclose(ratio, l1 / l0, rtol=1e-2 if e.startswith("root") else 2e-3, err_msg=e)


def test_rig_compliance_is_a_spring_in_series_with_the_measured_trace():
    from canebench.data.dataset import bundled_dataset, load_dataset
    from canebench.execute.runner import run_trials
    from canebench.execute.executors import make_executor
    from canebench.probe.protocol import PROTOCOLS

    trials = load_dataset(bundled_dataset(), "b3c2t1")
    ex = make_executor("serial", 1, None)
    k0 = run_trials(trials, ["pinocchio"], PROTOCOLS["fast"], ModelConfig(), executor=ex).to_df().k_sim.iloc[0]
    k_rig = 200.0
    k1 = run_trials(trials, ["pinocchio"], PROTOCOLS["fast"], ModelConfig(effects=(f"rig_compliance(k_rig={k_rig})",)),
                    executor=ex).to_df().k_sim.iloc[0]
    # N/mm; the series rule is exact for a linear cane, the probe's trace bends by a few per cent
    assert 1 / k1 == pytest.approx(1 / k0 + 1 / (k_rig * 1e-3), rel=0.02)


def test_model_file_round_trip_and_bad_files(tmp_path):
    from canebench.model.modelfile import load_model_file, write_model_file
    from canebench.model.presets import PRESETS

    cfg = PRESETS["beam-consistent"].replace(effects=(
        "root_compliance(k_root=42)",
        {"effect": "obstruction", "scope": "per_trial", "local": {"b1c1t2": {"onset_mm": 12.5}}}))
    p = write_model_file(tmp_path / "m.yaml", cfg, "beam-consistent", {"root_compliance": {"k_root": [30, 60]}})
    back = load_model_file(p)
    assert back == cfg
    assert back.fit_window_mm("b1c1", "b1c1t2") == 12.5 and back.fit_window_mm("b1c1", "b1c1t1") is None
    bad = {"effects: [{effect: wind}]": "wind", "effects: [{effect: root_compliance, params: {k_root: -1}}]": "k_root",
           "preset: nope": "preset", "colour: red": "colour", "effects: {a: 1}": "effects", "[1, 2": "<file>",
           # values of the wrong type reached the checks (or difflib) and raised a TypeError (session 66)
           "config: {modulus_pa: [1, 2]}": "modulus_pa", "config: {density: {a: 1}}": "density",
           "config: {diameter_factor: null}": "diameter_factor", "config: {min_segments: 2.5}": "min_segments",
           "config: {stiffness_formula: 5}": "stiffness_formula", "config: {node_at_push: 3}": "node_at_push",
           "config: {modulus_pa: true}": "modulus_pa", "preset: [paper]": "preset",
           "effects: [{effect: probe_misalignment, params: {angle_deg: 1.0e6}}]": "angle_deg",
           "effects: [{effect: obstruction, params: {onset_mm: -5}}]": "onset_mm",
           # the probe's pitch is the configuration's plus the effect's
           "config: {probe_angle_deg: 60}\neffects: [{effect: probe_misalignment, params: {angle_deg: 60}}]": "angle_deg",
           "effects: [{effect: probe_misalignment, params: {angle_deg: 89}}]": "angle_deg",
           # a key given twice: PyYAML keeps the last without a word
           "effects: [{effect: root_compliance, params: {k_root: 120, k_root: 5}}]": "given twice"}
    for text, field in bad.items():
        (tmp_path / "bad.yaml").write_text(text)
        with pytest.raises(InputError, match=field) as ei:
            load_model_file(tmp_path / "bad.yaml")
        assert "bad.yaml" in str(ei.value)
    # within the search bounds no warning; a valid value outside the physical range is warned about, once
    from canebench.errors import InputWarning

    for text, warned in (("{effect: modulus_scale, params: {scale: 50}}", True),
                         ("{effect: rig_compliance, params: {k_rig: 1.0e-6}}", True),
                         ("{effect: modulus_scale, params: {scale: 1.2}}", False),
                         # a spring stiffer than its search bound is nearer rigid, no implausible plant
                         ("{effect: rig_compliance, params: {k_rig: 1.0e6}}", False),
                         ("{effect: root_compliance, params: {k_root: 1.0e4}}", False)):
        (tmp_path / "w.yaml").write_text(f"effects: [{text}]")
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            load_model_file(tmp_path / "w.yaml")
        got = [w for w in caught if issubclass(w.category, InputWarning)]
        assert len(got) == int(warned) and (not warned or "physically plausible" in str(got[0].message)), got
    assert load_model_file(tmp_path / "w.yaml").replace(min_segments=4).min_segments == 4
    cfg = PRESETS["default"].with_overrides({"min_segments": 4.0, "modulus_pa": 4e9}, source="f.yaml")
    assert cfg.min_segments == 4 and isinstance(cfg.min_segments, int)


def test_onset_finds_kinks_not_curvature():
    from canebench.discovery.onsets import detect_onset

    rng = np.random.default_rng(3)
    x = np.arange(0, 40, 0.5)
    noise = rng.normal(0, 0.02, len(x))  # 2 gf
    kink = 0.05 * x + 0.3 * np.maximum(x - 22.0, 0) + noise
    o = detect_onset(x, kink)
    assert o is not None and abs(o.onset_mm - 22.0) <= 1.0
    smooth_up = 0.05 * x + 0.002 * x**2 + noise  # large-deflection stiffening: no second body
    assert detect_onset(x, smooth_up) is None
    assert detect_onset(x, 0.05 * x + noise) is None
    # a weaker second body, 1.6 times the slope (as an independently generated set's, whose load
    # cell is quieter: 1 gf), is found; smooth curves stiffening as much or twice as much over
    # the push are not; a body adding less than half the slope is not an obstruction
    quiet = noise / 2
    o = detect_onset(x, 0.05 * x + 0.03 * np.maximum(x - 22.0, 0) + quiet)
    assert o is not None and abs(o.onset_mm - 22.0) <= 1.5 and 1.4 < o.slope_after / o.slope_before < 1.9
    assert detect_onset(x, 0.05 * x + 0.0004 * x**2 + quiet) is None
    assert detect_onset(x, 0.05 * x + 0.0008 * x**2 + quiet) is None
    assert detect_onset(x, 0.05 * x + 0.015 * np.maximum(x - 22.0, 0) + quiet) is None


def _rig(x: np.ndarray, f: np.ndarray):
    from canebench.data.rig import RigTrial

    return RigTrial("synthetic.csv", x, f, 0.5 * np.arange(len(x)), 500.0)


def test_a_soft_contact_hidden_in_the_tare_stretch_is_an_obstruction():
    """A cane rising 0.5 gf/mm (8 gf over 16 mm, noise 2 gf) before a second body adds 3 gf/mm:
    the field stage's flat-then-line knee lands on the second body, the early-contact check
    finds the ramp; a flat tare, and a contact start that is merely lumpy, are left alone."""
    from canebench.discovery.onsets import detect_early_contact
    from canebench.measure.field import extract_field_stiffness

    rng = np.random.default_rng(5)
    x = np.arange(0, 50, 0.5)
    contact, onset = 6.0, 16.0
    cane = 0.5 * np.maximum(x - contact, 0)
    second = 3.0 * np.maximum(x - contact - onset, 0)
    f = -15.0 + cane + second + rng.normal(0, 2.0, len(x))
    fit = extract_field_stiffness(_rig(x, f))
    # the failure this exists for: the field stage takes the ramp for tare
    assert fit.onset_mm > contact + 0.6 * onset
    e = detect_early_contact(x, f, fit.onset_mm)
    assert e is not None
    assert abs(e.contact_mm - contact) <= 3.0 and abs(e.contact_mm + e.onset_mm - (contact + onset)) <= 3.0
    assert e.slope_after > 4 * e.slope_before
    # a flat tare stretch, then a cane: nothing before the knee
    flat = -15.0 + 4.0 * np.maximum(x - 10.0, 0) + rng.normal(0, 2.0, len(x))
    assert detect_early_contact(x, flat, extract_field_stiffness(_rig(x, flat)).onset_mm) is None
    # a lumpy start (3.3 then 5.9 gf/mm, as real b6c2t1): the slope ratio is below EARLY_MIN_RATIO
    lumpy = -5.0 + 3.3 * np.clip(x - 2.5, 0, 3.0) + 5.9 * np.maximum(x - 5.5, 0) + rng.normal(0, 2.0, len(x))
    assert detect_early_contact(x, lumpy, 5.5) is None
    # long tare stretches (5-40 mm) before clean contacts of any stiffness: the flat level's own
    # uncertainty must not pass for a ramp (an earlier version flagged 2 in 360 of these)
    flagged = []
    for _ in range(150):
        tare = rng.uniform(5, 40)
        xx = np.arange(0, tare + 40, 0.5)
        ff = rng.uniform(-60, 10) + rng.uniform(0.3, 20) * np.maximum(xx - tare, 0) + rng.normal(0, 2.0, len(xx))
        if detect_early_contact(xx, ff, extract_field_stiffness(_rig(xx, ff)).onset_mm) is not None:
            flagged.append(tare)
    assert flagged == []
    # contact starts that round over 0.5-3 mm as the probe seats (softplus onsets, noise 0.3-2 gf,
    # canes of 0.5-20 gf/mm): a hinge finds a ramp of 3 mm at half the slope after it, which an
    # earlier version took for a soft cane before a second body in 22 of 50 such traces
    rounded = []
    for _ in range(100):
        w, k = rng.uniform(0.5, 3.0), rng.uniform(0.5, 20.0)
        xx = np.arange(0, 70, 0.5)
        ff = 25.0 + k * w * np.logaddexp(0, (xx - 5.0) / w) + rng.normal(0, rng.uniform(0.3, 2.0), len(xx))
        if detect_early_contact(xx, ff, extract_field_stiffness(_rig(xx, ff)).onset_mm) is not None:
            rounded.append((w, k))
    assert rounded == []


def test_an_elbow_inside_the_knee_search_does_not_pull_the_contact_late(tmp_path):
    """A soft cane (2.4 gf/mm from 6 mm) meets a second body 16 mm later (9.4 gf/mm after): the
    field stage's flat-then-line knee, searched until the force has risen 150 gf, spans ramp
    and elbow with one line and lands inside the ramp, so the onset counted from it is too
    early (an independent generator's softest obstructed trials: 6-10 mm), and the early-contact
    check takes the ramp before the knee for a soft cane before a second body at the knee. The
    record up to the elbow puts contact and onset where they are, its slope is the cane's, the
    early-contact check searches before that contact (and finds nothing), and the field stage
    given the cut reads the same fit. A stiff cane whose elbow lies beyond the knee's search
    keeps its knee and onset. A third body on a soft cane (a ramp of 0.5 gf/mm from 6 mm, a
    second body at 22 mm, a third at 34 mm) moves the contact to the second body, and the ramp
    before it is an early contact there."""
    from types import SimpleNamespace

    from canebench.discovery.contacts import contacts_before_elbows, early_contacts, field_onsets
    from canebench.execute.pipeline import FieldResult, field_fit_for
    from canebench.measure.field import extract_field_stiffness
    from canebench.model.config import ModelConfig
    from canebench.model.effects import EffectSpec

    rng = np.random.default_rng(3)
    x = np.arange(0, 60, 0.5)
    cases = {"soft": (6.0, 2.4, 16.0, 7.0, 0.0), "stiff": (6.0, 12.0, 16.0, 24.0, 0.0),
             "third": (6.0, 0.5, 16.0, 2.5, 9.0)}  # contact, slope, onset, added, added by a third body
    fields, rows = {}, ["Iteration,Time Stamp,Load Cell Reading (gf),Displacement (mm),Height (mm)"]
    for name, (c, k, o, k2, k3) in cases.items():
        f = (-40.0 + k * np.maximum(x - c, 0) + k2 * np.maximum(x - c - o, 0) + k3 * np.maximum(x - 34.0, 0)
             + rng.normal(0, 0.3 if k3 else 0.5, len(x)))
        f = f[f < 1000.0]
        csv = tmp_path / f"{name}.csv"
        csv.write_text("\n".join(rows + [f"{i + 2},{500 * i},{v:.2f},{100 + x[i]},700" for i, v in enumerate(f)]))
        ff = extract_field_stiffness(_rig(x[: len(f)], f))
        fields[name] = FieldResult(SimpleNamespace(csv=csv), ff, ff.reason)
    assert fields["soft"].fit.onset_mm > 6.0 + 3.0  # the bias: the knee inside the ramp
    assert abs(fields["stiff"].fit.onset_mm - 6.0) <= 1.0
    onsets = field_onsets(fields)
    assert {"soft", "stiff"} <= set(onsets)
    assert onsets["soft"] < 16.0 - 3.0
    moved = contacts_before_elbows(onsets, fields)
    assert set(moved) == set(onsets) - {"stiff"}
    ff = moved["soft"].fit
    assert abs(ff.onset_mm - 6.0) <= 1.0
    assert abs(moved["soft"].onset_mm - 16.0) <= 1.0
    assert abs(moved["soft"].record_end_mm - 22.0) <= 1.0
    assert ff.k_n_per_mm == pytest.approx(2.4 * 9.80665e-3, rel=0.05)
    assert abs(onsets["stiff"] - 16.0) <= 1.0
    # the obstruction effect carries the cut: the field stage of any run reads the same fit
    spec = EffectSpec("obstruction", (), (("soft", (("onset_mm", moved["soft"].onset_mm),
                                                    ("record_end_mm", moved["soft"].record_end_mm))),), "per_trial")
    cfg = ModelConfig().replace(effects=(spec,))
    assert cfg.record_end_mm("c", "soft") == moved["soft"].record_end_mm
    assert cfg.record_end_mm("c", "stiff") is None
    again = field_fit_for(fields["soft"].trial, cfg.fit_window_mm("c", "soft"), cfg.record_end_mm("c", "soft"))
    assert (again.onset_mm, again.k_n_per_mm) == (ff.onset_mm, ff.k_n_per_mm)
    # the ramp before the late knee, and the elbow after it, read as an early contact (a soft cane
    # before a second body at the knee); before the moved contact there is no ramp
    knees = {k: m.fit.onset_mm for k, m in moved.items()}
    assert "soft" in early_contacts(fields)
    assert "soft" not in early_contacts(fields, knees=knees)
    # the third body's elbow moves the contact to the second body (the hinge's flat part is the
    # ramp's mean, so its knee comes up to a few mm before 22), before which the cane's ramp is
    assert 16.0 <= moved["third"].fit.onset_mm <= 22.5
    assert abs(early_contacts(fields, knees=knees)["third"].contact_mm - 6.0) <= 1.0


def test_a_load_cell_drifting_before_contact_is_not_a_contact_before_an_obstruction():
    """A load cell settling by +5 gf (time constant 6 mm) from the record's start, then a cane of
    3 gf/mm from 11 mm: the trace's shape alone reads a soft ramp, then a slope 5-10 times
    steeper, as a contact before a second body (an independent generator's drifts gave 14 such
    false obstructions in 16 sets). The model places the cane: the slope after the knee is
    what the cane's other pushes give, so the ramp is a drift; the soft contact of the test
    above keeps its ramp. Both hold with the model 2x off, as long as the cane's other pushes
    show the same offset (the level)."""
    from types import SimpleNamespace

    from canebench.discovery.onsets import detect_early_contact, ramp_is_the_cane
    from canebench.discovery.contacts import split_early_contacts
    from canebench.measure.field import extract_field_stiffness

    rng = np.random.default_rng(11)
    x = np.arange(0, 44, 0.5)
    drift = -40.0 + 5.0 * (1 - np.exp(-x / 6.0)) + 3.0 * np.maximum(x - 11.0, 0) + rng.normal(0, 0.3, len(x))
    fit = extract_field_stiffness(_rig(x, drift))
    assert abs(fit.onset_mm - 11.0) <= 1.0  # the field stage itself finds the contact
    e = detect_early_contact(x, drift, fit.onset_mm)
    assert e is not None and e.slope_after > 5 * e.slope_before  # the shape alone is fooled
    soft = -15.0 + 0.5 * np.maximum(x - 6.0, 0) + 3.0 * np.maximum(x - 22.0, 0) + rng.normal(0, 0.3, len(x))
    e_soft = detect_early_contact(x, soft, extract_field_stiffness(_rig(x, soft)).onset_mm)
    assert e_soft is not None
    for bias in (1.0, 0.5, 2.0):  # k_model = bias * the cane's true slope; the level is -ln(bias)
        assert not ramp_is_the_cane(e, 3.0 * bias, -np.log(bias))
        assert ramp_is_the_cane(e_soft, 0.5 * bias, -np.log(bias))
    assert ramp_is_the_cane(e, float("nan"), 0.0)  # nothing to compare with: the shape decides, as before

    # the workflow's split: levels from the cane's other pushes and from all pushes; a drift only
    # when neither puts the cane nearer the ramp (the cane's other push may hide an elbow)
    gf = 9.80665e-3
    trials = [SimpleNamespace(id=f"c{c}t{i}", cane=SimpleNamespace(id=f"c{c}")) for c in range(4) for i in range(3)]
    k_cane = {"c0": 3.0, "c1": 0.5, "c2": 3.0, "c3": 3.0}  # gf/mm; c1 is the soft cane; the model is right
    geoms = {t.id: SimpleNamespace(compliance=lambda k=k_cane[t.cane.id]: (1e-3 / (k * gf), 0.0)) for t in trials}
    fields = {t.id: SimpleNamespace(k=k_cane[t.cane.id] * gf) for t in trials}
    kept, drifts = split_early_contacts({"c0t0": e, "c1t0": e_soft}, trials, geoms, fields, {})
    assert set(drifts) == {"c0t0"} and set(kept) == {"c1t0"}
    fields["c1t1"] = fields["c1t2"] = SimpleNamespace(k=8 * 0.5 * gf)  # the soft cane's other pushes: elbows missed
    kept, drifts = split_early_contacts({"c1t0": e_soft}, trials, geoms, fields, {})
    assert set(kept) == {"c1t0"}  # the data's level still places the cane at the ramp
    kept, drifts = split_early_contacts({"c0t0": e}, trials, geoms, {}, {})
    assert set(kept) == {"c0t0"}  # no level at all: as before
    # pushes with an onset of their own give no level: c0's other two pushes read 8x below the
    # model (as a cane's own level that would keep its ramp); with onsets there, only the data's
    # level is left, and it calls the ramp a drift
    fields = {t.id: SimpleNamespace(k=k_cane[t.cane.id] * gf) for t in trials}
    fields["c0t1"] = fields["c0t2"] = SimpleNamespace(k=3.0 / 8 * gf)
    kept, drifts = split_early_contacts({"c0t0": e}, trials, geoms, fields, {})
    assert set(kept) == {"c0t0"}
    kept, drifts = split_early_contacts({"c0t0": e}, trials, geoms, fields, {"c0t1": 10.0, "c0t2": 12.0})
    assert set(drifts) == {"c0t0"}


@pytest.mark.field
def test_no_real_trial_has_a_hidden_soft_contact(field_dir):
    """Of the 54 real trials, only four have ten or more samples before the contact knee, and
    none of those rises softly and then steepens: the check must not remove real data."""
    from canebench.data.dataset import load_dataset
    from canebench.data.rig import read_rig_csv
    from canebench.discovery.onsets import detect_early_contact
    from canebench.measure.field import extract_field_stiffness

    hits = []
    for t in load_dataset(field_dir):
        rig = read_rig_csv(t.csv)
        if detect_early_contact(rig.displacement_mm, rig.force_gf, extract_field_stiffness(rig).onset_mm):
            hits.append(t.id)
    assert hits == []


def test_an_anchored_screen_is_the_same_screen_moved_to_the_anchor(bundled_trials):
    """Re-anchoring on an engine changes only the linearization point: with the anchor's
    stiffness taken from the screen itself, every prediction is the un-anchored one (the rig's
    series part included), and at the anchor the prediction is the anchor's stiffness."""
    from canebench.discovery.screen import trial_geometry
    from canebench.discovery.screenset import Anchored, ScreenSet
    from canebench.model.effects import EffectSpec
    from canebench.model.presets import PRESETS

    cfg = PRESETS["beam-consistent"]
    ss = ScreenSet.build([trial_geometry(t, cfg) for t in bundled_trials[:9]])
    lkb = np.log(np.linspace(0.01, 0.3, len(ss.trials)))
    anchor = (EffectSpec.parse("root_compliance(k_root=20)"), EffectSpec.parse("rig_compliance(k_rig=300)"))
    lka = Anchored(ss, lkb).predict(anchor)
    sa = ss.anchored(anchor)
    for specs in [(), (EffectSpec.parse("rig_compliance(k_rig=80)"),),
                  (EffectSpec.parse("base_flare(excess_mm=6, length_mm=200)"),
                   EffectSpec.parse("probe_misalignment(angle_deg=20)"),
                   EffectSpec.parse("rig_compliance(k_rig=1000)"))]:
        np.testing.assert_allclose(Anchored(sa, lka).predict(specs), Anchored(ss, lkb).predict(specs), rtol=0, atol=1e-10)
    # and the anchor survives subsetting (cross-validation folds) and resampling (the bootstrap)

    keep = np.arange(len(ss.trials)) % 2 == 0
    np.testing.assert_allclose(Anchored(sa.subset(keep), lka[keep]).predict(()), lkb[keep], rtol=0, atol=1e-10)
    rows = np.array([0, 0, 3, 5, 8])
    tk = sa.take(rows, np.array(["a", "a", "b", "c", "d"]))
    np.testing.assert_allclose(Anchored(tk, lka[rows]).predict(()), lkb[rows], rtol=0, atol=1e-10)
    # Anchored carries its ln k along with every cut of its screen (what the fits are given)
    at = Anchored(sa, lka)
    np.testing.assert_allclose(at.subset(keep).predict(()), lkb[keep], rtol=0, atol=1e-10)
    at_rows = at.take(rows, np.array(["a", "a", "b", "c", "d"]))
    np.testing.assert_allclose(at_rows.predict(()), lkb[rows], rtol=0, atol=1e-10)
    assert list(at_rows.screen.canes) == ["a", "a", "b", "c", "d"]
    # at the anchor its ln k comes back as it is, and recomputed through the caliper line's own
    # diameters (which leaves the anchor) it comes back to rounding; 10 % thicker moves even the
    # anchor's own model, stiffer, but less than (1.1)^4 on the cane's part: the root's 20 N m/rad and
    # the rig's 300 N/m do not scale with the section
    np.testing.assert_array_equal(at.predict(anchor), lka)
    np.testing.assert_allclose(at.with_diameters(sa.d0).predict(anchor), lka, rtol=0, atol=1e-10)
    thick = at.with_diameters(sa.d0 * 1.1).predict(anchor)
    cane = 1.0 / np.exp(lka) - 1e3 / 300.0
    assert np.all(thick > lka + 1e-4) and np.all(thick < -np.log(cane / 1.1**4 + 1e3 / 300.0))


def test_the_screen_s_per_trial_sums_are_its_pass_over_every_point(bundled_trials):
    """A model that leaves the diameter alone is evaluated from three sums per trial; one that
    changes it, by a pass over every quadrature point. A flare with no excess changes nothing, so
    the two paths must agree to rounding, with the probe pitched, the modulus scaled and a root
    (the kernel's cross term and the 1/E act before and after the sums), and after a cut of the
    screen and new diameters (each starts without the sums of the screen it came from)."""
    from canebench.discovery.screen import trial_geometry
    from canebench.discovery.screenset import ScreenSet
    from canebench.model.effects import AppliedEffects, EffectSpec
    from canebench.model.presets import PRESETS

    ss = ScreenSet.build([trial_geometry(t, PRESETS["beam-consistent"]) for t in bundled_trials[:9]])
    rest = [EffectSpec.parse(e) for e in ("probe_misalignment(angle_deg=23)", "modulus_scale(scale=0.7)",
                                          "root_compliance(k_root=35)")]
    fast = AppliedEffects([s.instance() for s in rest])
    slow = AppliedEffects([s.instance() for s in rest + [EffectSpec.parse("base_flare(excess_mm=0)")]])
    assert slow.changes_diameter and not fast.changes_diameter
    for scr in (ss, ss.take(np.array([4, 4, 1])), ss.with_diameters(ss.d0 * 1.2)):
        # the same arithmetic on both paths: equal to the last bit
        np.testing.assert_array_equal(scr.compliance(fast)[0], scr.compliance(slow)[0])
        # and the pass over every point the sums replace, written out: sum of w u^T K u / (E I) per trial
        E = fast.modulus(scr.E)
        th = scr.th0 + np.deg2rad(23.0)
        c, s = np.cos(th)[scr.idx], np.sin(th)[scr.idx]
        kern = scr.kaa * c**2 + scr.kae * c * s + scr.kee * s**2
        cane = np.bincount(scr.idx, scr.w * kern / (np.pi * np.maximum(scr.d0, scr.min_d) ** 4 / 64.0),
                           minlength=len(scr.trials)) / E
        root = (scr.raa * np.cos(th) ** 2 + scr.rae * np.cos(th) * np.sin(th) + scr.ree * np.sin(th) ** 2) / 35.0
        np.testing.assert_allclose(scr.compliance(fast)[0], cane + root, rtol=1e-13, atol=0)
    # points not laid out a run per trial (summed by bincount instead) give the same sums
    from dataclasses import replace

    perm = np.random.default_rng(0).permutation(len(ss.s))
    mixed = replace(ss, **{k: getattr(ss, k)[perm] for k in ("idx", "s", "w", "d0", "kaa", "kae", "kee")})
    for fx in (fast, slow):
        np.testing.assert_allclose(mixed.compliance(fx)[0], ss.compliance(fx)[0], rtol=1e-12, atol=0)
    # 20 % thicker everywhere: the cane's part of the compliance falls by 1.2^4, the root's stays
    no_root = AppliedEffects([s.instance() for s in rest[:2]])
    np.testing.assert_allclose(ss.with_diameters(ss.d0 * 1.2).compliance(no_root)[0],
                               ss.compliance(no_root)[0] / 1.2**4, rtol=1e-12)


def test_the_held_out_gain_s_sign_test_leaves_rounding_out():
    """Per-cane gains of a candidate fitted at its null value are rounding (1e-16): they are ties,
    not 18 canes' worth of evidence. Twelve canes that all gain are significant (exact p 2^-12)."""
    from canebench.discovery.fit import sign_flip_p

    rng = np.random.default_rng(3)
    assert sign_flip_p(rng.normal(0.0, 1e-16, 18)) == 1.0
    assert sign_flip_p(np.linspace(0.01, 0.12, 12)) == pytest.approx(2.0**-12)
    assert sign_flip_p(-np.linspace(0.01, 0.12, 12)) == pytest.approx(1.0)


@pytest.mark.field
def test_onset_on_the_real_elbow(field_dir):
    from canebench.data.dataset import load_dataset
    from canebench.discovery.onsets import detect_onset
    from canebench.execute.pipeline import field_stage

    from canebench.discovery.contacts import field_onsets
    from canebench.model.config import ModelConfig
    from canebench.model.effects import EffectSpec

    t = load_dataset(field_dir, "b5c2t3")
    fields = field_stage(t)
    ff = fields["b5c2t3"].fit
    o = detect_onset(ff.displacement_mm, ff.force_n)
    # the README's elbow: 0.07 -> 1.9 N/mm near 37-40 mm
    assert o is not None and 30 <= o.onset_mm <= 42 and o.slope_after > 10 * o.slope_before
    # the elbow is what leaves the whole trace unusable (R^2 0.62): the workflow searches it all
    # the same, and up to the onset the trace is a usable line at the slope before the elbow
    assert not ff.usable and ff.only_poorly_linear
    onsets = field_onsets(fields)
    assert set(onsets) == {"b5c2t3"} and onsets["b5c2t3"] == o.onset_mm
    cut = ModelConfig().replace(effects=(EffectSpec("obstruction", (), (("b5c2t3", (("onset_mm", o.onset_mm),)),),
                                                    "per_trial"),))
    before = field_stage(t, None, cut)["b5c2t3"].fit
    assert before.usable and before.r2 > 0.9
    assert before.k_n_per_mm == pytest.approx(o.slope_before, rel=0.15)


@pytest.mark.field
def test_read_contacts_scores_the_real_elbow_with_the_config_it_returns(field_dir):
    """The contacts stage on the README's obstructed cane: its second field stage and the baseline's
    configuration are the same configuration, which differs from the base one by the obstruction only."""
    from canebench.data.dataset import load_dataset
    from canebench.discovery.contacts import read_contacts
    from canebench.execute.pipeline import field_stage
    from canebench.model.config import ModelConfig

    trials = load_dataset(field_dir, "b5c2*")
    # not the default: the config returned must be built from this one (damping plays no part in
    # a contact or a field fit)
    cfg0 = ModelConfig(damping=0.2)
    fc = read_contacts(trials, None, cfg0)
    # the README's elbow near 40 mm (the raw record: 261 gf at 38 mm, 632 gf at 40 mm, contact at
    # its first sample); the cane's other two pushes rise without one
    assert set(fc.onsets) == {"b5c2t3"} and 34 <= fc.onsets["b5c2t3"] <= 41
    assert not fc.early and not fc.recontact
    # the configuration's one effect is the obstruction, per trial, at the onset found
    assert [(e.name, e.scope) for e in fc.config.effects] == [("obstruction", "per_trial")]
    assert fc.config.effects[0].local == (("b5c2t3", (("onset_mm", fc.onsets["b5c2t3"]),)),)
    assert fc.config.replace(effects=()) == cfg0
    # the whole trace is unusable (R^2 0.62); read up to its elbow, it is scored
    assert not fc.fields0["b5c2t3"].fit.usable and fc.fields["b5c2t3"].fit.usable
    again = field_stage(trials, None, fc.config)
    for tid in ("b5c2t1", "b5c2t2", "b5c2t3"):
        assert fc.fields[tid].fit.k_n_per_mm == again[tid].fit.k_n_per_mm
    for tid in ("b5c2t1", "b5c2t2"):  # no onset: the obstruction leaves their fits alone
        assert fc.fields[tid].fit.k_n_per_mm == fc.fields0[tid].fit.k_n_per_mm


def test_third_party_effect_plugs_in(cantilever, monkeypatch):
    from canebench.model import effects as fxmod
    from canebench.model.effects import EFFECTS, Effect, Parameter

    class Stiffer(Effect):
        name = "test_stiffer_root"
        where = "base"
        parameters = {"factor": Parameter("1", 1.0, 10.0, 1.0)}

        def modulus(self, E):
            return E * self.p["factor"]

    class FakeEP:
        name, value = "test_stiffer_root", "pkg:Stiffer"

        def load(self):
            return Stiffer

    monkeypatch.setattr(fxmod, "_loaded", False)
    monkeypatch.setattr(fxmod.metadata, "entry_points", lambda group: [FakeEP()] if group == fxmod.ENTRY_POINT_GROUP else [])
    try:
        c = build_chain(cantilever, cantilever.push_points[0].id, _cfg("test_stiffer_root(factor=2)"))
        assert c.modulus == pytest.approx(2 * E)
    finally:
        if "test_stiffer_root" in EFFECTS:
            EFFECTS.remove("test_stiffer_root")


@pytest.fixture(scope="module")
def hidden_root(tmp_path_factory):
    from canebench.canes.generate_hidden import generate_hidden

    d = tmp_path_factory.mktemp("hidden") / "root"
    return generate_hidden(d, 11, {"root_compliance": {"k_root": 15.0}}, n_bushes=6)


@pytest.mark.heavy
def test_discover_names_a_hidden_root_spring_and_writes_the_contract(hidden_root, tmp_path):
    from canebench.data.dataset import load_dataset
    from canebench.discovery.workflow import discover
    from canebench.execute.executors import make_executor
    from canebench.model.modelfile import load_model_file

    out = tmp_path / "d"
    res = discover(load_dataset(hidden_root), out=out, executor=make_executor("serial", 1, None), n_boot=20,
                   backends=["beam", "pinocchio"])
    doc = json.loads((out / "discovery.json").read_text())
    assert set(doc) >= {"baseline", "named", "unexplained", "gap", "trials"}
    named = {n["effect"]: n for n in doc["named"]}
    assert set(named) == {"root_compliance"}, doc["named"]
    # the truth is 15 N m/rad; the issue asks for 20 %
    assert named["root_compliance"]["params"]["k_root"] == pytest.approx(15.0, rel=0.2)
    lo, hi = named["root_compliance"]["ci95"]["k_root"]
    assert lo < named["root_compliance"]["params"]["k_root"] < hi
    # a root spring only softens, and the report says by how much
    assert named["root_compliance"]["ln_k_change"]["max"] < 0
    # one root for every cane: tested for a value per cane, and kept global (the report says so)
    assert named["root_compliance"]["scope"] == "global"
    assert not named["root_compliance"]["per_cane_test"]["per_cane"]
    g = doc["gap"]
    assert g["after_cv"]["median_abs_log_ratio"] < 0.5 * g["before"]["median_abs_log_ratio"]
    # every engine re-run with the fitted model agrees with the screen's prediction
    for b, v in g["per_backend"].items():
        assert v["after_median"] < 0.5 * v["before_median"], b
        assert v["screen_vs_engine_max"] < 0.05, b
    # the linear screen alone (from the baseline run, no re-anchoring) against the engines' change:
    # within 5 % (gravity on a cane leaning on its root spring is what it misses)
    for b, v in g["per_backend"].items():
        assert v["linear_screen_vs_engine_max"] < 0.05, b
    # the screen was re-anchored on the beam: the first anchor run measures the linear screen's
    # error at the fitted spring, which is what a second effect would otherwise have absorbed
    first = doc["anchors"][0]
    assert first["step"] == 1 and first["n_failed"] == 0 and 1e-4 < first["engine_minus_screen_max_abs"] < 0.05
    cfg = load_model_file(out / "model.yaml")
    assert [e.name for e in cfg.effects] == ["root_compliance"]
    report = (out / "report.html").read_text()
    assert report.count("Discovery") >= 1
    assert "alone: ln k -" in report
    assert "one value for all canes (per-cane test: p = " in report
    # the report lists every adequacy check the result holds, in the words the CLI prints
    from canebench.discovery.checks_text import adequacy_lines

    lines = adequacy_lines(doc)
    assert len(lines) >= 4 and all(html.escape(line) in report for line in lines)
    assert len(res.to_df()) == 54


def test_a_named_effect_says_what_it_alone_changes_ln_k_by(bundled_trials):
    """Each named entry carries ``ln_k_change``: what the effect alone changes ln k by on the scored
    trials, through the screen (anchored elsewhere, as after a re-anchoring). A modulus scale s
    changes every trial's stiffness by ln s exactly (the model without effects has no series part);
    a rig spring of k_rig N/m in series with a stiffness of k N/mm changes it by -ln(1 + 1e3 k / k_rig)
    (the anchor's own rig spring taken out first); a root spring only softens and a flare only
    stiffens. The CLI and the report print it."""
    from canebench.discovery.checks_text import change_text
    from canebench.discovery.screen import trial_geometry
    from canebench.discovery.screenset import Anchored, ScreenSet
    from canebench.discovery.workflow import _named_entries
    from canebench.model.effects import EffectSpec
    from canebench.model.presets import PRESETS

    ss = ScreenSet.build([trial_geometry(t, PRESETS["beam-consistent"]) for t in bundled_trials[:9]])
    lkb = np.log(np.linspace(0.01, 0.3, len(ss.trials)))
    anchor = (EffectSpec.parse("root_compliance(k_root=20)"), EffectSpec.parse("rig_compliance(k_rig=300)"))
    at = Anchored(ss.anchored(anchor), Anchored(ss, lkb).predict(anchor))
    specs = [EffectSpec.parse(t) for t in ("modulus_scale(scale=1.5)", "root_compliance(k_root=20)",
                                           "base_flare(excess_mm=6, length_mm=200)", "rig_compliance(k_rig=100)")]
    scale, root, flare, rig = (n["ln_k_change"] for n in _named_entries(specs, {}, at))
    assert scale["min"] == pytest.approx(math.log(1.5), abs=1e-12)
    assert scale["max"] == pytest.approx(math.log(1.5), abs=1e-12)
    # the screen without effects gives back lkb (the anchor's root and rig taken out), so in series:
    rig_closed = -np.log1p(1e3 * np.exp(lkb) / 100.0)
    for key, agg in (("median", np.median), ("min", np.min), ("max", np.max)):
        assert rig[key] == pytest.approx(agg(rig_closed), abs=1e-12)
    assert root["max"] < 0 and flare["min"] > 0
    for c in (root, flare):
        assert c["min"] <= c["median"] <= c["max"] and c["min"] < c["max"]
    assert change_text({"ln_k_change": scale}) == "ln k +0.405 (median; +0.405 to +0.405)"
    assert change_text({"params": {}}) == ""


def test_an_interval_reaching_no_effect_covers_the_null():
    """``covers_null``: a scale's interval across 1, a pitch's across 0, a flare's excess down to 0
    and a spring's up to its stiffest search bound (standing for infinitely stiff) reach no effect;
    intervals beside them, and a flare's length (whose null is only a default), do not."""
    from canebench.discovery.nulls import covers_null
    from canebench.model.effects import EFFECTS, EffectSpec

    def cov(text, **ci):
        s = EffectSpec.parse(text)
        return covers_null(s, {(s.name, k): v for k, v in ci.items()})

    assert cov("modulus_scale(scale=1.2)", scale=(0.95, 1.4)) == ["scale"]
    # the fit clamps log-scale parameters in log space: its stiffest root is exp(log(high)), a hair
    # below high, and must still count as reaching it
    assert cov("root_compliance(k_root=40)", k_root=(20.0, math.exp(math.log(3000.0)))) == ["k_root"]
    assert cov("modulus_scale(scale=1.2)", scale=(1.05, 1.4)) == []
    assert cov("modulus_scale(scale=0.8)", scale=(0.6, 0.97)) == []
    # seed 7's set 25 (self-test): its pitch and interval
    assert cov("probe_misalignment(angle_deg=-30.6)", angle_deg=(-36.1, 6.2)) == ["angle_deg"]
    assert cov("probe_misalignment(angle_deg=-30.6)", angle_deg=(-36.1, -21.0)) == []
    high = EFFECTS["root_compliance"].parameters["k_root"].high
    assert cov("root_compliance(k_root=40)", k_root=(20.0, high)) == ["k_root"]
    assert cov("root_compliance(k_root=40)", k_root=(20.0, 0.5 * high)) == []
    assert cov("rig_compliance(k_rig=500)", k_rig=(300.0, EFFECTS["rig_compliance"].parameters["k_rig"].high)) == \
        ["k_rig"]
    assert cov("base_flare(excess_mm=3, length_mm=100)", excess_mm=(0.0, 5.0), length_mm=(20.0, 600.0)) == \
        ["excess_mm"]
    assert cov("base_flare(excess_mm=3, length_mm=100)", excess_mm=(1.0, 5.0), length_mm=(20.0, 600.0)) == []
    # a parameter the bootstrap did not draw (held fixed) is not judged
    assert cov("modulus_scale(scale=1.2)") == []
    # the side a null lies on, for a third party's parameters too: beyond either bound, at one, inside
    from canebench.discovery.nulls import null_bound
    from canebench.model.effects import Parameter

    assert null_bound(Parameter("N/m", 20.0, 1e5, math.inf)) == 1e5
    assert null_bound(Parameter("1", -10.0, 10.0, -math.inf)) == -10.0
    assert null_bound(Parameter("m/N", 1e-6, 1e-2, 0.0, True)) == 1e-6
    assert null_bound(Parameter("mm", 0.0, 25.0, 0.0)) == 0.0
    assert math.isnan(null_bound(Parameter("deg", -45.0, 45.0, 0.0)))
    assert math.isnan(null_bound(Parameter("1", 0.0, 1.0, math.nan)))


@pytest.mark.heavy
def test_a_name_whose_interval_reaches_no_effect_is_withheld_and_the_rest_refitted(hidden_root, tmp_path,
                                                                                  monkeypatch):
    """The hidden root spring (15 N m/rad) passes the selection; its bootstrap interval is then
    stretched to the search bound (3000 N m/rad, a root as stiff as no root). It is not named:
    reported as ``unsupported``, the drop logged in the selection, the model refitted without it
    and re-anchored on the engine, whose run is then the baseline's: the "after" is the "before";
    the result is flagged unexplained."""
    import canebench.discovery.workflow as wf
    from canebench.data.dataset import load_dataset
    from canebench.execute.executors import make_executor
    from canebench.model.modelfile import load_model_file

    real = wf.bootstrap_ci
    seen = []

    def stretched(fit, *a, **k):
        ci = real(fit, *a, **k)
        seen.append(dict(ci))
        key = ("root_compliance", "k_root")
        if key in ci:
            ci[key] = (ci[key][0], wf.EFFECTS["root_compliance"].parameters["k_root"].high)
        return ci

    monkeypatch.setattr(wf, "bootstrap_ci", stretched)
    out = tmp_path / "d"
    res = wf.discover(load_dataset(hidden_root), out=out, executor=make_executor("serial", 1, None), n_boot=10,
                      confirm=False)
    # the root passed the selection with an interval that did not reach no effect
    lo, hi = seen[0][("root_compliance", "k_root")]
    assert hi < 1000, seen[0]
    assert len(seen) == 1  # nothing was left to draw intervals for
    doc = json.loads((out / "discovery.json").read_text())
    assert doc["named"] == [] and res.named == []
    # the residuals leaned the root's way significantly and nothing named takes that
    assert doc["unexplained"] is True
    (u,) = doc["unsupported"]
    assert u["effect"] == "root_compliance" and u["covers_null"] == ["k_root"]
    assert u["units"] == {"k_root": "N m/rad"}  # the issue's unit, as for a named effect
    assert u["params"]["k_root"] == pytest.approx(15.0, rel=0.2)
    assert [r["removed"] for r in doc["selection"] if r.get("removed")] == ["root_compliance"]
    assert "for an interval that reaches no effect: root_compliance" in doc["stop_reason"]
    assert any(n.startswith("root_compliance passed the selection") for n in doc["notes"])
    assert load_model_file(out / "model.yaml").effects == ()
    g = doc["gap"]
    assert g["after_cv"]["median_abs_log_ratio"] == pytest.approx(g["before"]["median_abs_log_ratio"], rel=1e-6)


@pytest.mark.heavy
def test_discover_names_nothing_on_a_null_dataset(tmp_path):
    from canebench.canes.generate_hidden import generate_hidden
    from canebench.data.dataset import load_dataset
    from canebench.discovery.workflow import discover
    from canebench.execute.executors import make_executor

    d = generate_hidden(tmp_path / "null", 12, {}, n_bushes=6)
    res = discover(load_dataset(d), confirm=False, executor=make_executor("serial", 1, None), n_boot=10)
    assert res.named == [], res.named
    assert res.gap["after_cv"] == res.gap["before"]
    # nothing hidden: the baseline scales across canes as the data do
    assert not res.adequacy["inadequate"], res.adequacy


def test_discovery_settings_are_checked_whatever_numeric_type_carries_them():
    """numpy scalars pass (a sweep from Python hands them over); bools, NaN and out-of-range values do not."""
    from canebench.discovery.workflow import _check_settings
    from canebench.errors import InputError

    _check_settings(np.float32(0.05), np.int64(40), np.float32(0.0), np.uint8(3))
    _check_settings(0.01, 1, 0, 1)
    for bad in ((True, 40, 0.05, 3), (0.05, True, 0.05, 3), (0.05, 40, True, 3), (0.05, 40, 0.05, False),
                (float("nan"), 40, 0.05, 3), (1.0, 40, 0.05, 3), (0.05, 40.0, 0.05, 3), (0.05, 0, 0.05, 3),
                (0.05, 40, float("nan"), 3), (0.05, 40, -1e-9, 3), (0.05, 40, 0.05, 0), (0.05, 40, "0.05", 3)):
        with pytest.raises(InputError):
            _check_settings(*bad)


@pytest.fixture
def not_installed_engine():
    """A backend registered under ``discover_not_installed`` whose engine module does not exist."""
    from canebench.backends.base import DynamicBackend
    from canebench.registry import register_backend, unregister_backend

    class NotInstalled(DynamicBackend):
        name, engine_module = "discover_not_installed", "no_such_engine_module_here"

        def settings(self, proto):
            return {}

        def build(self, chain, proto):
            raise AssertionError("an unavailable engine is never built")

    register_backend(NotInstalled)
    try:
        yield NotInstalled.name
    finally:
        unregister_backend(NotInstalled.name)


def test_a_mistyped_engine_stops_discovery_before_any_work(tmp_path, bundled_trials, not_installed_engine):
    """An unknown name raises before the output folder exists (it used to surface from the
    provenance block after minutes of fitting). The engine lookup skips an engine that is not
    installed, with its reason (the next test's run reports it), and refuses only a missing
    baseline engine, without which nothing can be scored."""
    from canebench.discovery import workflow
    from canebench.errors import BackendUnavailable, UnknownBackend

    out = tmp_path / "out"
    with pytest.raises(UnknownBackend, match="nosuch"):
        workflow.discover(bundled_trials, backends=["beam", "nosuch"], out=out)
    assert not out.exists()
    usable, skipped = workflow._engines("beam", "beam", ["beam", not_installed_engine])
    assert usable == ["beam"] and "no_such_engine_module_here" in skipped[not_installed_engine], (usable, skipped)
    with pytest.raises(BackendUnavailable, match=not_installed_engine):
        workflow._engines("test", not_installed_engine, None)


@pytest.mark.heavy
def test_a_missing_engine_is_skipped_and_the_result_says_why(tmp_path, not_installed_engine):
    """An engine that is not installed is skipped (it crashed discovery's provenance block
    once); the result says why, and its gap and provenance hold only the engines that ran."""
    from canebench.canes.generate_hidden import generate_hidden
    from canebench.data.dataset import load_dataset
    from canebench.discovery.workflow import discover
    from canebench.execute.executors import make_executor

    trials = load_dataset(generate_hidden(tmp_path / "null", 12, {}, n_bushes=2))
    out = tmp_path / "out"
    res = discover(trials, backends=["beam", not_installed_engine], out=out,
                   executor=make_executor("serial", 1, None), n_boot=5)
    assert any(n.startswith(f"backend {not_installed_engine} skipped: ") and "no_such_engine_module_here" in n
               for n in res.notes), res.notes
    assert set(res.gap["per_backend"]) == {"beam"}
    doc = json.loads((out / "discovery.json").read_text())
    assert doc["provenance"]["engines"].keys() == {"beam"}


@pytest.mark.heavy
def test_of_the_effects_that_pass_the_one_with_the_lowest_bic_is_named(tmp_path, monkeypatch):
    """A probe pitched 30 degrees on canes whose moduli scatter 0.3 in ln (twice the self-test's;
    the real canes scatter more): a modulus scale and the pitch both pass the first step, and
    the scale's held-out L1 gain is as large as the pitch's (each mostly moves the level), so
    naming by that gain named the scale first and never the pitch beside it. The pitch's
    pattern within canes is what the likelihood sees: by BIC it is named, alone, near its angle
    (20 %: the done-when tolerance). The seed is one where the two gains come out that way round
    (9205-9212 searched once the generator's push started from the sagged cane: both passed on
    six; the scale's gain was the larger on 9209, 9211 and 9212, and the pitch was named on
    all three). The rig's sample count, and with it the noise stream, depends on the stiffness,
    so another angle or seed is another dataset: on some neither passes."""
    import canebench.canes.generate_hidden as gh
    from canebench.data.dataset import load_dataset
    from canebench.discovery.workflow import discover
    from canebench.execute.executors import make_executor

    monkeypatch.setattr(gh, "MODULUS_LOG_SD", 0.3)
    d = gh.generate_hidden(tmp_path / "pitch", 9212, {"probe_misalignment": {"angle_deg": 30.0}}, n_bushes=6)
    res = discover(load_dataset(d), confirm=False, executor=make_executor("serial", 1, None), n_boot=10,
                   candidates=("modulus_scale", "probe_misalignment"))
    first = res.steps[res.steps.step == 1].set_index("candidate")
    # both passed every rule of the first step (significance, held-out gain, BIC, materiality),
    # the scale with the larger held-out gain (the old rule's pick) by less than the canes'
    # scatter can tell, the pitch with a BIC lower by more than 10 (very strong evidence)
    assert first.passed.all(), first
    g = first.cv_gain_per_cane
    assert 0 < g["modulus_scale"] - g["probe_misalignment"] < 0.05, g
    assert first.bic["probe_misalignment"] < first.bic["modulus_scale"] - 10
    assert [n["effect"] for n in res.named] == ["probe_misalignment"], res.named
    assert res.named[0]["params"]["angle_deg"] == pytest.approx(30.0, rel=0.2)
    # the traces bend as the pitched probe says they should (the shape check passes)
    sh = res.adequacy["shape"]
    assert sh["p"] > 0.05 and sh["beta"] > 0.5 and sh["predicted_mean"] > 0.05, sh


@pytest.mark.heavy
def test_a_material_effect_is_not_named_where_one_too_small_to_name_fits_better(tmp_path):
    """A probe pitched 15 degrees (seed 9602, the weak-pitch study's set: median |d ln k| 0.044,
    under twice the noise): the pitch passes significance with the lowest BIC but moves the model
    by 0.045 in mean |ln k|, under the materiality rule's 0.05, and a modulus scale, which takes
    the level, passes every rule. Naming the scale would put the level on the wrong physics;
    nothing is named, the stop reason says why, and the result is flagged unexplained. (Before the
    rule, the scale was named, 1.30.)"""
    from canebench.canes.generate_hidden import generate_hidden
    from canebench.data.dataset import load_dataset
    from canebench.discovery.selection import MIN_CHANGE
    from canebench.discovery.workflow import discover
    from canebench.execute.executors import make_executor

    d = generate_hidden(tmp_path / "pitch", 9602, {"probe_misalignment": {"angle_deg": 15.0}})
    res = discover(load_dataset(d), confirm=False, executor=make_executor("serial", 1, None), n_boot=10,
                   candidates=("modulus_scale", "probe_misalignment"))
    first = res.steps[res.steps.step == 1].set_index("candidate")
    scale, pitch = first.loc["modulus_scale"], first.loc["probe_misalignment"]
    # the case the rule is for: the scale passes every rule; the pitch fails materiality alone
    assert scale.passed and scale.net_change_mean_abs >= MIN_CHANGE, scale
    assert not pitch.passed and pitch.net_change_mean_abs < MIN_CHANGE, pitch
    assert pitch.p < pitch.level and pitch.cv_relative_gain > 0.05, pitch
    assert pitch.bic < scale.bic and scale.outranked_by == "probe_misalignment"
    # the pair was judged with no passing single as its rival, and the pitch beside the scale is
    # immaterial too: it does not pass either
    pair = first.loc["modulus_scale+probe_misalignment"]
    assert not pair.passed and list(pair.passenger) == ["probe_misalignment"], pair
    assert res.named == [], res.named
    assert "probe_misalignment" in res.stop_reason and "too small to name" in res.stop_reason
    assert res.gap["after_cv"] == res.gap["before"]
    # the residual leaned toward the pitch significantly and nothing named takes it: unexplained
    ts = res.to_json()["too_small_to_name"]
    assert ts["effect"] == "probe_misalignment" and ts["outranked"] == ["modulus_scale"], ts
    assert ts["net_change_mean_abs"] == pytest.approx(pitch.net_change_mean_abs)
    assert res.unexplained and any("too small to name" in n for n in res.notes), res.notes


@pytest.mark.heavy
def test_a_pair_displaces_a_single_that_mimics_its_sum(tmp_path):
    """A soft root (41 N m/rad) with a stiffer material (scale 1.72), the strengths an independent
    generator hid in its ds10: the two cancel in the mean (the scale alone does not lean the
    residuals its way) and the root alone overshoots the thin canes out of sample, while a
    flexing rig, which softens the stiff canes most as the root does, passes the first step
    alone. Naming that single named the rig; the pair, tried beside it, has a BIC lower by more
    than 10 and both members gain out of sample beside the other, so the pair is named, each
    within the done-when 20 % of its truth."""
    from canebench.canes.generate_hidden import generate_hidden
    from canebench.data.dataset import load_dataset
    from canebench.discovery.workflow import discover
    from canebench.execute.executors import make_executor

    k_root, scale = 40.8, 1.72
    d = generate_hidden(tmp_path / "pair", 31, {"root_compliance": {"k_root": k_root}, "modulus_scale": {"scale": scale}},
                        n_bushes=6)
    res = discover(load_dataset(d), confirm=False, executor=make_executor("serial", 1, None), n_boot=10,
                   candidates=("modulus_scale", "root_compliance", "rig_compliance"))
    first = res.steps[res.steps.step == 1].set_index("candidate")
    # the premise: the rig passed every rule of the first step alone, neither member did
    assert first.passed["rig_compliance"] and not first.passed["root_compliance"], first
    assert not first.passed["modulus_scale"], first
    pair = first.loc["modulus_scale+root_compliance"]
    assert pair.chosen and pair.bic < first.bic["rig_compliance"] - 10, first
    # each member gains out of sample beside the other alone, well beyond the 5 % asked: the root
    # alone misses the thin canes' level, the scale alone the thick canes' root
    # (the rule asks 5 % of the other's own held-out mean |ln| per cane: the baseline's less its gain)
    l1_base = pair.cv_gain_per_cane / pair.cv_relative_gain
    for m, o in (("modulus_scale", "root_compliance"), ("root_compliance", "modulus_scale")):
        assert pair.gain_beside_other[m] > 0.2 * (l1_base - first.cv_gain_per_cane[o]), (m, first)
    got = {n["effect"]: n["params"] for n in res.named}
    assert set(got) == {"modulus_scale", "root_compliance"}, res.named
    assert got["modulus_scale"]["scale"] == pytest.approx(scale, rel=0.2)
    assert got["root_compliance"]["k_root"] == pytest.approx(k_root, rel=0.2)


def test_each_hidden_effects_own_share_is_the_stiffness_without_it(tmp_path):
    """With a modulus scale and a rig spring hidden together, taking one out has closed forms:
    the rod's small-deflection stiffness is proportional to E, and the rig is a series spring."""
    import json

    from canebench.canes.generate_hidden import generate_hidden
    from canebench.discovery.selftest import _member_sizes

    scale, k_rig = 1.5, 120.0
    d = generate_hidden(tmp_path / "pair", 21, {"modulus_scale": {"scale": scale}, "rig_compliance": {"k_rig": k_rig}},
                        n_bushes=1, canes_per_bush=2)
    truth = json.loads((d / "truth" / "truth.json").read_text())
    for c in truth["canes"].values():
        for tr in c["trials"].values():
            k_lin = tr["k_linear_n_per_mm"] * 1e3  # the rod with the scaled modulus, no rig
            series = lambda k: 1.0 / (1.0 / k + 1.0 / k_rig)  # noqa: E731
            assert tr["k_effect_n_per_mm"] * 1e3 == pytest.approx(series(k_lin), rel=1e-9)
            assert tr["k_without_rig_compliance_n_per_mm"] * 1e3 == pytest.approx(k_lin, rel=1e-9)
            # E / scale: the rod's linear stiffness scales with E (rel 1e-6: a finite-difference Jacobian)
            assert tr["k_without_modulus_scale_n_per_mm"] * 1e3 == pytest.approx(series(k_lin / scale), rel=1e-6)
    sizes = _member_sizes(d)
    assert set(sizes) == {"modulus_scale", "rig_compliance"} and all(v > 0 for v in sizes.values())


def test_level_trend_holds_its_level_and_sees_stiffening_that_goes_as_compliance():
    """The adequacy check on simulated tables: 18 canes of 3 trials whose stiffness levels spread
    as the real canes' do (sd 1 in ln k between canes), cane offsets 0.15 (the canes' own modulus
    scatter) and trial noise 0.05. Level and residual are independent here, so this checks the
    permutation null, not the bias their shared geometry error brings (the self-test counts
    the flags on nulls and correctly named sets for that)."""
    from canebench.discovery.structure import level_trend

    rng = np.random.default_rng(5)
    canes = np.repeat([f"c{i:02d}" for i in range(18)], 3)

    def table(extra):
        level = np.repeat(rng.normal(-3.5, 1.0, 18), 3) + rng.normal(0, 0.3, 54)
        r = np.repeat(rng.normal(0, 0.15, 18), 3) + rng.normal(0, 0.05, 54) + extra(level)
        return pd.DataFrame({"cane": canes, "r": r, "level": level})

    # level 0.05 on 200 nulls: 10 expected, 18 or more has probability 0.01
    ps = np.array([level_trend(table(lambda x: 0 * x), "r", "level", seed=i, n_perm=400)["p"] for i in range(200)])
    assert np.sum(ps < 0.05) < 18, np.sort(ps)[:20]
    # a neighbour's support adds stiffness in proportion to the cane's compliance: ln(1 + c / k),
    # equal to the cane's own stiffness at the median cane, 0.3 of it left after a fitted effect
    # took the mean. Measured power at 0.01: 44 of 50; a test blind to the level (e.g. one
    # shuffling trials within canes) would reject about 1 in 50
    ps = np.array([level_trend(table(lambda x: 0.3 * np.log1p(np.exp(-(x + 3.5)))), "r", "level", seed=i,
                               n_perm=400)["p"] for i in range(50)])
    assert np.sum(ps < 0.01) >= 35, np.sort(ps)


@pytest.mark.heavy
def test_discover_withholds_names_for_a_lateral_support_outside_the_library(tmp_path):
    """A neighbouring cane as a lateral spring below the push points (not in the library): the
    library fits what it can (here a modulus scale), but the residual still falls with the
    model's stiffness level between canes, beyond what the calipers' own error makes it do, so
    nothing is named: the fit is reported as partial and the result is unexplained. k_support
    200 N/m is the top of the self-test's range; the check sees strong supports only (seed 13's
    dataset at the same strength gives p = 0.014 with three effects fitted, flagged by the
    permutation warning only: docs/discovery.md)."""
    from canebench.canes.generate_hidden import generate_hidden
    from canebench.data.dataset import load_dataset
    from canebench.discovery.workflow import discover
    from canebench.execute.executors import make_executor

    d = generate_hidden(tmp_path / "ool", 14, {"lateral_support": {"height_frac": 0.45, "k_support": 200.0}},
                        n_bushes=6)
    out = tmp_path / "out"
    res = discover(load_dataset(d), confirm=False, executor=make_executor("serial", 1, None), n_boot=10, out=out)
    a = res.adequacy["after_cv"]
    assert res.unexplained and res.adequacy["inadequate"], res.adequacy
    assert a["r"] < a["null_median"] < 0  # soft canes stiffer than the model, beyond the geometry's lean
    assert a["p"] < 0.002 and not a["geometry_bounded"] and a["n_trials_left_out"] == 0
    assert not [n for n in res.named if n["scope"] != "per_trial"], res.named
    assert res.partial and res.partial_config is not None and res.partial_config.effects
    assert [e.name for e in res.config.effects if e.name != "obstruction"] == []  # the model file names nothing
    assert res.gap["after_cv"] == res.gap["before"] and "partial_after_cv" in res.gap
    assert any("does not scale across canes" in n for n in res.notes), res.notes
    # the files say the same: the model file names nothing, the partial one holds the fit
    from canebench.model.modelfile import load_model_file

    doc = json.loads((out / "discovery.json").read_text())
    assert [n["effect"] for n in doc["partial"]] == [e.name for e in res.partial_config.effects
                                                     if e.name != "obstruction"]
    assert [e.name for e in load_model_file(out / "model.yaml").effects if e.name != "obstruction"] == []
    assert load_model_file(out / "model_partial.yaml").effects == res.partial_config.effects
    assert "partial: not named" in (out / "report.html").read_text()


@pytest.mark.heavy
def test_direction_test_holds_its_level_on_nulls_and_sees_a_global_shift():
    """The selection's score test on the bundled geometry with simulated residuals: canes
    carry their own offsets (tau 0.3 in ln, the real data's scale) and trials their noise;
    also with an effect already fitted (its refit is projected out of the candidate)."""
    from canebench.data.dataset import bundled_dataset, load_dataset
    from canebench.discovery.fit import (Candidate, apply_vinv, direction_test_p, fit_candidate,
                                         variance_components)
    from canebench.discovery.screen import trial_geometry
    from canebench.discovery.screenset import Anchored, ScreenSet
    from canebench.model.presets import PRESETS

    cfg = PRESETS["beam-consistent"]
    trials = load_dataset(bundled_dataset())
    ss = ScreenSet.build([trial_geometry(t, cfg) for t in trials])
    lkb = np.zeros(len(ss.trials))
    canes, inv, counts = np.unique(ss.canes, return_inverse=True, return_counts=True)
    rng = np.random.default_rng(3)

    # the covariance inverse against a dense solve
    x = rng.normal(size=len(lkb))
    V = 0.02**2 * np.eye(len(x)) + 0.3**2 * (inv[:, None] == inv[None, :])
    np.testing.assert_allclose(apply_vinv(x, inv, counts, 0.02**2, 0.3**2), np.linalg.solve(V, x), rtol=1e-9)

    def draw(shift):
        return lkb + shift + rng.normal(0, 0.3, len(canes))[inv] + rng.normal(0, 0.03, len(lkb))

    def p_of(name, lkf, fixed=(), project=False):
        from canebench.discovery.screenset import Anchored

        s2, t2 = variance_components(lkf - Anchored(ss, lkb).predict(fixed), ss.canes)
        return direction_test_p(name, Anchored(ss, lkb), lkf, fixed, s2, t2, n_perm=2000, seed=int(rng.integers(1 << 30)),
                                project_fitted=project)

    # level 0.05 on 200 nulls: 10 expected; 18 or more has probability 0.01 at the nominal level
    # and 0.7 at a level of 0.10, so a test that rejects twice too often fails here
    ps = np.array([p_of("modulus_scale", draw(0.0)) for _ in range(200)])
    assert np.sum(ps < 0.05) < 18, np.sort(ps)[:20]
    ps = np.array([p_of("root_compliance", draw(0.0)) for _ in range(200)])
    assert np.sum(ps < 0.05) < 18, np.sort(ps)[:20]
    # with a real, fitted modulus shift in the model the next candidate still holds its level,
    # with and without projecting the fitted effect's direction out
    for project in (False, True):
        ps = []
        for _ in range(60):
            lkf = draw(np.log(1.4))
            fit = fit_candidate(Candidate.of(("modulus_scale",)), Anchored(ss, lkb), lkf)
            ps.append(p_of("root_compliance", lkf, fit.specs, project))
        assert np.sum(np.array(ps) < 0.05) <= 7, (project, np.sort(ps)[:10])  # 3 expected; P(>= 8) = 0.02
    # a shift the size of the cane scatter (the hidden-effect suite's scale cases) on 18 canes
    assert np.median([p_of("modulus_scale", draw(np.log(1.37))) for _ in range(10)]) < 0.01
    # the selection's pair step: one test whose max runs over several pairs' joint grids, calibrated
    # by the same sign flips. 100 nulls at 0.05: 5 expected; 11 or more has probability 0.011 at the
    # nominal level and 0.58 at 0.10
    union = [("rig_compliance", "base_flare"), ("root_compliance", "modulus_scale"),
             ("probe_misalignment", "root_compliance")]
    ps = np.array([p_of(union, draw(0.0)) for _ in range(100)])
    assert np.sum(ps < 0.05) < 11, np.sort(ps)[:20]


def test_a_pair_is_redrawn_until_both_members_are_resolvable(tmp_path, monkeypatch):
    """The self-test's pairs: a member hidden behind the other is redrawn (seeded), and the truth
    records the strengths used and how many draws it took. The generator is replaced by one whose
    shares are known: the scale's is |ln scale|, the root's always 1."""
    import json
    import math

    import canebench.canes.generate_hidden as gh
    from canebench.discovery.selftest import NOISE, _generate_case, _member_sizes

    def fake(folder, seed, effects):
        share = abs(math.log(effects["modulus_scale"]["scale"]))
        tr = {"k_effect_n_per_mm": 1.0, "k_without_modulus_scale_n_per_mm": math.exp(-share),
              "k_without_root_compliance_n_per_mm": math.exp(-1.0)}
        (folder / "truth").mkdir(parents=True)
        (folder / "truth" / "truth.json").write_text(json.dumps({"effects": effects, "canes": {"c": {"trials": {"1": tr}}}}))
        return folder

    monkeypatch.setattr(gh, "generate_hidden", fake)
    case = {"kind": "pair", "seed": 5, "effects": {"root_compliance": {"k_root": 4.0}, "modulus_scale": {"scale": 1.05}}}
    runs = []
    for i in range(2):
        _generate_case(tmp_path / f"p{i}", case)
        runs.append(json.loads((tmp_path / f"p{i}" / "truth" / "truth.json").read_text()))
        assert min(_member_sizes(tmp_path / f"p{i}").values()) > 2 * NOISE
    assert runs[0]["draws"] > 1 and runs[0]["effects"]["modulus_scale"]["scale"] != 1.05
    assert runs[0] == runs[1]  # seeded: the same case gives the same dataset
    # a single effect is never redrawn
    one = {"kind": "single", "seed": 5, "effects": {"modulus_scale": {"scale": 1.05}}}
    _generate_case(tmp_path / "s", one)
    assert json.loads((tmp_path / "s" / "truth" / "truth.json").read_text())["effects"] == one["effects"]


def test_the_selftest_draws_each_effect_once_in_every_fifth_of_its_range():
    """The suite's 5 singles per effect are stratified: one strength in each fifth of the range
    stated in ``random_strength``'s docstring (log range for springs), so the strong end, where
    the issue's parameter criterion is scored, is in every suite whatever the seed. Unstratified,
    the strongest fifth is missed by all 5 draws with probability 0.8^5 = 0.33 per effect."""
    from canebench.discovery.selftest import suite

    ranges = {  # effect, parameter, stated range, transform to the axis that is cut in fifths
        ("modulus_scale", "scale"): (0.15, 0.7, lambda v: abs(math.log(v))),
        ("root_compliance", "k_root"): (math.log(3.0), math.log(150.0), math.log),
        ("rig_compliance", "k_rig"): (math.log(20.0), math.log(1500.0), math.log),
        ("base_flare", "collar"): (0.3, 1.2, float),
        ("probe_misalignment", "angle_deg"): (15.0, 40.0, abs),
    }
    for seed in (7, 8, 123):
        singles = [c["effects"] for c in suite(seed) if c["kind"] == "single"]
        for (eff, par), (lo, hi, f) in ranges.items():
            x = [f(e[eff][par]) for e in singles if eff in e]
            assert len(x) == 5 and all(lo <= v <= hi for v in x), (seed, eff, x)
            assert sorted(int(5 * (v - lo) / (hi - lo)) for v in x) == [0, 1, 2, 3, 4], (seed, eff, x)


def test_the_selftest_per_cane_sets_come_last_and_leave_the_other_cases_as_they_were():
    """The per-cane roots are drawn after every other case, so a suite with them holds the same
    first 40 cases (effects, ids, seeds) as one without: stored runs of those stay comparable. Their
    roots cover PER_CANE_K_ROOT one stratum a set, with a spread in PER_CANE_LN_SD."""
    import hashlib

    from canebench.discovery.selftest import PER_CANE_K_ROOT, PER_CANE_LN_SD, suite

    # the 40 cases of 416b8d5's suite (before the per-cane sets), hashed with that commit's own code:
    # the stored full runs of seeds 7-9 (README's table) are of exactly these
    before = {7: "748500ab290d4d20", 8: "1036d0215d2ee3e4", 9: "929bcfec41cc8cb1"}
    for seed in (7, 8, 9):
        cases = suite(seed)
        assert hashlib.sha256(json.dumps(cases[:40], sort_keys=True).encode()).hexdigest()[:16] == before[seed]
        assert cases[:-2] == suite(seed, per_cane=0) and len(cases) == 42
        pc = [c for c in cases if c["kind"] == "per_cane"]
        assert [c["id"][:2] for c in pc] == ["40", "41"]
        k = [c["effects"]["root_compliance"]["k_root"] for c in pc]
        x = np.log(np.array(k) / PER_CANE_K_ROOT[0]) / np.log(PER_CANE_K_ROOT[1] / PER_CANE_K_ROOT[0])
        assert sorted(int(2 * v) for v in x) == [0, 1], (seed, k)
        assert all(PER_CANE_LN_SD[0] <= c["effects"]["root_compliance"]["ln_sd"] <= PER_CANE_LN_SD[1] for c in pc)


def test_the_selftest_scores_a_per_cane_root_against_the_canes_drawn_roots():
    """Each cane's value is compared with the generator's root for that cane (in ln), the global
    value with the drawn roots' geometric mean; a root named with one value for all is not found.
    Outside the per-cane sets a root per cane is a wrong scope; inside them it is the answer."""
    from canebench.discovery.selftest import _per_cane_scores, summarize

    drawn = {"b1c1": 10.0, "b1c2": 20.0, "b2c1": 40.0, "b2c2": 80.0}
    truth = {"canes": {c: {"k_root": v} for c, v in drawn.items()} | {"b3c1": {}}}
    local = {c: {"k_root": 1.5 * v} for c, v in drawn.items()}  # right ranks, 1.5 times too stiff
    local["b1c2"]["k_root"] = 20.0 * 1.5 * 2.0  # one cane off by a further factor 2
    entry = {"scope": "per_cane", "params": {"k_root": 33.0}, "per_cane_test": {"p": 1e-4, "ln_sd_between_canes": 0.8},
             "local": local}
    sc = _per_cane_scores(entry, truth)
    # the drawn roots 10, 20, 40, 80: ln sd = ln 2 times the sd of 0, 1, 2, 3 (sqrt(5/3))
    assert sc["per_cane_ln_sd_ratio"] == pytest.approx(0.8 / (math.log(2) * math.sqrt(5 / 3)), abs=1e-12)
    a = np.log([1.5 * v for v in drawn.values()]); a[1] += np.log(2.0)
    b = np.log(list(drawn.values()))
    assert sc["per_cane_found"] and sc["per_cane_p"] == 1e-4 and sc["per_cane_n"] == 4
    assert sc["per_cane_r"] == pytest.approx(np.corrcoef(a, b)[0, 1], abs=1e-12)
    assert sc["per_cane_rms_ln"] == pytest.approx(np.sqrt(np.mean((a - b) ** 2)), abs=1e-12)
    assert sc["per_cane_err_k_root"] == pytest.approx(33.0 / (10 * 20 * 40 * 80) ** 0.25 - 1.0, abs=1e-12)
    glob = _per_cane_scores({"scope": "global", "params": {"k_root": 28.3}, "per_cane_test": {"p": 0.3}}, truth)
    assert not glob["per_cane_found"] and "per_cane_r" not in glob and glob["per_cane_p"] == 0.3
    assert "per_cane_ln_sd_ratio" not in glob  # kept global: no spread to compare
    assert _per_cane_scores(None, truth) == {"per_cane_found": False}
    flat = {**entry, "local": {c: {"k_root": 30.0} for c in drawn}}  # one value for all: no correlation
    assert math.isnan(_per_cane_scores(flat, truth)["per_cane_r"])
    # against the generator's law (median 25, ln sd 0.7), in the test's standard errors (0.2 and 0.25)
    assert "per_cane_ln_sd_z" not in sc  # no sampling covariance in the entry: no z
    law = {**truth, "effects": {"root_compliance": {"k_root": 25.0, "ln_sd": 0.7}}}
    with_cov = {**entry, "per_cane_test": {**entry["per_cane_test"], "median": 30.0,
                                           "cov_ln_median_ln_sd": [[0.04, 0.01], [0.01, 0.0625]]}}
    z = _per_cane_scores(with_cov, law)
    assert z["per_cane_ln_median_z"] == pytest.approx(math.log(30 / 25) / 0.2, abs=1e-12)
    assert z["per_cane_ln_sd_z"] == pytest.approx(math.log(0.8 / 0.7) / 0.25, abs=1e-12)

    base = dict(partial="", size=0.5, gap_before=1.0, unexplained=False)
    rows = pd.DataFrame([
        {"kind": "per_cane", "hidden": "root_compliance", "named": "root_compliance", "correct": True,
         "per_cane": "root_compliance", "gap_after_cv": 0.2, **sc},
        {"kind": "per_cane", "hidden": "root_compliance", "named": "root_compliance+modulus_scale",
         "correct": False, "per_cane": "", "gap_after_cv": 0.5, **glob},
        {"kind": "single", "hidden": "root_compliance", "named": "root_compliance", "correct": True,
         "per_cane": "root_compliance", "gap_after_cv": 0.4},
        {"kind": "single", "hidden": "base_flare", "named": "base_flare", "correct": True,
         "per_cane": "base_flare", "gap_after_cv": 0.4},
    ]).assign(**base)
    s = summarize(rows)
    assert (s["per_cane_scopes"], s["per_cane_scopes_not_flare"]) == (2, 1)  # the single root's scope only
    assert (s["n_per_cane_sets"], s["per_cane_sets_named_root"], s["per_cane_sets_found_per_cane"]) == (2, "1/2", "1/2")
    assert s["per_cane_r_median"] == s["per_cane_r_worst"] == pytest.approx(sc["per_cane_r"])
    assert s["per_cane_ln_sd_ratio_median"] == s["per_cane_ln_sd_ratio_worst"] == pytest.approx(sc["per_cane_ln_sd_ratio"])
    two = pd.concat([rows.iloc[:1], rows.iloc[:1].assign(per_cane_ln_sd_ratio=0.5)])
    # worst: the ratio farthest from 1 in ln (0.5 against about 0.89)
    assert summarize(two)["per_cane_ln_sd_ratio_worst"] == 0.5
    assert s["per_cane_median_gap_shrink_out_of_sample"] == pytest.approx(0.8)  # the correctly named set only
    assert s["correct_rate_all_hidden"] == 1.0  # the issue's rates leave the per-cane sets out
    assert summarize(rows[rows.kind == "single"])["n_per_cane_sets"] == 0


def test_run_case_scores_each_kind_from_the_discovery_it_ran_and_reuses_a_finished_row(tmp_path, monkeypatch):
    """The wiring between a case, its truth and its discovery (the discovery and the generator are
    stand-ins here; both have tests of their own): a per-cane set is scored per cane and has no
    ``err_k_root`` (its root has no one true value); a single root is scored against the drawn
    value with its interval; a finished row is read back, not recomputed."""
    from pathlib import Path

    from canebench.discovery import selftest

    canes = {f"b1c{i}": 10.0 * 2**i for i in range(1, 5)}  # each cane's drawn root (N m/rad)

    def fake_generate(folder, case, max_draws=24):
        trials = {f"{c}t1": {"k_effect_n_per_mm": 0.1, "k_plain_n_per_mm": 0.2, "s": 0.3} for c in canes}
        truth = {"effects": case["effects"],
                 "canes": {c: {**({"k_root": k} if case["kind"] == "per_cane" else {}),
                               "trials": {f"{c}t1": trials[f"{c}t1"]}} for c, k in canes.items()}}
        (folder / "truth").mkdir(parents=True)
        (folder / "truth" / "truth.json").write_text(json.dumps(truth))

    docs, calls = {}, []

    class Result:
        def __init__(self, doc):
            self.doc, self.trials = doc, pd.DataFrame({"trial": list(canes)})

        def to_json(self):
            return self.doc

    def fake_discover(folder, seed):
        calls.append(Path(folder).name)
        return Result(docs[Path(folder).name])

    monkeypatch.setattr(selftest, "_generate_case", fake_generate)
    monkeypatch.setattr(selftest, "discover_case", fake_discover)
    gap = {"before": {"median_abs_log_ratio": 1.0}, "after_cv": {"median_abs_log_ratio": 0.3}}
    # each cane's value twice its drawn root: r 1, rms ln 2, the global 40 against the drawn roots'
    # geometric mean of 10 * 2^2.5
    local = {c: {"k_root": 2 * k} for c, k in canes.items()}
    docs["40-per_cane"] = {"named": [{"effect": "root_compliance", "scope": "per_cane", "params": {"k_root": 40.0},
                                      "ci95": {"k_root": [30.0, 50.0]}, "local": local,
                                      "per_cane_test": {"p": 1e-6}}],
                           "unexplained": False, "gap": gap, "selection": []}
    docs["05-single"] = {"named": [{"effect": "root_compliance", "scope": "global", "params": {"k_root": 24.0},
                                    "ci95": {"k_root": [21.0, 27.0]}}],
                         "unexplained": False, "gap": gap, "selection": []}
    pc = selftest.run_case({"id": "40-per_cane", "kind": "per_cane", "seed": 1,
                            "effects": {"root_compliance": {"k_root": 40.0, "ln_sd": 0.6}}}, str(tmp_path))
    assert pc["correct"] and pc["per_cane"] == "root_compliance" and pc["per_cane_found"]
    assert (pc["per_cane_p"], pc["per_cane_n"]) == (1e-6, 4)
    assert pc["per_cane_r"] == pytest.approx(1.0) and pc["per_cane_rms_ln"] == pytest.approx(math.log(2))
    assert pc["per_cane_err_k_root"] == pytest.approx(abs(40.0 / (10.0 * 2**2.5) - 1))
    assert "err_k_root" not in pc and "ci_covers_k_root" not in pc
    assert pc["size"] == pytest.approx(math.log(2)) and pc["gap_after_cv"] == 0.3
    single = selftest.run_case({"id": "05-single", "kind": "single", "seed": 2,
                                "effects": {"root_compliance": {"k_root": 20.0}}}, str(tmp_path))
    assert single["correct"] and single["per_cane"] == "" and "per_cane_found" not in single
    assert single["err_k_root"] == pytest.approx(0.2) and single["ci_covers_k_root"] is False
    assert calls == ["40-per_cane", "05-single"]
    again = selftest.run_case({"id": "40-per_cane", "kind": "per_cane", "seed": 1,
                               "effects": {"root_compliance": {"k_root": 40.0, "ln_sd": 0.6}}}, str(tmp_path))
    assert json.dumps(again, sort_keys=True) == json.dumps(pc, sort_keys=True)  # NaN != NaN in a dict
    assert calls == ["40-per_cane", "05-single"]


def test_the_selftest_says_where_the_out_of_library_support_touches(tmp_path):
    """A support touching near the base lies below every push of every cane, one near the tip
    above them all; the summary counts the out-of-library sets of the first kind and the names
    given there (a stiffer lower cane is what a flare or a root makes)."""
    import json

    from canebench.canes.generate_hidden import generate_hidden
    from canebench.discovery.selftest import _support_below_pushes, summarize

    share = {}
    for frac in (0.02, 0.98):
        d = generate_hidden(tmp_path / f"s{frac}", 5, {"lateral_support": {"height_frac": frac, "k_support": 50.0}},
                            n_bushes=1, canes_per_bush=2)
        truth = json.loads((d / "truth" / "truth.json").read_text())
        share[frac] = _support_below_pushes(truth)
    assert share == {0.02: 1.0, 0.98: 0.0}
    rows = pd.DataFrame([
        {"kind": "out_of_library", "named": "base_flare", "unexplained": False, "support_below_pushes": 1.0},
        {"kind": "out_of_library", "named": "none", "unexplained": True, "support_below_pushes": 0.5},
        {"kind": "no_effect", "named": "none", "unexplained": False},
    ]).assign(hidden="none", correct=True, partial="", size=0.0, gap_before=1.0, gap_after_cv=1.0)
    s = summarize(rows)
    assert (s["n_out_of_library_support_below_pushes"], s["out_of_library_misnamed_support_below_pushes"]) == (1, 1)
    assert (s["out_of_library_misnamed"], s["out_of_library_flagged_unexplained"]) == (1, 1)


def test_the_selftest_counts_names_won_by_a_close_call_and_the_wrong_ones_among_them():
    """Rows whose name carried a close rival (``close_rivals``), right or wrong, are counted; rows
    written before the column existed count as none."""
    from canebench.discovery.selftest import summarize

    rows = pd.DataFrame([
        {"kind": "single", "hidden": "probe_misalignment", "named": "modulus_scale", "correct": False,
         "close_rivals": "modulus_scale>probe_misalignment", "false_names": "modulus_scale"},
        {"kind": "single", "hidden": "modulus_scale", "named": "modulus_scale", "correct": True,
         "close_rivals": "modulus_scale>probe_misalignment", "false_names": None},
        {"kind": "single", "hidden": "root_compliance", "named": "root_compliance", "correct": True,
         "close_rivals": None, "false_names": None},
        # two names with a close rival (one a pair), only the second false; and a false name that
        # won clearly beside a close call that was right
        {"kind": "pair", "hidden": "rig_compliance+root_compliance", "named": "root_compliance+base_flare",
         "correct": False, "close_rivals": "root_compliance>rig_compliance+modulus_scale; base_flare>rig_compliance",
         "false_names": "base_flare"},
        {"kind": "pair", "hidden": "rig_compliance+root_compliance", "named": "rig_compliance+base_flare",
         "correct": False, "close_rivals": "rig_compliance>root_compliance", "false_names": "base_flare"},
    ]).assign(unexplained=False, partial="", size=1.0, gap_before=1.0, gap_after_cv=0.5)
    s = summarize(rows)
    assert (s["names_with_close_rival"], s["wrong_names_with_close_rival"]) == (5, 2)
    s = summarize(rows.drop(columns=["close_rivals"]))
    assert (s["names_with_close_rival"], s["wrong_names_with_close_rival"]) == (0, 0)


def test_a_close_rival_is_worded_once_for_the_cli_and_the_report(tmp_path):
    """A name won by a close call reads "barely ahead of X: BIC +d" (two decimals) in the CLI's
    line and, escaped, in the report's table; a name without one reads as before."""
    import json

    from canebench.cli.discover import _part
    from canebench.discovery.checks_text import rivals_text
    from reports.discovery import section

    def _rivals_text(n):  # as the CLI's line puts it
        return _part(rivals_text(n), " ({})")

    won = {"effect": "modulus_scale", "scope": "global", "params": {"scale": 1.31}, "ci95": {"scale": [1.2, 1.4]},
           "close_rivals": [{"candidate": "probe_misalignment", "bic_above": 0.186},
                            {"candidate": "a<b", "bic_above": 1.5}]}
    clear = {"effect": "root_compliance", "scope": "global", "params": {"k_root": 20.0}, "ci95": {}}
    assert _rivals_text(won) == " (barely ahead of probe_misalignment: BIC +0.19, a<b: BIC +1.50)"
    assert _rivals_text(clear) == ""
    gap = {"median_abs_log_ratio": 0.3, "worst_abs_log_ratio": 0.9}
    (tmp_path / "discovery.json").write_text(json.dumps(
        {"baseline": "beam", "named": [won, clear], "unexplained": False, "gap": {"before": gap, "after_cv": gap}}))
    html_ = section(tmp_path)
    assert "modulus_scale <i>(barely ahead of probe_misalignment: BIC +0.19, a&lt;b: BIC +1.50)</i>" in html_
    assert "<td>root_compliance</td>" in html_ and html_.count("barely ahead") == 1


def test_the_selftest_counts_the_intervals_that_hold_the_truth(tmp_path):
    """Per parameter and over all, the named parameters whose 95 % interval holds the truth
    (``ci_covers_*``), counted from the rows as written to and read back from the CSV (where an
    unnamed effect leaves the cell empty); a suite without the column counts none."""
    import warnings

    from canebench.discovery.selftest import summarize

    rows = pd.DataFrame([
        {"kind": "single", "hidden": "modulus_scale", "err_scale": 0.05, "ci_covers_scale": True},
        {"kind": "single", "hidden": "modulus_scale", "err_scale": 0.12, "ci_covers_scale": False},
        {"kind": "single", "hidden": "root_compliance", "err_k_root": 0.02, "ci_covers_k_root": True},
        {"kind": "single", "hidden": "root_compliance"},  # not named: no error, no interval
        {"kind": "pair", "hidden": "modulus_scale+root_compliance", "err_scale": 0.01, "ci_covers_scale": True,
         "err_k_root": 0.3, "ci_covers_k_root": False},
    ]).assign(named="x", correct=True, unexplained=False, partial="", size=1.0, gap_before=1.0, gap_after_cv=0.5)
    rows.to_csv(tmp_path / "rows.csv", index=False)
    with warnings.catch_warnings():
        # read back, the all-empty "partial" column is float: the summary must take it quietly
        warnings.simplefilter("error")
        for df in (rows, pd.read_csv(tmp_path / "rows.csv")):
            s = summarize(df)
            assert (s["ci95_covers_scale"], s["ci95_covers_k_root"], s["ci95_covers_truth"]) == ("2/3", "1/2", "3/5")
            assert "ci95_covers_k_rig" not in s
    s = summarize(rows.drop(columns=["ci_covers_scale", "ci_covers_k_root"]))
    assert s["ci95_covers_truth"] == "0/0" and "ci95_covers_scale" not in s


def test_the_selftest_reports_each_done_when_criterion_against_the_issues_targets():
    """The issue's "done when" thresholds (90 % correct on large effects, all four parameters
    within 20 % there, at most 1 false name on the nulls, both pair members named, every
    out-of-library set flagged and none misnamed, a median out-of-sample shrink of 50 %), judged
    on hand-made summaries at and just past each threshold; a kind with no large set is not
    measured rather than met."""
    from canebench.discovery.selftest import done_when

    base = {"correct_rate_large_effects": 0.9, "n_large_effects": 20, "within_20pct_scale": "4/4",
            "within_20pct_k_root": "5/5", "within_20pct_k_rig": "0/0", "within_20pct_angle_deg": "2/2",
            "false_names_on_nulls": 1, "pairs_both_named": 3, "n_pairs": 3, "n_out_of_library": 2,
            "out_of_library_flagged_unexplained": 2, "out_of_library_misnamed": 0,
            "median_gap_shrink_out_of_sample": 0.5}

    def met(**over):
        return dict(zip(*done_when({**base, **over})[["criterion", "met"]].to_numpy().T))

    at = met()
    assert at.pop("k_rig within 20 % of truth, effects > 2x the noise") is None  # 0/0: nothing to judge
    assert all(v is True for v in at.values()) and len(at) == 8, at
    past = {"correct_rate_large_effects": 0.85, "within_20pct_angle_deg": "1/2", "false_names_on_nulls": 2,
            "pairs_both_named": 2, "out_of_library_misnamed": 1, "median_gap_shrink_out_of_sample": 0.49}
    for key, value in past.items():
        failed = [c for c, v in met(**{key: value}).items() if v is False]
        assert len(failed) == 1, (key, failed)
    # flagged but one misnamed as well (seed 8's set 38 in the self-test): not met
    assert met(out_of_library_flagged_unexplained=1, out_of_library_misnamed=1)[
        "out-of-library sets flagged unexplained, not misnamed"] is False


def test_the_fit_s_first_simplex_steps_every_parameter_across_its_range_even_from_zero():
    """scipy's Nelder-Mead steps a coordinate at 0 by 0.00025 only; the start grid puts a scale
    (log 1) and a pitch at 0, and from there a scale + rig pair was fitted scale 1.000 (fit.py,
    SIMPLEX_STEP). Each vertex must move one parameter by a tenth of its search range, inward at
    a bound."""
    from canebench.discovery.fit import Candidate, first_simplex
    from canebench.model.effects import EFFECTS

    cand = Candidate.of(("modulus_scale", "rig_compliance", "probe_misalignment"))
    ranges = []
    for n, p in cand.free:
        par = EFFECTS[n].parameters[p]
        ranges.append(math.log(par.high / par.low) if par.log else par.high - par.low)
    x0 = np.array([0.0, math.log(EFFECTS["rig_compliance"].parameters["k_rig"].high), 0.0])
    sim = first_simplex(x0, *cand.box())
    assert sim.shape == (4, 3) and np.array_equal(sim[0], x0)
    steps = sim[1:] - x0
    np.testing.assert_allclose(np.abs(np.diag(steps)), 0.1 * np.array(ranges))
    assert np.count_nonzero(steps) == 3
    assert steps[1, 1] < 0  # the rig starts at its upper bound: its vertex steps inward


def test_the_fit_restarts_nelder_mead_that_stalls_on_a_corner_of_its_box():
    """The fit's objective clips its parameters into their search box, so it is flat outside, and
    a simplex that strays there can shrink onto a corner (seed 7's rig + flare set: the flare at
    both of its bounds, BIC -67.0 where -99.0 exists; fit.nelder_mead_in_box). Here a curved
    valley meets the face y = 0 and runs along it: the optimum on the box is x = 6.6/7, y = 0,
    f = 0.2/7 (minimize (x - 0.8)^2 + 2.5 (1 - x)^2 along the face). From these starts plain
    Nelder-Mead with the same first simplex stops on the corner (1, 0), f = 0.04 (checked below,
    so the case is a real one); restarted from its answer it reaches the optimum."""
    from scipy.optimize import minimize

    from canebench.discovery.fit import first_simplex, nelder_mead_in_box

    lo, hi = np.zeros(2), np.ones(2)

    def f(x):
        x = np.clip(x, lo, hi)
        return (x[0] - 0.8) ** 2 + 10 * (x[1] + 0.5 - 0.5 * x[0]) ** 2

    for x0 in ([0.60663578, 0.72949656], [0.86317892, 0.54146122], [0.67062441, 0.64718951]):
        x0 = np.array(x0)
        plain = minimize(f, x0, method="Nelder-Mead",
                         options={"xatol": 1e-4, "fatol": 1e-6, "initial_simplex": first_simplex(x0, lo, hi)})
        assert plain.fun == pytest.approx(0.04, abs=1e-6)  # stalled on the corner
        res = nelder_mead_in_box(f, x0, lo, hi, maxiter=800)
        assert res.fun == pytest.approx(0.2 / 7, abs=1e-6)
        np.testing.assert_allclose(np.clip(res.x, lo, hi), [6.6 / 7, 0.0], atol=1e-3)


def test_the_selftest_kinds_survive_a_csv_round_trip():
    """``selftest.csv`` is read back by users with pandas' defaults, which turn the strings
    ``null``, ``NA``, ``None``... into NaN: a kind spelled that way would vanish from
    ``df[df.kind == ...]`` and the nulls' rows would count nowhere."""
    import io

    from canebench.discovery.selftest import suite

    cases = suite(7)
    back = pd.read_csv(io.StringIO(pd.DataFrame(cases)[["id", "kind"]].to_csv(index=False)))
    assert back.kind.notna().all(), back[back.kind.isna()]
    assert list(back.kind) == [c["kind"] for c in cases]
    assert (back.kind == "no_effect").sum() == 5


def test_a_rig_softer_than_the_cane_gives_a_smooth_trace(tmp_path):
    """The generator's series spring (x_rig = x_cane + F / k_rig) at the soft end of the
    self-test's range: 20 N/m, beside canes up to ten times stiffer. The readings' second
    differences carry the load cell's noise (sigma <= 3 gf, so sd <= 3 sqrt(6) = 7.3 gf), the
    preload step at contact (<= 15 gf) and the trace's own bend; 40 gf is 5.5 of those sd. A
    damped fixed-point solve of the series equation stops converging once the cane is more
    than 3 times stiffer than the rig, and wrote swings of 100 gf between samples here.

    Smoothness alone misses the other way that solve failed: ending on a smooth trace that
    reads low (0.60-0.73 of the series stiffness at cane/rig ratios of 3.5-4.5, seeds 8010 and
    8011 on the old solver). So where the cane is over 3 times stiffer than the rig, the field
    stiffness over the whole contact must be the truth's series stiffness k_effect within 10 %:
    this solver gives 0.98-1.02 there (the load cell's noise on a 60-80 mm rise), the old one
    0.60-0.73 or no usable slope at all."""
    from canebench.canes.generate_hidden import generate_hidden
    from canebench.data.rig import read_rig_csv
    from canebench.measure.field import extract_field_stiffness

    d = generate_hidden(tmp_path / "rig", 8010, {"rig_compliance": {"k_rig": 20.0}}, n_bushes=2)
    truth = json.loads((d / "truth" / "truth.json").read_text())
    ratios = [tr["k_linear_n_per_mm"] / 0.020 for c in truth["canes"].values() for tr in c["trials"].values()]
    assert max(ratios) > 3.0  # the premise: some cane is stiffer than the rig by more than 3
    for f in sorted((d / "trials").glob("*.csv")):
        reading = pd.read_csv(f)["Load Cell Reading (gf)"].to_numpy()
        assert np.max(np.abs(np.diff(reading, 2))) < 40.0, f.name
    stiff = 0
    for _, r in pd.read_csv(d / "push_points.csv").iterrows():
        tr = truth["canes"][f"b{r.bush}c{r.cane}"]["trials"][str(r.trial)]
        if tr["k_linear_n_per_mm"] / 0.020 > 3.0:
            stiff += 1
            k = extract_field_stiffness(read_rig_csv(d / r.file), n_boot=10).k_n_per_mm
            assert abs(k / tr["k_effect_n_per_mm"] - 1.0) < 0.10, (r.file, k, tr["k_effect_n_per_mm"])
    assert stiff >= 3


def _seed7_pair_screen():
    """The bundled geometry's screen, its own stiffness (N/mm) as the anchor, seeded cane and trial
    scatter (0.1 and 0.02 in ln), and seed 7's self-test pair (scale 1.69, root 131 N m/rad)."""
    from canebench.data.dataset import bundled_dataset, load_dataset
    from canebench.discovery.screen import trial_geometry
    from canebench.discovery.screenset import ScreenSet
    from canebench.model.effects import EffectSpec
    from canebench.model.presets import PRESETS

    ss = ScreenSet.build([trial_geometry(t, PRESETS["beam-consistent"]) for t in load_dataset(bundled_dataset())])
    lkb = -np.log(ss.c0 * 1e3)
    canes, inv = np.unique(ss.canes, return_inverse=True)
    rng = np.random.default_rng(7)
    scatter = rng.normal(0, 0.1, len(canes))[inv] + rng.normal(0, 0.02, len(lkb))
    truth = (EffectSpec.parse("modulus_scale(scale=1.69)"), EffectSpec.parse("root_compliance(k_root=131)"))
    return ss, lkb, scatter, truth


def test_the_backward_pass_drops_a_stale_effect_and_keeps_material_and_new_ones():
    """Selection's backward pass (``backward``) on the bundled geometry, the engine re-anchoring
    replaced by a stand-in that records its calls. With a modulus scale and a stiff root hidden
    (seed 7's self-test pair: 1.69, 131 N m/rad) and a rig spring fitted beside them, the rig
    refits to a stiffness that changes nothing: it is dropped, the rest re-anchored once, the
    drop recorded. With a real rig hidden too (80 N/m, in series with canes of 10 to 300 N/m)
    nothing is dropped; nor is the stale rig when it is the effect just added."""
    from types import SimpleNamespace

    from canebench.discovery.fit import Candidate, fit_candidate
    from canebench.discovery.screenset import Anchored
    from canebench.discovery.selection import MIN_CHANGE, backward, stalest
    from canebench.model.effects import EffectSpec

    ss, lkb, scatter, truth = _seed7_pair_screen()
    at = Anchored(ss, lkb)
    names = ("modulus_scale", "rig_compliance", "root_compliance")
    calls = []

    def reanchor(at_, cv_):
        calls.append(tuple(s.name for s in cv_.fit.specs))
        return at_, cv_

    def run(hidden, protect):
        lkf = Anchored(ss, lkb).predict(hidden) + scatter
        cv = SimpleNamespace(fit=fit_candidate(Candidate.of(names), at, lkf))
        calls.clear()
        steps = []
        out = backward(names, protect, cv, at, lkf, MIN_CHANGE, reanchor, steps, 3)
        return out, steps, lkf, cv

    (current, cv, _, dropped), steps, lkf, _ = run(truth, ("root_compliance",))
    assert current == ("modulus_scale", "root_compliance") and dropped == ["rig_compliance"]
    assert calls == [("modulus_scale", "root_compliance")] and [s.name for s in cv.fit.specs] == list(current)
    assert steps[0]["removed"] == "rig_compliance" and steps[0]["net_change_mean_abs"] < MIN_CHANGE
    # the refitted scale and root are the truth's (the scatter's mean aside)
    got = {s.name: dict(s.params) for s in cv.fit.specs}
    assert got["root_compliance"]["k_root"] == pytest.approx(131, rel=0.1), got
    # the stale rig just added is not the backward pass's to drop (it passed against this model)
    (current, *_), steps, _, _ = run(truth, ("rig_compliance",))
    assert current == names and steps == [] and calls == []
    # a material rig: nothing goes; the stalest candidate (the scale, the rig just added being
    # protected) changes the model well past MIN_CHANGE
    (current, *_), steps, lkf, cv0 = run(truth + (EffectSpec.parse("rig_compliance(k_rig=80)"),),
                                         ("root_compliance",))
    assert current == names and steps == [] and calls == []
    nearest = stalest(names, ("modulus_scale", "rig_compliance"), cv0, at, lkf)
    assert nearest["net"] > 2 * MIN_CHANGE, nearest


def test_a_name_won_by_less_than_close_bic_carries_its_rival():
    """Forward selection on the bundled geometry (one effect allowed, the engine re-anchoring an
    identity): the field is a 35 degree pitch's pattern blended with its mean level (weights w and
    1 - w) plus seeded scatter. At w = 0.35 the level is as much of the story as the pattern: a
    modulus scale and the pitch both pass every rule, their BICs under CLOSE_BIC apart; the lower
    is named and the other is reported beside it, with the BIC gap the step's rows show, on the
    named effect and in one note. At w = 0.45 the pitch wins clearly and nothing is reported."""
    import pandas as pd

    from canebench.discovery.screenset import Anchored
    from canebench.discovery.selection import CLOSE_BIC, forward_select
    from canebench.discovery.workflow import mark_close_calls
    from canebench.model.effects import EffectSpec

    ss, lkb, scatter, _ = _seed7_pair_screen()
    at = Anchored(ss, lkb)
    pitch = at.predict((EffectSpec.parse("probe_misalignment(angle_deg=35)"),)) - lkb
    pair = ("modulus_scale", "probe_misalignment")

    def select(w):
        lkf = lkb + w * pitch + (1 - w) * np.mean(pitch) + scatter
        sel = forward_select(pair, at, lkf, lambda a, c: (a, c), max_effects=1)
        return sel, pd.DataFrame(sel.steps).set_index("candidate")

    sel, rows = select(0.35)
    assert rows.passed.all(), rows
    won, lost = rows.bic.idxmin(), rows.bic.idxmax()
    gap = rows.bic[lost] - rows.bic[won]
    assert 0 < gap < CLOSE_BIC and sel.current == (won,)
    assert sel.close_calls == [{"step": 1, "chosen": (won,), "rivals": [(lost, pytest.approx(gap))]}]
    assert lost in rows.close_rivals[won]
    named = [{"effect": won}, {"effect": "obstruction"}]
    notes = mark_close_calls(named, sel.close_calls)
    assert named[0]["close_rivals"] == [{"candidate": lost, "bic_above": pytest.approx(gap)}]
    assert "close_rivals" not in named[1] and len(notes) == 1 and lost in notes[0]
    # a step whose choice was dropped later leaves nothing to report, nor a rival named itself
    assert mark_close_calls([{"effect": "obstruction"}], sel.close_calls) == []
    both = [{"effect": won}, {"effect": lost}]
    assert mark_close_calls(both, sel.close_calls) == [] and all("close_rivals" not in n for n in both)

    sel, rows = select(0.45)
    assert sel.current == ("probe_misalignment",) and sel.close_calls == []
    assert rows.bic["modulus_scale"] - rows.bic["probe_misalignment"] > CLOSE_BIC


@pytest.mark.heavy
def test_effects_whose_interval_reaches_no_effect_leave_one_at_a_time_with_their_pair_partner():
    """``drop_unsupported`` on the bundled geometry (seed 7's scale 1.69 and root 131 N m/rad
    hidden, as in the backward-pass test), intervals and engine re-anchoring replaced by stand-ins
    that record their calls. A spurious pitch whose interval reaches 0 goes, the rest are refitted
    and re-anchored, and the backward pass then drops the rig that had gone stale beside them. A
    root whose interval reaches its stiffest bound takes the scale it entered beside as a pair
    with it, and the model is the empty one's, as handed in. Where both reach their null in the
    marginal intervals but either alone is tight, only the one whose removal changes the model
    least goes. A partner is the one an effect last entered beside; and a backward pass that
    empties the model leaves the empty one's screen."""
    from types import SimpleNamespace

    from canebench.discovery.fit import Candidate, fit_candidate
    from canebench.discovery.screenset import Anchored
    from canebench.discovery.selection import MIN_CHANGE, drop_unsupported, stalest
    from canebench.model.effects import EFFECTS

    ss, lkb, scatter, truth = _seed7_pair_screen()
    at = Anchored(ss, lkb)
    lkf = Anchored(ss, lkb).predict(truth) + scatter
    empty = Anchored(ss.subset(np.ones(len(lkb), bool)), lkb.copy())  # stands for the pre-selection screen
    calls, drawn = [], []
    root_high = EFFECTS["root_compliance"].parameters["k_root"].high

    def reanchor(at_, cv_):
        calls.append(tuple(s.name for s in cv_.fit.specs))
        return at_, cv_

    def tight(fit):
        # an interval of +-10 % about every fitted value: excludes every null here
        return {(s.name, k): (0.9 * v, 1.1 * v) for s in fit.specs for k, v in s.params}

    def draw_ci(fit, at_):
        drawn.append(tuple(s.name for s in fit.specs))
        return tight(fit)

    def run(names, entered, override):
        cv = SimpleNamespace(fit=fit_candidate(Candidate.of(names), at, lkf))
        ci = {**tight(cv.fit), **override}
        calls.clear(), drawn.clear()
        steps = []
        out = drop_unsupported(names, entered, cv, at, lkf, ci, draw_ci, reanchor, empty, MIN_CHANGE, steps)
        return out, steps, cv

    # a spurious pitch, then the stale rig (fitted at its stiffest bound beside the pitch, so given
    # an interval below it here: it is the backward pass's to drop, not the interval's)
    names = ("modulus_scale", "rig_compliance", "root_compliance", "probe_misalignment")
    (current, cv, _, ci, unsupported, stale), steps, _ = run(
        names, tuple((n,) for n in names), {("probe_misalignment", "angle_deg"): (-20.0, 5.0),
                                            ("rig_compliance", "k_rig"): (5e4, 9e4)})
    assert [u["effect"] for u in unsupported] == ["probe_misalignment"]
    assert unsupported[0]["covers_null"] == ["angle_deg"] and unsupported[0]["ci95"]["angle_deg"] == [-20.0, 5.0]
    assert stale == ["rig_compliance"] and current == ("modulus_scale", "root_compliance")
    assert calls == [("modulus_scale", "rig_compliance", "root_compliance"), ("modulus_scale", "root_compliance")]
    assert drawn == [current] and set(ci) == {("modulus_scale", "scale"), ("root_compliance", "k_root")}
    assert [r["removed"] for r in steps] == ["probe_misalignment", "rig_compliance"]
    got = {s.name: dict(s.params) for s in cv.fit.specs}
    assert got["root_compliance"]["k_root"] == pytest.approx(131, rel=0.1), got

    # a pair's member reaches its null: its partner goes too, and the model is the empty one's
    (current, cv, at_out, ci, unsupported, stale), steps, _ = run(
        ("modulus_scale", "root_compliance"), (("modulus_scale", "root_compliance"),),
        {("root_compliance", "k_root"): (60.0, root_high)})
    assert current == () and ci == {} and stale == [] and calls == [] and drawn == []
    assert at_out is empty and cv.fit.specs == ()
    by = {u["effect"]: u for u in unsupported}
    assert by["root_compliance"]["covers_null"] == ["k_root"]
    assert by["modulus_scale"]["covers_null"] == [] and by["modulus_scale"]["dropped_with"] == "root_compliance"
    assert steps[0]["removed"] == "modulus_scale+root_compliance"

    # the same pair where the scale passed alone at that step (selection.entry_groups): the root
    # goes by itself and the scale stays, refitted and re-anchored
    (current, cv, at_out, ci, unsupported, stale), steps, _ = run(
        ("modulus_scale", "root_compliance"), (("modulus_scale", "root_compliance"), ("root_compliance",)),
        {("root_compliance", "k_root"): (60.0, root_high)})
    assert current == ("modulus_scale",) and stale == [] and calls == [("modulus_scale",)]
    assert [u["effect"] for u in unsupported] == ["root_compliance"] and "dropped_with" not in unsupported[0]
    assert steps[0]["removed"] == "root_compliance"
    # and the other way: the scale (which passed alone) reaching its null takes the root with it
    (current, cv, at_out, ci, unsupported, stale), steps, _ = run(
        ("modulus_scale", "root_compliance"), (("modulus_scale", "root_compliance"), ("root_compliance",)),
        {("modulus_scale", "scale"): (0.95, 2.0)})
    assert current == () and {u["effect"]: u.get("dropped_with") for u in unsupported} == {
        "modulus_scale": None, "root_compliance": "modulus_scale"}

    # both reach their null in the marginal intervals: one goes, the other is tight alone and stays
    (current, cv, _, ci, unsupported, stale), steps, cv0 = run(
        ("modulus_scale", "root_compliance"), (("modulus_scale",), ("root_compliance",)),
        {("root_compliance", "k_root"): (60.0, root_high), ("modulus_scale", "scale"): (0.95, 2.0)})
    first = stalest(("modulus_scale", "root_compliance"), ("modulus_scale", "root_compliance"), cv0, at,
                    lkf)["name"]
    assert [u["effect"] for u in unsupported] == [first] and len(current) == 1 and first not in current
    assert calls == [current] and drawn == [current]

    # the group an effect last entered in decides its partner: a rig dropped as stale that came back
    # beside the root takes the root with it, not the scale it once stood beside
    (current, cv, _, ci, unsupported, stale), steps, _ = run(
        names[:3], (("modulus_scale",), ("rig_compliance", "root_compliance")),
        {("rig_compliance", "k_rig"): (300.0, EFFECTS["rig_compliance"].parameters["k_rig"].high)})
    assert current == ("modulus_scale",) and stale == []
    assert {u["effect"]: u.get("dropped_with") for u in unsupported} == {"rig_compliance": None,
                                                                          "root_compliance": "rig_compliance"}

    # the backward pass after a drop can empty the model: then it is the empty one's, with no engine run
    lkf_null = lkb + scatter
    cv = SimpleNamespace(fit=fit_candidate(Candidate.of(("modulus_scale", "rig_compliance")), at, lkf_null))
    ci = {**tight(cv.fit), ("modulus_scale", "scale"): (0.9, 1.1), ("rig_compliance", "k_rig"): (5e3, 9e4)}
    calls.clear(), drawn.clear()
    current, cv, at_out, ci, unsupported, stale = drop_unsupported(
        ("modulus_scale", "rig_compliance"), (("modulus_scale",), ("rig_compliance",)), cv, at, lkf_null, ci,
        draw_ci, reanchor, empty, MIN_CHANGE, [])
    assert [u["effect"] for u in unsupported] == ["modulus_scale"] and stale == ["rig_compliance"]
    assert current == () and at_out is empty and cv.fit.specs == ()
    assert calls == [("rig_compliance",)] and drawn == [] and ci == {}


def test_caliper_scatter_is_pooled_over_canes_with_more_calipers_than_a_line_needs():
    """Each cane's line has two parameters: three calipers give one degree of freedom, two give
    none (skipped), and a dataset with none anywhere falls back to the documented default."""
    from types import SimpleNamespace

    from canebench.discovery.screenset import CALIPER_SIGMA_DEFAULT_M, CALIPER_SIGMA_FLOOR_M, caliper_sigma

    def geom(cane, s, resid_mm):
        return SimpleNamespace(cane=cane, cal_s=np.asarray(s, float), cal_resid=1e-3 * np.asarray(resid_mm, float))

    a = geom("a", [0.5, 0.6, 0.7], [0.1, -0.2, 0.1])  # sum of squares 0.06 mm^2, 1 dof
    b = geom("b", [0.4, 0.5, 0.6, 0.7], [0.3, -0.3, -0.3, 0.3])  # 0.36 mm^2, 2 dof
    two = geom("c", [0.5, 0.7], [5.0, -5.0])  # no dof: its (impossible) residuals are not used
    # a cane's calipers count once however many of its trials are in the list
    got = caliper_sigma([a, a, a, b, two, b])
    assert got == pytest.approx(1e-3 * math.sqrt((0.06 + 0.36) / 3), rel=1e-12)
    assert caliper_sigma([two]) == CALIPER_SIGMA_DEFAULT_M
    assert caliper_sigma([geom("d", [0.5, 0.6, 0.7], [0, 0, 0])]) == CALIPER_SIGMA_FLOOR_M


def test_a_flare_must_read_what_the_calipers_read(bundled_trials):
    """The calipers are data too. A long, thin flare hidden in the stiffness alone (the calipers
    read the plain line, as a neighbour's support or a soft-cane bias would leave them) is what
    the fit takes without the caliper term (9 scatters at the calipers); with it, the fitted
    flare's change at every caliper stays below their own scatter, which is what "invisible to
    the calipers" means (a third of the term's weight would let it reach 1.3). Every trial
    carries its own cane's calipers, through folds and resamples, and a cane counts once; a
    diameter factor scales the line, not the calipers' scatter."""
    from dataclasses import replace

    from canebench.discovery.fit import Candidate, fit_candidate
    from canebench.discovery.screen import trial_geometry
    from canebench.discovery.screenset import Anchored, ScreenSet
    from canebench.model.effects import AppliedEffects, EffectSpec
    from canebench.model.presets import PRESETS

    cfg = PRESETS["beam-consistent"]
    geoms = [trial_geometry(t, cfg) for t in bundled_trials]
    ss = ScreenSet.build(geoms)
    assert len(ss.cal_s) == 3 * len(ss.trials) and 0 < ss.cal_sigma < 1e-3
    for i, g in enumerate(geoms):
        np.testing.assert_array_equal(ss.cal_s[ss.cal_idx == i], g.cal_s)
    half = ScreenSet.build([trial_geometry(t, cfg.replace(diameter_factor=0.5)) for t in bundled_trials])
    assert half.cal_sigma == pytest.approx(ss.cal_sigma, rel=1e-9)
    lkb = -np.log(ss.c0 * 1e3)
    long_thin = EffectSpec.parse("base_flare(excess_mm=6, length_mm=600)")
    fx = AppliedEffects([long_thin.instance()])
    at_cal = fx.diameter(ss.cal_s, ss.cal_line) - ss.cal_line
    assert at_cal.min() > 3 * ss.cal_sigma  # the calipers would have seen it
    canes, inv = np.unique(ss.canes, return_inverse=True)
    lkf = Anchored(ss, lkb).predict((long_thin,)) + np.random.default_rng(3).normal(0, 0.05, len(canes))[inv]
    plain = replace(ss, cal_idx=ss.cal_idx[:0], cal_s=ss.cal_s[:0], cal_line=ss.cal_line[:0], cal_w=ss.cal_w[:0])

    def change_at_calipers(fit):
        f = AppliedEffects([s.instance() for s in fit.specs])
        return np.abs(f.diameter(ss.cal_s, ss.cal_line) - ss.cal_line).max()

    free = fit_candidate(Candidate.of(("base_flare",)), Anchored(plain, lkb), lkf)
    held = fit_candidate(Candidate.of(("base_flare",)), Anchored(ss, lkb), lkf)
    assert change_at_calipers(free) > 3 * ss.cal_sigma
    assert change_at_calipers(held) < ss.cal_sigma
    # the term: 0.5 sum over canes of (change / scatter)^2, one cane at a time
    term = ss.caliper_nll(fx)
    by_cane = sum(0.5 * np.sum((at_cal[ss.canes[ss.cal_idx] == c] / ss.cal_sigma) ** 2) / 3 for c in canes)
    assert term == pytest.approx(by_cane, rel=1e-12)
    one = ss.canes == canes[-1]
    g0 = geoms[int(np.flatnonzero(one)[0])]  # the cane's own calipers, counted once
    own = 0.5 * np.sum(((fx.diameter(g0.cal_s, g0.cal_line) - g0.cal_line) / ss.cal_sigma) ** 2)
    assert ss.subset(one).caliper_nll(fx) == pytest.approx(own, rel=1e-12)
    rows = np.flatnonzero(one)
    twice = ss.take(np.concatenate([rows, rows]), np.array(["x"] * len(rows) + ["y"] * len(rows)))
    assert twice.caliper_nll(fx) == pytest.approx(2 * own, rel=1e-12)
    assert ss.caliper_nll(AppliedEffects([EffectSpec.parse("root_compliance(k_root=20)").instance()])) == 0.0


def test_geometry_draws_carry_the_caliper_lines_least_squares_error_through_the_screen(bundled_trials):
    """Each cane's line error has the least-squares covariance (centroid sigma^2 / n, slope
    sigma^2 / Sxx, independent); to first order the trial's ln k moves by J_c dc + J_b db, with
    J from finite differences of the screen here, independently of the draws; and a Monte Carlo
    of perturbed readings refitted with the chain's own line fit gives the same variance. Draws
    of 0.2 mm on 5-10 mm canes are 2-4 %, where d^-4 is linear to a few %: variance within 10 % (2000 draws
    give 3 % sampling error on a variance). A cane's trials share one line error: their g
    correlate; canes are independent."""
    from canebench.discovery.adequacy import geometry_draws
    from canebench.discovery.screen import trial_geometry
    from canebench.discovery.screenset import Anchored, ScreenSet
    from canebench.model.presets import PRESETS

    ss = ScreenSet.build([trial_geometry(t, PRESETS["beam-consistent"]) for t in bundled_trials])
    lkb = np.full(len(ss.trials), -3.0)  # any anchor: the draws are changes in ln k
    g = geometry_draws(Anchored(ss, lkb), (), n_draws=2000, seed=3)
    assert g.shape == (2000, len(ss.trials))
    var_lin = np.zeros(len(ss.trials))
    h = 1e-6
    for i in range(len(ss.trials)):
        cane = ss.canes[i]
        s = ss.cal_s[ss.cal_idx == i]
        sc, sxx = s.mean(), np.sum((s - s.mean()) ** 2)
        pts = np.isin(ss.idx, np.flatnonzero(ss.canes == cane))
        base = Anchored(ss.with_diameters(ss.d0), lkb).predict(())[i]
        jc = (Anchored(ss.with_diameters(ss.d0 + h * pts), lkb).predict(())[i] - base) / h
        jb = (Anchored(ss.with_diameters(ss.d0 + h * pts * (ss.s - sc)), lkb).predict(())[i] - base) / h
        assert jc > 0  # a thicker line: a stiffer cane
        var_lin[i] = ss.cal_sigma**2 * (jc**2 / len(s) + jb**2 / sxx)
    np.testing.assert_allclose(g.var(axis=0), var_lin, rtol=0.10)
    # independently: perturb the readings themselves, refit each line with the chain's own
    # least-squares fit (fit_diameter) and recompute on the screen. 2000 draws each; ln k is
    # skewed (d^-4), so each variance has about 4.5 % sampling error and a ratio of two about
    # 6.5 %: every trial's within 25 % (4 errors), their mean over 18 independent canes within 5 %
    from canebench.model.diameter import fit_diameter

    rng = np.random.default_rng(8)
    canes = list(dict.fromkeys(ss.canes))
    first = {c: int(np.flatnonzero(ss.canes == c)[0]) for c in canes}
    cal = {c: (ss.cal_s[ss.cal_idx == first[c]], ss.cal_line[ss.cal_idx == first[c]]) for c in canes}
    base_fit = {c: fit_diameter(*cal[c]) for c in canes}
    cane_q = ss.canes[ss.idx]
    lk0 = Anchored(ss.with_diameters(ss.d0), lkb).predict(())
    mc = np.empty((2000, len(ss.trials)))
    for b in range(2000):
        dd = np.zeros_like(ss.d0)
        for c in canes:
            s_c, line = cal[c]
            refit = fit_diameter(s_c, line + rng.normal(0.0, ss.cal_sigma, len(s_c)))
            q = cane_q == c
            dd[q] = refit(ss.s[q]) - base_fit[c](ss.s[q])
        mc[b] = Anchored(ss.with_diameters(ss.d0 + dd), lkb).predict(()) - lk0
    ratio = g.var(axis=0) / mc.var(axis=0)
    assert np.all(np.abs(ratio - 1) < 0.25) and abs(ratio.mean() - 1) < 0.05, ratio
    same = [(i, j) for i in range(len(ss.trials)) for j in range(i) if ss.canes[i] == ss.canes[j]]
    other = [(i, j) for i in range(len(ss.trials)) for j in range(i) if ss.canes[i] != ss.canes[j]]
    cc = np.corrcoef(g.T)
    assert np.mean([cc[i, j] for i, j in same]) > 0.8
    assert abs(np.mean([cc[i, j] for i, j in other])) < 0.02


def test_adequacy_holds_its_level_where_level_and_residual_share_the_geometry_error():
    """18 canes of 3 trials: a line error g (sd 0.25 in ln k, what the self-test's calipers give)
    raises the model's level and lowers the residual together, beside the canes' own offsets
    (0.15) and trial noise (0.05). The permutation check ignores the shared error and rejects
    twice as often as its level; the geometry null (given draws of g from the same law) is
    centred where the nulls' r are and close to its level: its variance components are
    estimated from the table, which makes it a little liberal (measured over 600 such nulls:
    7.7 % at 0.05, 1.7 % at 0.01, the level discover uses). Asserted at 0.01 on 200: fewer than
    9 (a test holding 0.02 gives 9 or more with probability 0.02). It still sees a
    neighbour-like stiffening that goes as the cane's compliance (ln(1 + c / k), 0.6 of it left
    after the mean was fitted)."""
    from canebench.discovery.adequacy import level_trend_geometry
    from canebench.discovery.structure import level_trend

    rng = np.random.default_rng(11)
    canes = np.repeat([f"c{i:02d}" for i in range(18)], 3)
    inv = np.repeat(np.arange(18), 3)

    def table(extra):
        true = np.repeat(rng.normal(-3.5, 1.0, 18), 3) + rng.normal(0, 0.3, 54)
        g = np.repeat(rng.normal(0, 0.25, 18), 3)
        r = np.repeat(rng.normal(0, 0.15, 18), 3) + rng.normal(0, 0.05, 54) + extra(true) - g
        draws = rng.normal(0, 0.25, (1000, 18))[:, inv]
        return canes, r, true + g, draws

    p_perm, p_geo = [], []
    for i in range(200):
        c, r, lev, draws = table(lambda x: 0 * x)
        p_perm.append(level_trend(pd.DataFrame({"cane": c, "r": r, "x": lev}), "r", "x", seed=i, n_perm=400)["p"])
        p_geo.append(level_trend_geometry(c, r, lev, draws, seed=i)["p"])
    print("geometry null rejections at 0.01:", int(np.sum(np.array(p_geo) < 0.01)), "of 200")
    assert np.sum(np.array(p_geo) < 0.01) < 9, np.sort(p_geo)[:20]
    # what the shared error does to a null that ignores it: 22 measured; 20 or more has
    # probability 0.003 for a test that holds 0.05
    assert np.sum(np.array(p_perm) < 0.05) >= 20, np.sort(p_perm)[:25]
    power = [level_trend_geometry(*table(lambda x: 0.6 * np.log1p(np.exp(-(x + 3.5)))), seed=i)["p"]
             for i in range(50)]
    print("power at 0.01:", int(np.sum(np.array(power) < 0.01)), "of 50")
    assert np.sum(np.array(power) < 0.01) >= 30, np.sort(power)
    # a draw the screen could not evaluate leaves its trial out, counted, instead of poisoning the null
    c, r, lev, draws = table(lambda x: 0 * x)
    bad = draws.copy()
    bad[5, 7] = np.nan
    keep = np.arange(54) != 7
    got, ref = level_trend_geometry(c, r, lev, bad, seed=1), level_trend_geometry(c[keep], r[keep], lev[keep],
                                                                                   draws[:, keep], seed=1)
    assert got["n_trials_left_out"] == 1 and got["p"] == ref["p"] and np.isfinite(got["null_median"])


@pytest.mark.heavy
def test_the_selection_score_test_holds_its_level_where_the_residual_carries_the_caliper_line_error(bundled_trials):
    """Nulls on the bundled geometry whose residual carries each cane's caliper-line error at
    the real calipers' scatter (0.9 mm; 1.06 pooled on the field data): r = -g + cane offsets
    (0.15) + trial noise (0.05), g drawn by ``geometry_draws``. A cane read too thick is
    predicted too stiff and measures softer, which a root spring beside a flare could mimic;
    the score test's denominator carries each cane's whole contribution, so it should not.
    Over 80 nulls, neither the first step's singles (Bonferroni 0.005 each) nor the pair test
    (0.025) rejects 7 times or more (a test holding 0.025 does with probability 0.004). The
    line error itself scatters the canes by about 0.9 in ln k at this scatter, so the test
    sees only what stands out of it: a global shift of 0.8 (about 3.8 standard errors of a
    mean over 18 canes) is seen in at least 15 of 20."""
    import dataclasses
    import itertools

    from canebench.discovery.adequacy import geometry_draws
    from canebench.discovery.fit import Candidate, direction_test_p, fit_candidate
    from canebench.discovery.screen import trial_geometry
    from canebench.discovery.screenset import Anchored, ScreenSet
    from canebench.discovery.selection import ALPHA
    from canebench.discovery.workflow import SCREENED
    from canebench.model.presets import PRESETS

    ss = ScreenSet.build([trial_geometry(t, PRESETS["beam-consistent"]) for t in bundled_trials])
    lkb = -np.log(ss.c0 * 1e3)
    g = geometry_draws(Anchored(dataclasses.replace(ss, cal_sigma=0.9e-3), lkb), (), n_draws=100, seed=1)
    assert 0.5 < np.std(g) < 1.5  # the line error moves ln k by about 0.9 at this scatter
    _, inv = np.unique(ss.canes, return_inverse=True)
    rng = np.random.default_rng(2)
    pairs = list(itertools.combinations(SCREENED, 2))
    level_single, level_pair = 0.5 * ALPHA / len(SCREENED), 0.5 * ALPHA

    def rejections(i, shift):
        lkf = lkb - g[i] + shift + rng.normal(0, 0.15, inv.max() + 1)[inv] + rng.normal(0, 0.05, len(lkb))
        f0 = fit_candidate(Candidate.of(()), Anchored(ss, lkb), lkf)
        single = min(direction_test_p(c, Anchored(ss, lkb), lkf, (), f0.s2, f0.t2, n_perm=2000, seed=i) for c in SCREENED)
        pair = direction_test_p(pairs, Anchored(ss, lkb), lkf, (), f0.s2, f0.t2, n_perm=2000, seed=i)
        return single < level_single, pair < level_pair

    nulls = np.array([rejections(i, 0.0) for i in range(80)])
    print("singles / pairs rejecting over 80 nulls:", nulls.sum(axis=0))
    assert nulls[:, 0].sum() < 7 and nulls[:, 1].sum() < 7, nulls.sum(axis=0)
    shifted = np.array([rejections(80 + i, 0.8) for i in range(20)])
    print("singles / pairs rejecting over 20 with the shift:", shifted.sum(axis=0))
    assert shifted[:, 0].sum() >= 15, shifted.sum(axis=0)


def test_the_screen_carries_the_engines_response_to_a_pitched_probe():
    """A pitched probe also loads the cane along its axis (tension pitched up, compression
    down), which the linear screen's 1/cos^2 does not see. On 12 bundled trials the beam at an
    extra pitch of +-30 deg differs from the screen alone by up to 0.07 in ln k (measured 0.074,
    0.067; 0.02 at 10 deg). With the engine tabulated at +-20 and +-40 deg
    (:func:`.engine_runs.pitch_table`) the screen must reproduce the engine at pitches off that grid within
    0.01 (a fifth of the 0.05 materiality step; measured 0.0018 at most)."""
    from canebench.data.dataset import bundled_dataset, load_dataset
    from canebench.discovery.screen import trial_geometry
    from canebench.discovery.screenset import Anchored, ScreenSet
    from canebench.discovery.engine_runs import BaselineEngine, ok_log_k, pitch_table
    from canebench.discovery.workflow import BASELINES
    from canebench.execute.executors import SerialExecutor
    from canebench.execute.runner import run_trials
    from canebench.model.effects import EffectSpec
    from canebench.model.presets import PRESETS
    from canebench.probe.protocol import PROTOCOLS

    ex = SerialExecutor()
    trials = load_dataset(bundled_dataset(), "b1c*,b2c1")
    backend, preset, _ = BASELINES["beam"]
    cfg0, proto = PRESETS[preset], PROTOCOLS["fast"]
    F = pd.DataFrame({"trial": [t.id for t in trials]})
    lkb = ok_log_k(run_trials(trials, [backend], proto, cfg0, None, executor=ex).to_df(), backend, F.trial)
    ss = ScreenSet.build([trial_geometry(t, cfg0) for t in trials])
    at_t, summary = pitch_table(BaselineEngine(trials, F, backend, proto, cfg0, (), None, ex, None), Anchored(ss, lkb))
    ss_t = at_t.screen
    assert at_t.log_k is lkb  # the table moves the screen, not its anchor
    assert summary["n_failed"] == 0
    for angle in (30.0, -30.0, 10.0):
        spec = EffectSpec("probe_misalignment", (("angle_deg", angle),))
        res = run_trials(trials, [backend], proto, cfg0.replace(effects=(spec,)), None, executor=ex).to_df()
        eng = ok_log_k(res, backend, F.trial)
        assert np.all(np.isfinite(eng))
        without = np.max(np.abs(eng - Anchored(ss, lkb).predict((spec,))))
        with_table = np.max(np.abs(eng - Anchored(ss_t, lkb).predict((spec,))))
        if abs(angle) == 30.0:
            assert without > 0.04  # the premise: the nonlinearity is material there
        assert with_table < 0.01, (angle, with_table, without)
    # anchored at a pitch, the prediction at another pitch uses the table's difference
    a = EffectSpec("probe_misalignment", (("angle_deg", 20.0),))
    res = run_trials(trials, [backend], proto, cfg0.replace(effects=(a,)), None, executor=ex).to_df()
    ss_a, lka = ss_t.anchored((a,)), ok_log_k(res, backend, F.trial)
    b = EffectSpec("probe_misalignment", (("angle_deg", -30.0),))
    eng_b = ok_log_k(run_trials(trials, [backend], proto, cfg0.replace(effects=(b,)), None,
                                 executor=ex).to_df(), backend, F.trial)
    assert np.max(np.abs(eng_b - Anchored(ss_a, lka).predict((b,)))) < 0.01
    # cross-validation folds and bootstrap resamples carry each trial's own row of the table

    full = Anchored(ss_a, lka).predict((b,))
    keep = np.arange(len(trials)) % 3 != 0
    # equal to rounding (a subset's sums run in another SIMD order on some CPUs); a trial given
    # another trial's row of the table would be off by the rows' difference, 1e-3 or more here
    np.testing.assert_allclose(Anchored(ss_a.subset(keep), lka[keep]).predict((b,)), full[keep], rtol=0, atol=1e-12)
    rows = np.array([5, 5, 0, 11])
    np.testing.assert_allclose(Anchored(ss_a.take(rows, np.array(["a", "a", "b", "c"])), lka[rows]).predict((b,)),
                               full[rows], rtol=0, atol=1e-12)



def test_a_cane_resample_draws_whole_canes_and_counts_each_copy_as_a_cane(bundled_trials):
    """The cane bootstrap's unit is the cane: a resample holds all of a drawn cane's trials, in as
    many groups as there are canes, a cane drawn twice being two groups (else the random cane
    effect would see one cane with doubled trials, and a narrower spread between canes)."""
    from canebench.discovery.fit import cane_resamples
    from canebench.discovery.screen import trial_geometry
    from canebench.discovery.screenset import Anchored, ScreenSet
    from canebench.model.presets import PRESETS

    ss = ScreenSet.build([trial_geometry(t, PRESETS["beam-consistent"]) for t in bundled_trials[:18]])
    at = Anchored(ss, np.log(np.linspace(0.01, 0.3, len(ss.trials))))
    own = {c: set(np.flatnonzero(ss.canes == c)) for c in np.unique(ss.canes)}
    assert len(own) >= 4 and all(len(r) > 1 for r in own.values())  # the premise: canes of several trials
    draws = list(cane_resamples(at, 30, seed=3))
    assert len(draws) == 30
    repeated = 0
    for rows, sub in draws:
        np.testing.assert_array_equal(sub.log_k, at.log_k[rows])  # the rows index the field data alike
        groups = {g: set(rows[sub.screen.canes == g]) for g in np.unique(sub.screen.canes)}
        assert len(groups) == len(own)
        for g, r in groups.items():
            assert r == own[g.split("#")[0]]  # a whole cane, and only that cane
            assert np.sum(sub.screen.canes == g) == len(r)  # each of its trials once
        repeated += len({g.split("#")[0] for g in groups}) < len(own)
    assert repeated > 20  # with replacement: about 1 - n!/n^n of draws repeat a cane
    again = list(cane_resamples(at, 30, seed=3))
    assert all(np.array_equal(a[0], b[0]) for a, b in zip(draws, again))
    assert not all(np.array_equal(a[0], b[0]) for a, b in zip(draws, cane_resamples(at, 30, seed=4)))


def test_the_interval_widening_for_few_canes_follows_student_s_t():
    """The cane bootstrap's percentile interval is widened by t(0.975, G - 1) / z(0.975) * sqrt(G / (G - 1)):
    checked against printed t-table values (t(0.975, 17) = 2.110, t(0.975, 2) = 4.303, z = 1.960), to
    the tables' three decimals; it falls toward 1 as canes are added and is infinite below two canes,
    whose bootstrap has no spread between canes to draw."""
    from canebench.discovery.fit import small_sample_widening as w

    assert w(18) == pytest.approx(2.110 / 1.960 * (18 / 17) ** 0.5, rel=1e-3)
    assert w(3) == pytest.approx(4.303 / 1.960 * 1.5 ** 0.5, rel=1e-3)
    gs = [2, 3, 5, 10, 18, 40, 100, 1000]
    assert all(a > b > 1.0 for a, b in zip([w(g) for g in gs], [w(g) for g in gs[1:]]))
    assert w(100000) == pytest.approx(1.0, abs=1e-4)
    assert w(1) == math.inf and w(0) == math.inf


def test_an_interval_is_widened_about_the_fit_in_the_fit_s_coordinate_and_cut_at_the_bounds():
    """``intervals_from_draws``: each end of the percentile interval moves away from the fit by the
    widening times its distance. A pitch is widened in degrees and cut at its 45-degree bound; a
    spring in log, so its low end stays positive where widening in N/m would cross zero and the
    widened ends stay in the draws' ratio about the fit; an end on the fit's wrong side is the fit;
    a widening of 1 is the plain percentile interval."""
    from canebench.discovery.fit import Candidate, Fit, intervals_from_draws, small_sample_widening

    def fit_of(name, value):
        cand = Candidate.of((name,))
        x = cand.to_internal({cand.free[0]: value})
        return Fit(cand, x, cand.specs(x), 0.0, 0.01, 0.01, 54)

    rng = np.random.default_rng(5)
    # a pitch fitted 30 degrees, its draws 30 +- 2 with five at 43-44
    pitch = fit_of("probe_misalignment", 30.0)
    d = np.r_[rng.normal(30.0, 2.0, 95), [43.0, 44.0, 44.0, 44.0, 44.0]].reshape(-1, 1)
    lo, hi = np.percentile(d[:, 0], [2.5, 97.5])
    key = ("probe_misalignment", "angle_deg")
    assert intervals_from_draws(pitch, d, 18, widening=1.0)[key] == pytest.approx((lo, hi), abs=1e-12)
    wlo, whi = intervals_from_draws(pitch, d, 18)[key]
    assert 30.0 - wlo == pytest.approx(small_sample_widening(18) * (30.0 - lo), rel=1e-12)
    assert whi == 45.0  # 30 + 1.11 x (44 - 30), the draws' 97.5th percentile widened, is past the bound
    # the draws' 2.5th percentile above the fit: the low end is the fit itself, however wide the widening
    assert intervals_from_draws(pitch, d + 5.0, 18, widening=3.0)[key][0] == 30.0
    # a rig of 100 N/m, its draws spread by a factor of e^0.4 either way (lognormal)
    rig = fit_of("rig_compliance", 100.0)
    d = np.exp(rng.normal(math.log(100.0), 0.4, 4000)).reshape(-1, 1)
    plo, phi = np.percentile(d[:, 0], [2.5, 97.5])
    assert 100.0 - 3.0 * (100.0 - plo) < 0  # widened in N/m, the low end would be negative
    rlo, rhi = intervals_from_draws(rig, d, 18, widening=3.0)[("rig_compliance", "k_rig")]
    assert rlo == pytest.approx(20.0)  # cut at the search's lowest rig (20 N/m); the log scale is checked next
    rlo, rhi = intervals_from_draws(rig, d, 18, widening=1.5)[("rig_compliance", "k_rig")]
    assert math.log(100.0 / rlo) == pytest.approx(1.5 * math.log(100.0 / plo), rel=0.02)
    assert math.log(rhi / 100.0) == pytest.approx(1.5 * math.log(phi / 100.0), rel=0.02)


def test_a_flare_s_interval_is_widened_per_parameter_and_one_reaching_no_excess_is_not_named():
    """A flare's two parameters are widened each on its own axis (excess in mm, length in log); an
    excess whose widened low end reaches 0 (no flare) is what the interval rule withholds
    (``nulls.covers_null``), while its plain percentile interval does not reach it; an end that
    all but 2.5 % of the draws lie below is the fit itself; below two canes (no spread between
    canes) the interval is the whole search range."""
    from canebench.discovery.fit import Candidate, Fit, intervals_from_draws
    from canebench.discovery.nulls import covers_null

    cand = Candidate.of(("base_flare",))
    assert [p for _, p in cand.free] == ["excess_mm", "length_mm"]
    x = cand.to_internal({("base_flare", "excess_mm"): 2.0, ("base_flare", "length_mm"): 100.0})
    fit = Fit(cand, x, cand.specs(x), 0.0, 0.01, 0.01, 54)
    rng = np.random.default_rng(2)
    # excess drawn 2 +- 0.5 mm but never above the fit; length 100 mm, spread e^0.15 either way
    d = np.c_[2.0 - np.abs(rng.normal(0.0, 0.5, 400)) - 0.6 * (rng.random(400) < 0.03),
              np.exp(rng.normal(math.log(100.0), 0.15, 400))]
    plo = np.percentile(d[:, 0], 2.5)
    assert 0.0 < plo < 4.0 / 3.0  # the premise: clear of no flare, but 2 - 3 (2 - plo) is below 0
    plain = intervals_from_draws(fit, d, 18, widening=1.0)
    wide = intervals_from_draws(fit, d, 18, widening=3.0)
    assert plain[("base_flare", "excess_mm")][1] == 2.0 == wide[("base_flare", "excess_mm")][1]  # the fit itself
    assert wide[("base_flare", "excess_mm")][0] == 0.0  # 2 - 3 (2 - plo) < 0: cut at the bound, no flare
    spec = fit.specs[0]
    assert covers_null(spec, plain) == [] and covers_null(spec, wide) == ["excess_mm"]
    llo, lhi = wide[("base_flare", "length_mm")]
    ql, qh = np.percentile(np.log(d[:, 1]), [2.5, 97.5])
    assert math.log(100.0 / llo) == pytest.approx(3.0 * (math.log(100.0) - ql), rel=1e-9)
    assert math.log(lhi / 100.0) == pytest.approx(3.0 * (qh - math.log(100.0)), rel=1e-9)
    # one cane: nothing to resample between canes, so nothing is excluded
    lone = intervals_from_draws(fit, d, 1)
    lo_box, hi_box = (b.tolist() for b in cand.box())
    assert lone[("base_flare", "excess_mm")] == (lo_box[0], hi_box[0])
    assert lone[("base_flare", "length_mm")] == pytest.approx((math.exp(lo_box[1]), math.exp(hi_box[1])))


def test_bootstrap_ci_widens_for_the_number_of_canes_not_of_trials(bundled_trials):
    """``bootstrap_ci`` is the percentile interval of its own draws widened for the canes resampled
    (18 here, of 54 trials): the same draws widened for 54 would be narrower, for 2 far wider."""
    from canebench.discovery.fit import Candidate, bootstrap_ci, bootstrap_draws, fit_candidate, intervals_from_draws
    from canebench.discovery.screenset import Anchored

    cfg, ss, lkb, canes, height, inv, rng, noise, truth = _scaled_bundled_screen(bundled_trials)
    at = Anchored(ss, lkb)
    lkf = at.predict(truth) + noise
    assert (len(np.unique(canes)), len(lkb)) == (18, 54)
    fit = fit_candidate(Candidate.of(("modulus_scale",)), at, lkf)
    ci = bootstrap_ci(fit, at, lkf, n_boot=30, seed=4)
    draws = bootstrap_draws(fit, at, lkf, n_boot=30, seed=4)
    for g, same in ((18, True), (54, False), (2, False)):
        assert (intervals_from_draws(fit, draws, g) == ci) is same, g


def _scaled_bundled_screen(bundled_trials):
    """The bundled geometry's screen with a modulus scale of 1.5, cane offsets (0.15) and trial noise (0.03)."""
    from canebench.discovery.screen import trial_geometry
    from canebench.discovery.screenset import ScreenSet
    from canebench.model.effects import EffectSpec
    from canebench.model.presets import PRESETS

    cfg = PRESETS["beam-consistent"]
    geoms = [trial_geometry(t, cfg) for t in bundled_trials]
    ss = ScreenSet.build(geoms)
    lkb = -np.log(ss.c0 * 1e3)
    canes, height = ss.canes, np.array([g.height for g in geoms])
    _, inv = np.unique(canes, return_inverse=True)
    rng = np.random.default_rng(5)
    noise = rng.normal(0, 0.15, inv.max() + 1)[inv] + rng.normal(0, 0.03, len(lkb))
    return cfg, ss, lkb, canes, height, inv, rng, noise, (EffectSpec.parse("modulus_scale(scale=1.5)"),)


def _power_law_diameters(bundled_trials, cfg, ss, inv, rng, low=0.4, high=2.2):
    """Each cane's diameters a power law a + b (1 - s/L)^p through its caliper line's values at the
    calipers, p drawn from ``low``-``high`` per cane (the line itself where p is 1). Also used by
    ``tests/scripts/taper_scale_bias.py``."""
    from canebench.model.chain import cane_curve

    expo = rng.uniform(low, high, inv.max() + 1)
    d0 = ss.d0.copy()
    for i, t in enumerate(bundled_trials):
        L = cane_curve(t.cane, cfg).length
        cs, cl = ss.cal_s[ss.cal_idx == i], ss.cal_line[ss.cal_idx == i]
        x = lambda s: np.clip(1.0 - s / L, 0.0, 1.0) ** expo[inv[i]]  # noqa: E731
        a, b = np.linalg.lstsq(np.column_stack([np.ones(len(cs)), x(cs)]), cl, rcond=None)[0]
        q = ss.idx == i
        d0[q] = a + b * x(ss.s[q])
    return d0

@pytest.mark.heavy
def test_a_trend_along_the_canes_withholds_names_only_when_no_library_effect_takes_it(bundled_trials):
    """The within-cane check's null carries the caliper line's random error, not the taper's
    curvature below the calipers. An independent generator's power-law tapers (exponents drawn
    from 0.4-2.2, two thirds convex) left every set's residual trending with push height and
    withheld a correct modulus scale (its ds05, p = 0.0013).

    (A) That mechanism on the bundled geometry: each cane's diameters a power law
    a + b (1 - s/L)^p through its caliper line's values at the calipers (p drawn as that
    generator drew it), modulus scale 1.5, cane offsets (0.15) and trial noise (0.03). With the
    scale named the check fails (asserted: the premise), and ``base_flare`` takes the trend.
    These canes are thicker than that generator's (bases 12-36 mm): the flare that takes the
    trend is pressed to its 25 mm bound, which is recorded (``at_bound``), not refused.
    (B) The same scale and each cane's middle and top pushes softer by (0.4, 1.1) in ln (the
    independent generator's 2 % canker between the lower pushes gave 0, 0.42, 1.15): the check
    fails and nothing takes it. A fifth or a tenth of that step is taken by a flare (25 mm over
    80 mm; 7 mm over 110 mm, measured in review): three pushes a cane do not tell a moderate
    weak zone from a fuller base, as docs/discovery.md states."""
    from canebench.discovery.fit import Candidate, cross_validate
    from canebench.discovery.screenset import Anchored
    from canebench.discovery.verdict import ADEQUACY_ALPHA, within_after, within_taken_by
    from canebench.discovery.workflow import SCREENED

    cfg, ss, lkb, canes, height, inv, rng, noise, scale = _scaled_bundled_screen(bundled_trials)
    at = Anchored(ss, lkb)
    named = ("modulus_scale",)
    others = tuple(c for c in SCREENED if c not in named)

    def check(lkf):
        return within_after(cross_validate(Candidate.of(named), at, lkf), at, canes, height, 1.0, 0)

    # (A) power-law tapers through each cane's caliper line
    d0 = _power_law_diameters(bundled_trials, cfg, ss, inv, rng)
    taper = Anchored(ss.with_diameters(d0), lkb).predict(scale) + noise
    w = check(taper)
    assert w["p"] < ADEQUACY_ALPHA, w  # the premise: the scale alone leaves the trend
    taken, tried = within_taken_by(others, named, at, taper, canes, height, 1.0, w["n_trials"], 0)
    assert taken is not None and taken["effect"] == "base_flare", tried
    assert taken["p"] >= ADEQUACY_ALPHA and taken["at_bound"] == ["excess_mm"] and len(tried) == len(others)
    # a spring at its stiffest adds nothing and cannot take anything
    assert all(t["why_not"].startswith("does nothing") for t in tried if t["effect"] in ("root_compliance",
                                                                                          "rig_compliance")), tried

    # (B) a weak zone between the lower pushes
    rank = np.array([int((height[inv == inv[i]] < height[i]).sum()) for i in range(len(height))])  # 0 = lowest
    canker = Anchored(ss, lkb).predict(scale) + noise - np.array([0.0, 0.4, 1.1])[rank]
    w = check(canker)
    assert w["p"] < ADEQUACY_ALPHA, w
    taken, tried = within_taken_by(others, named, at, canker, canes, height, 1.0, w["n_trials"], 0)
    assert taken is None, tried


def test_pushes_scattered_along_their_canes_beyond_the_calipers_error_withhold_names(bundled_trials):
    """A lateral support (a neighbouring cane as a spring) above the pushes on some canes and
    below them on others stiffens each cane's nearest push most: the pattern along the canes
    changes sign from cane to cane and cancels in the within-cane trend, but not in its size.
    An independent generator's (its ds14, springs of 300-3000 N/m) left a modulus scale of 2.8
    named and nothing flagged; its residual scattered within canes 20 times the caliper
    line's error. (A) Power-law tapers through the caliper lines (the largest within-cane
    spread a null reached, as in the test above) stay inside the allowance. (B) Springs of
    500 N/m above the top push of every other cane and below the lowest push of the rest,
    applied with the uniform cantilever's compliance at the push and the spring (each trial's
    EI from its own stiffness), do not: the spread fails the model (10 times the line's error;
    the trend fails here too, as the springs above stiffen more than those below, but on ds14
    it did not, p = 0.10)."""
    from canebench.discovery.adequacy import within_dispersion
    from canebench.discovery.fit import Candidate, cross_validate
    from canebench.discovery.screenset import Anchored
    from canebench.discovery.verdict import WITHIN_EXCESS, WITHIN_FLOOR, within_after

    cfg, ss, lkb, canes, height, inv, rng, noise, scale = _scaled_bundled_screen(bundled_trials)

    at = Anchored(ss, lkb)

    def spread(lkf):
        w = within_after(cross_validate(Candidate.of(("modulus_scale",)), at, lkf), at, canes, height, 1.0, 0)
        return w, within_dispersion(w, WITHIN_EXCESS, WITHIN_FLOOR)

    # (A) power-law tapers through each cane's caliper line
    d0 = _power_law_diameters(bundled_trials, cfg, ss, inv, rng)
    w, d = spread(Anchored(ss.with_diameters(d0), lkb).predict(scale) + noise)
    assert w["sd"] > w["geometry_sd"] > 0 and not d["fails"], d  # the tapers add spread, within the allowance

    # (B) a spring above the pushes on even canes, below them on odd ones
    c_hh = 1e-3 * np.exp(-lkb)  # m/N at the push
    h = height
    top = np.array([h[inv == inv[i]].max() for i in range(len(h))])
    low = np.array([h[inv == inv[i]].min() for i in range(len(h))])
    a = np.where(inv % 2 == 0, 1.15 * top, 0.6 * low)
    ei = h**3 / (3.0 * c_hh)
    c_ha = np.where(a >= h, h**2 * (3 * a - h), a**2 * (3 * h - a)) / (6.0 * ei)
    c_aa = a**3 / (3.0 * ei)
    k_s = 500.0
    stiffening = np.log(c_hh / (c_hh - c_ha**2 * k_s / (1.0 + k_s * c_aa)))
    w, d = spread(Anchored(ss, lkb).predict(scale) + noise + stiffening)
    assert d["fails"] and d["ratio"] > WITHIN_EXCESS and d["sd"] >= WITHIN_FLOOR, (w, d)
    # the spread alone, not the trend: without the springs the same canes pass
    w0, d0_ = spread(Anchored(ss, lkb).predict(scale) + noise)
    assert not d0_["fails"] and d0_["ratio"] < 2.0, d0_


def test_within_dispersion_is_the_pooled_within_cane_spread_against_the_caliper_lines():
    """sd and geometry_sd are pooled within-cane standard deviations (n - canes degrees of
    freedom), checked here on residuals built with known deviations."""
    from canebench.discovery.adequacy import within_dispersion, within_trend_geometry

    canes = np.repeat(np.arange(6), 3)
    dev = np.tile([-1.0, 0.0, 1.0], 6)  # each cane: deviations -1, 0, 1 about its mean
    resid = 0.2 * dev + np.repeat(np.linspace(-1, 1, 6), 3)  # cane offsets drop out
    position = np.tile([0.2, 0.4, 0.6], 6)
    g = np.stack([0.05 * dev * (1 if b % 2 else -1) + 3.0 for b in range(20)])  # within sd 0.05 in every draw
    w = within_trend_geometry(canes, resid, position, g)
    dof = 18 - 6
    assert w["sd"] == pytest.approx(math.sqrt(6 * 2 * 0.2**2 / dof))
    assert w["geometry_sd"] == pytest.approx(math.sqrt(6 * 2 * 0.05**2 / dof))
    d = within_dispersion(w, 3.0, 0.05)
    assert d["ratio"] == pytest.approx(4.0) and d["fails"]
    assert not within_dispersion(w, 5.0, 0.05)["fails"]  # inside the allowance
    assert not within_dispersion(w, 3.0, 0.5)["fails"]  # too small to matter


def test_within_dispersion_leaves_out_one_cane_in_ten_not_an_effect_along_every_cane():
    """The pooled spread leaves out the tenth of canes that scatter most (adequacy.TRIM_SHARE).

    Our self-test's obstruction sets (seed 7, sets 25-27) each held one trial that an
    obstruction engaged from contact made 5-11 times stiffer (no elbow to find): its cane
    alone lifted the pooled spread to 16-23 times the caliper line's. Here 15 canes of 3
    pushes with trial noise 0.03 in ln k and a geometry error of 0.02: (A) one push 6 times
    stiffer (ln 6 = 1.79) leaves the trimmed spread at the noise (within 40 %: 28 degrees of
    freedom give the pooled sd a relative error of about 13 %, so 40 % is 3 of those) and its
    ratio to the geometry's (0.03 / 0.02) under 2, while over every cane it would fail; (B)
    two such canes are more
    than the trim takes, and fail; (C) a scatter of 0.3 on every cane (a neighbour's support
    on each) fails trimmed or not."""
    from canebench.discovery.adequacy import within_dispersion, within_trend_geometry
    from canebench.discovery.verdict import WITHIN_EXCESS, WITHIN_FLOOR

    rng = np.random.default_rng(3)
    C, per, noise, geo = 15, 3, 0.03, 0.02
    canes = np.repeat(np.arange(C), per)
    position = np.tile([0.2, 0.4, 0.6], C)
    g = 0.5 + rng.normal(0.0, geo, (400, C * per))
    base = rng.normal(0.0, noise, C * per) + np.repeat(rng.normal(0.0, 0.3, C), per)

    def check(resid):
        w = within_trend_geometry(canes, resid, position, g)
        whole = {"sd": w["sd_all"], "geometry_sd": w["geometry_sd_all"]}
        return w, within_dispersion(w, WITHIN_EXCESS, WITHIN_FLOOR), within_dispersion(whole, WITHIN_EXCESS,
                                                                                       WITHIN_FLOOR)

    one = base.copy()
    one[3 * 7 + 1] += math.log(6.0)
    w, d, d_all = check(one)
    assert w["sd_trimmed_canes"] == ["7"], w  # the outlier's cane
    assert abs(w["sd"] / noise - 1.0) < 0.4 and d["ratio"] < 2.0 and not d["fails"], (w, d)
    assert d_all["fails"] and w["sd_all"] > 0.25, d_all
    two = one.copy()
    two[3 * 11] += math.log(6.0)
    assert check(two)[1]["fails"]
    every = base + 0.3 * rng.choice([-1.0, 1.0], C * per)
    w, d, _ = check(every)
    assert d["fails"] and w["sd"] > 0.2, (w, d)


def test_the_adequacy_lines_say_which_check_failed_and_which_canes_the_spread_left_out():
    """The CLI and the report word the checks once (checks_text); a failed check says so."""
    from canebench.discovery.checks_text import adequacy_lines

    doc = {"partial": [{"effect": "modulus_scale"}],
           "adequacy": {"alpha": 0.002, "inadequate": True,
                        "within_after_cv": {"r": 0.1, "p": 0.3, "null_sd": 0.1, "n_canes": 15, "sd_all": 0.319,
                                            "sd_trimmed_canes": ["b5c3"]},
                        "within_dispersion": {"sd": 0.024, "geometry_sd": 0.019, "ratio": 1.27, "factor": 8.0,
                                              "material": 0.06, "fails": False},
                        "shape": {"p": None, "predicted_spread": 0.002, "predicted_mean": 0.0,
                                  "level": {"mean": -0.37, "p": 5e-5, "excess": 0.15, "n_canes": 18,
                                            "fails": True}}}}
    lines = adequacy_lines(doc)
    assert len(lines) == 5, lines  # within trend, spread, shape (nothing to check), level, the verdict
    spread = next(line for line in lines if line.startswith("within-cane spread"))
    assert "b5c3" in spread and "0.319" in spread and not spread.endswith("it is")
    level = next(line for line in lines if "beyond the model's" in line)
    assert "-0.370" in level and level.endswith("it is")
    assert "partial, not named" in lines[-1]
    assert adequacy_lines({"adequacy": {}}) == []
    # the verdict follows the checks, not the partial list; a failed p-value check says so
    doc["adequacy"]["inadequate"], doc["partial"] = True, []
    doc["adequacy"]["after_cv"] = {"r": -0.6, "p": 0.0001, "n_canes": 18, "null_median": 0.1}
    lines = adequacy_lines(doc)
    assert lines[0].endswith("it is") and "baseline" in lines[-1], lines
    # older or sparser files: missing or None fields print as nan, never raise
    sparse = {"adequacy": {"alpha": 0.002, "within_after_cv": {"r": math.nan, "p": 1.0, "null_sd": math.nan,
                                                              "n_canes": 3},
                           "within_dispersion": {"sd": math.nan, "geometry_sd": math.nan, "ratio": math.nan,
                                                 "factor": 8.0, "material": 0.1, "fails": False},
                           "shape": None}}
    assert len(adequacy_lines(sparse)) == 2


def test_the_failure_reasons_explain_each_failed_check_and_only_those():
    """The withheld note's clauses (checks_text.failure_reasons): one per check the workflow
    listed as failed, in the workflow's order, with the figures that decided it."""
    from canebench.discovery.checks_text import failure_reasons

    ad = {"alpha": 0.002, "failed": ["dispersion", "shape_level"],
          "after_cv": {"r": -0.6, "p": 0.0001, "null_median": 0.1},
          "within_after_cv": {"r": 0.1, "p": 0.3, "null_sd": 0.1, "sd_trimmed_canes": ["b5c3", "b2c1"]},
          "within_dispersion": {"sd": 0.231, "geometry_sd": 0.019, "ratio": 12.2, "factor": 8.0, "material": 0.1,
                                "fails": True},
          "shape": {"p": 0.5, "level": {"mean": -0.37, "p": 5e-5, "excess": 0.15, "n_canes": 18, "fails": True}}}
    why = failure_reasons(ad)
    assert len(why) == 2, why
    assert why[0].startswith("leaves a cane's own pushes scattered") and "0.231" in why[0] and "12.2 times" in why[0]
    assert "b5c3, b2c1, which scatter most" in why[0]
    assert why[1].startswith("does not bend the traces") and "soften by 0.370" in why[1] and "18 canes" in why[1]
    # the trend's after_cv is in the document but did not fail: no clause for it
    assert not any("scale across canes" in w for w in why)
    ad["failed"] = ["trend"]
    (trend,) = failure_reasons(ad)
    assert "falls with the model's stiffness level" in trend and "r = -0.60" in trend and "< 0.002" in trend
    assert failure_reasons({"alpha": 0.002, "failed": []}) == []


def test_the_trimmed_spreads_pool_the_kept_canes_exactly():
    """Deterministic residuals: the trimmed sd and geometry_sd are the pooled within-cane figures
    of the canes kept, with their own degrees of freedom; canes are ranked by their own variance
    (a cane of 4 pushes is not trimmed for having more); a single push has no spread and does not
    count toward the ten canes a trim needs."""
    from canebench.discovery.adequacy import within_trend_geometry

    dev3, dev4 = np.array([-1.0, 0.0, 1.0]), np.array([-1.5, -0.5, 0.5, 1.5])
    amp = np.array([0.01, 0.02, 0.03, 0.04, 0.05, 0.06, 0.07, 0.08, 0.09, 0.2])  # cane 9 scatters most
    geo = np.linspace(0.01, 0.03, 10)  # each cane's own geometry error
    pushes = [dev3] * 8 + [dev4, dev3]  # cane 8 has 4 pushes
    canes = np.concatenate([np.full(len(d), c) for c, d in enumerate(pushes)])
    resid = np.concatenate([a * d for a, d in zip(amp, pushes)]) + 0.5 * canes
    gdev = np.concatenate([gc * d for gc, d in zip(geo, pushes)])
    g = np.stack([(1 if b % 2 else -1) * gdev + 2.0 for b in range(10)])
    position = np.concatenate([np.linspace(0.2, 0.6, len(d)) for d in pushes])
    w = within_trend_geometry(canes, resid, position, g)
    assert w["sd_trimmed_canes"] == ["9"], w
    keep = canes != 9
    ss_keep = sum(float(np.sum((a * d) ** 2)) for a, d in zip(amp[:9], pushes[:9]))
    gs_keep = sum(float(np.sum((gc * d) ** 2)) for gc, d in zip(geo[:9], pushes[:9]))
    dfk = int(keep.sum()) - 9
    assert w["sd"] == pytest.approx(math.sqrt(ss_keep / dfk))
    assert w["geometry_sd"] == pytest.approx(math.sqrt(gs_keep / dfk))
    n = len(canes)
    assert w["sd_all"] == pytest.approx(math.sqrt((ss_keep + 2 * 0.2**2) / (n - 10)))
    # by variance, not sum: cane 8 (4 pushes, 5 x 0.09^2 = 0.0405) outweighs cane 9 in sum when
    # cane 9 scatters 0.14 (2 x 0.14^2 = 0.0392), but not in variance (0.0135 against 0.0196)
    resid2 = resid.copy()
    resid2[canes == 9] = 0.14 * dev3 + 4.5
    assert within_trend_geometry(canes, resid2, position, g)["sd_trimmed_canes"] == ["9"]
    # nine canes: nothing trimmed
    nine = canes < 9
    w9 = within_trend_geometry(canes[nine], resid[nine], position[nine], g[:, nine])
    assert w9["sd_trimmed_canes"] == [] and w9["sd"] == pytest.approx(w9["sd_all"])
    # ten canes of which one is a single push: nine with spread, nothing trimmed
    one = ~((canes == 0) & (position > 0.2))
    w1 = within_trend_geometry(canes[one], resid[one], position[one], g[:, one])
    assert w1["sd_trimmed_canes"] == [], w1


def test_a_fitted_flare_carries_the_note_that_a_support_below_the_pushes_looks_the_same():
    """A flare is told apart from a neighbour's support below the pushes by nothing in stiffness
    data (docs/discovery.md, seed 8's set 38): a named flare says so, with its decay length and
    the canes' lowest pushes, and says the pair can match it when a root spring stands beside
    it; a flare withheld as partial says so too. No flare fitted: no note."""
    from canebench.discovery.checks_text import lookalike_notes

    flare = {"effect": "base_flare", "scope": "global", "params": {"excess_mm": 4.2, "length_mm": 122.7}}
    root = {"effect": "root_compliance", "scope": "global", "params": {"k_root": 459.0}}
    obstruction = {"effect": "obstruction", "scope": "per_trial", "params": {}}
    (alone,) = lookalike_notes([flare, obstruction], [], [896.0, 445.0, 610.0])
    assert alone.startswith("base_flare, named,") and "decays over 123 mm" in alone
    assert "445-896 mm" in alone and "lateral spring support" in alone and "root_compliance" not in alone
    (beside,) = lookalike_notes([root, flare], [], [445.2, 444.9])
    assert "root_compliance beside the flare can match it" in beside and "are 445 mm along" in beside
    (withheld,) = lookalike_notes([obstruction], [root, flare], [445.0])
    assert "withheld as partial" in withheld and "root_compliance beside" in withheld
    assert lookalike_notes([root, obstruction], [], [445.0]) == []
    assert lookalike_notes([], [root], [445.0]) == []
    assert lookalike_notes([flare], [], []) == []


def test_an_elbow_that_spoils_the_line_is_found_and_scored_up_to_it():
    """A second body engaging partway leaves the whole trace no line (R^2 < 0.8), the one fault
    that makes a trace unusable by itself: its elbow is searched all the same, and up to it the
    trace is the cane's line. A trial whose refit is still no line is named but not scored, and says why."""
    from types import SimpleNamespace

    from canebench.data.rig import RigTrial
    from canebench.discovery.contacts import field_onsets
    from canebench.discovery.workflow import not_scored_reason
    from canebench.measure.field import extract_field_stiffness
    from canebench.units import GF_TO_N

    rng = np.random.default_rng(4)
    x = np.arange(0.0, 44.0, 0.5)
    contact = np.maximum(x - 3.0, 0.0)  # 6 flat samples, then contact
    # the cane at 5 gf/mm; a second body adds 50 gf/mm from 30 mm of contact on
    f = -50.0 + 5.0 * contact + 50.0 * np.maximum(contact - 30.0, 0.0) + rng.normal(0, 1.0, len(x))
    rig = RigTrial("elbow.csv", x, f, 0.5 * np.arange(len(x)), 700.0)
    ff = extract_field_stiffness(rig, n_boot=50)
    assert not ff.usable and ff.only_poorly_linear, ff.reason
    onsets = field_onsets({"t": SimpleNamespace(fit=ff, reason=ff.reason)})
    assert set(onsets) == {"t"} and abs(onsets["t"] - 30.0) <= 1.0
    before = extract_field_stiffness(rig, window_mm=onsets["t"], n_boot=50)
    assert before.usable and before.k_n_per_mm == pytest.approx(5.0 * GF_TO_N, rel=0.05)
    # a trace that never rises is unusable for another reason, and is not searched
    flat = extract_field_stiffness(RigTrial("flat.csv", x, -50.0 + 0.2 * contact + rng.normal(0, 1.0, len(x)),
                                            0.5 * np.arange(len(x)), 700.0), n_boot=50)
    assert not flat.usable and not flat.only_poorly_linear
    # a trace still no line up to its elbow is not scored, with the field fit's reason
    assert not_scored_reason("n", SimpleNamespace(fit=ff, reason=ff.reason, k=ff.k_n_per_mm), {}, {"n": 0.1}, {}) \
        == f"no field stiffness: {ff.reason}"
    assert not_scored_reason("gone", None, {}, {}, {}) == "no field stiffness: no field fit"


def test_a_pair_member_that_passed_alone_is_not_dropped_with_its_partner():
    """entry_groups records a pair so that drop_unsupported takes a member that failed the step
    alone with its partner, but not one that passed alone (the pair was preferred for its BIC)."""
    from canebench.discovery.selection import entry_groups

    assert entry_groups(("modulus_scale",), set()) == [("modulus_scale",)]
    assert entry_groups(("modulus_scale", "root_compliance"), set()) == [("modulus_scale", "root_compliance")]
    assert entry_groups(("modulus_scale", "root_compliance"), {"base_flare"}) == [("modulus_scale", "root_compliance")]
    assert entry_groups(("modulus_scale", "root_compliance"), {"modulus_scale"}) == [
        ("modulus_scale", "root_compliance"), ("root_compliance",)]
    assert entry_groups(("modulus_scale", "root_compliance"), {"modulus_scale", "root_compliance"}) == [
        ("modulus_scale",), ("root_compliance",)]


def test_only_an_unnamed_flare_may_take_a_trend_along_the_canes():
    """verdict.within_takers: a spring or a scale the selection did not name may not keep the names
    standing by taking the within-cane trend (a trellis tie was taken by a rig spring and kept a
    misnamed scale standing); only an unnamed flare, and not one just refused for its interval."""
    from canebench.discovery.verdict import within_takers

    lib = ("modulus_scale", "root_compliance", "rig_compliance", "base_flare", "probe_misalignment", "obstruction")
    assert within_takers(lib, ("modulus_scale",), []) == ("base_flare",)
    assert within_takers(lib, ("modulus_scale", "base_flare"), []) == ()
    assert within_takers(lib, ("modulus_scale",), [{"effect": "base_flare"}]) == ()


def test_a_trial_left_out_of_the_scoring_says_why_in_the_json():
    """A very stiff cane reaches the rig's 1000 gf stop a few steps after contact (an independent
    generator's canes held by a neighbour: 78 -> 988 gf in four rows). Its trace has too few contact
    samples for a slope, so it has no residual; it must still be listed, with the field fit's reason,
    not vanish from the output. So must a trial the baseline engine failed on."""
    from types import SimpleNamespace

    from canebench.data.rig import RigTrial
    from canebench.discovery.workflow import DiscoveryResult, not_scored_reason
    from canebench.measure.field import MIN_CONTACT_SAMPLES, extract_field_stiffness

    f = _stiff_force()
    x = 0.5 * np.arange(len(f))  # 0.5 mm steps, one every 0.5 s
    ff = extract_field_stiffness(RigTrial("stiff.csv", x, f, x, 560.0), n_boot=20)
    assert not ff.usable and ff.fault == "contact_samples" and ff.n_contact < MIN_CONTACT_SAMPLES, ff.reason
    fr = SimpleNamespace(fit=ff, reason="", k=ff.k_n_per_mm)
    why = not_scored_reason("stiff", fr, {}, {"stiff": 0.2}, {})
    assert why.startswith("no field stiffness: only ") and "contact samples" in why, why
    good = SimpleNamespace(fit=None, reason="", k=0.3)
    assert not_scored_reason("sim", good, {}, {"sim": math.nan}, {"sim": "diverged: |v| > 10 m/s"}) == \
        "no baseline stiffness: diverged: |v| > 10 m/s"
    assert not_scored_reason("sim", good, {}, {"sim": -0.1}, {}) == "no baseline stiffness: the engine gave none"
    # the reason is discovery's one test of a scored trial: empty only for a positive field and baseline
    assert not_scored_reason("ok", good, {}, {"ok": 0.2}, {}) == ""
    trials = pd.DataFrame({"trial": ["a", "stiff", "sim"], "cane": ["c1", "c1", "c1"],
                           "obstruction_onset_mm": [math.nan] * 3, "early_contact_mm": [math.nan] * 3,
                           "r_before": [0.1, math.nan, math.nan], "r_after_cv": [0.05, math.nan, math.nan],
                           "not_scored": ["", why, "no baseline stiffness: diverged: |v| > 10 m/s"]})
    res = DiscoveryResult("beam", [], False, {}, trials, pd.DataFrame(), pd.DataFrame(), pd.DataFrame(),
                          ModelConfig())
    rows = {r["trial"]: r for r in json.loads(json.dumps(res.to_json()))["trials"]}
    assert rows["a"]["scored"] and "not_scored" not in rows["a"]
    assert not rows["stiff"]["scored"] and rows["stiff"]["not_scored"] == why
    assert not rows["sim"]["scored"] and rows["sim"]["not_scored"].startswith("no baseline stiffness")


def _stiff_force(n=20):
    """Load cell readings (gf) of a cane held so stiffly that the rig reaches its 1000 gf stop four
    samples after contact (an independent generator's cane braced by a neighbour): a -27 gf tare
    with 3 gf noise, then 100, 400, 700, 1000 gf above it."""
    f = -27.0 + np.random.default_rng(5).normal(0, 3.0, n)
    f[n - 4:] += 100.0 + 300.0 * np.arange(4)
    return f


def _stiff_rig_csv(path, height_mm):
    """A rig file (the field format) holding :func:`_stiff_force`'s record at 0.5 mm steps."""
    f = _stiff_force()
    n = len(f)
    pd.DataFrame({"Iteration": np.arange(2, n + 2, dtype=float), "Time Stamp": 31907.0 + 500.0 * np.arange(n),
                  "Load Cell Reading (gf)": f.round(2), "Displacement (mm)": 117.0 + 0.5 * np.arange(n),
                  "Height (mm)": height_mm}).to_csv(path, index=False)


def _bundled_with_stiff(dst, stiff):
    """The bundled dataset copied to ``dst``, with the trials in ``stiff`` replaced by
    :func:`_stiff_rig_csv` records (``load_dataset``'s selection takes the bushes wanted)."""
    import shutil

    from canebench.data.dataset import bundled_dataset

    shutil.copytree(bundled_dataset(), dst)
    for r in pd.read_csv(dst / "push_points.csv").itertuples():
        if f"b{r.bush}c{r.cane}t{r.trial}" in stiff:
            _stiff_rig_csv(dst / r.file, r.height_mm)
    return dst


def test_discover_lists_a_trial_it_cannot_score_in_its_json_and_notes(tmp_path):
    """Through discover() itself: a stiff record with four contact samples has no field slope, so the
    trial is left out of the fit; discovery.json lists it with scored false and the field fit's
    reason, the notes count it, and the other 17 are scored."""
    from canebench.data.dataset import load_dataset
    from canebench.discovery.workflow import discover
    from canebench.execute.executors import make_executor

    d = _bundled_with_stiff(tmp_path / "data", {"b1c1t3"})
    res = discover(load_dataset(d, "b1*,b2*"), confirm=False, executor=make_executor("serial", 1, None), n_boot=10,
                   candidates=("modulus_scale",), out=tmp_path / "out")
    rows = {r["trial"]: r for r in json.loads((tmp_path / "out" / "discovery.json").read_text())["trials"]}
    assert len(rows) == 18 and not rows["b1c1t3"]["scored"]
    assert rows["b1c1t3"]["not_scored"] == "no field stiffness: only 4 contact samples (< 5)"
    assert all(r["scored"] and "not_scored" not in r for t, r in rows.items() if t != "b1c1t3")
    assert [n for n in res.notes if "not scored" in n] == [
        "1 of 18 trials not scored: b1c1t3 (no field stiffness: only 4 contact samples (< 5))"]
    assert not np.isfinite(res.trials.set_index("trial").r_before["b1c1t3"])


def test_too_few_scored_trials_stop_discovery_naming_those_left_out(tmp_path):
    """Four of nine trials too stiff for a field slope leave five, under the six discovery needs: the
    error names the field and every trial left out, with why, since no discovery.json follows."""
    from canebench.data.dataset import load_dataset
    from canebench.discovery.workflow import discover
    from canebench.errors import InputError
    from canebench.execute.executors import make_executor

    stiff = {"b1c1t1", "b1c1t2", "b1c2t3", "b1c3t1"}
    d = _bundled_with_stiff(tmp_path / "data", stiff)
    with pytest.raises(InputError) as err:
        discover(load_dataset(d, "b1*"), confirm=False, executor=make_executor("serial", 1, None), n_boot=10,
                 candidates=("modulus_scale",))
    msg = str(err.value)
    assert "only 5 usable trials on 3 canes" in msg and "4 of 9 trials not scored" in msg, msg
    assert all(f"{t} (no field stiffness: only 4 contact samples" in msg for t in stiff), msg


def test_the_cli_labels_an_unscored_obstruction_apart_from_an_early_contact():
    """Both are left out of the fit; only the early contact is one (the CLI had called both so)."""
    from canebench.cli.discover import _excluded_text

    assert _excluded_text({"onset_mm": 30.0, "excluded": True, "reason": "no field stiffness: R^2 0.6"}) == \
        " (not scored)"
    assert _excluded_text({"onset_mm": 12.0, "contact_mm": 3.0, "excluded": True}) == " (early contact)"
    assert _excluded_text({"onset_mm": 30.0}) == ""


def test_a_trial_left_out_is_listed_once_an_obstructed_one_with_its_onset():
    """One note lists every trial left out (an obstructed one with its onset, where the obstruction
    is named); the obstructed ones among them, whatever the reason (a trace still no line up to the
    elbow, or the engine), are the obstruction's excluded values."""
    from canebench.discovery.workflow import not_scored_note

    why = ["", "no field stiffness: R^2 0.62 < 0.8", "no baseline stiffness: diverged", "no field stiffness: x"]
    trials = ["a", "elbow", "sim", "stiff"]
    unscored, note = not_scored_note(trials, why, {"a": 12.0, "elbow": 30.0, "sim": 9.5})
    assert unscored == {"elbow": why[1], "sim": why[2]}
    assert note == ("3 of 4 trials not scored: elbow (obstruction at 30.0 mm; no field stiffness: R^2 0.62 < 0.8); "
                    "sim (obstruction at 9.5 mm; no baseline stiffness: diverged); stiff (no field stiffness: x)")
    assert note.count("elbow") == 1
    # no obstruction named: no onsets in the note, none excluded from it
    assert not_scored_note(trials, why, {}) == ({}, "3 of 4 trials not scored: elbow (no field stiffness: R^2 0.62 "
                                                    "< 0.8); sim (no baseline stiffness: diverged); stiff (no field "
                                                    "stiffness: x)")
    assert not_scored_note(["a"], [""], {"a": 1.0}) == ({}, "")


def test_discover_leaves_out_a_trial_no_model_can_be_built_for_and_goes_on(tmp_path):
    """A cane whose calipers' line reaches the diameter floor below its pushes (calipers near the
    ground of a flared cane) has no model: its three trials are listed as not scored with the
    chain's reason (the file and the calipers), and the other canes are scored as usual; before,
    the screen's geometry raised and ended the run."""
    import shutil

    import yaml

    from canebench.data.dataset import bundled_dataset, load_dataset
    from canebench.discovery.workflow import discover
    from canebench.execute.executors import make_executor

    d = tmp_path / "data"
    shutil.copytree(bundled_dataset(), d)
    doc = yaml.safe_load((d / "canes" / "b1c1.yaml").read_text())
    doc["calipers"] = [{"height": 0.05, "diameter": 0.030}, {"height": 0.20, "diameter": 0.020},
                       {"height": 0.30, "diameter": 0.0135}]
    (d / "canes" / "b1c1.yaml").write_text(yaml.safe_dump(doc))
    res = discover(load_dataset(d, "b1*,b2*"), confirm=False, executor=make_executor("serial", 1, None), n_boot=10,
                   candidates=("modulus_scale",), out=tmp_path / "out")
    rows = {r["trial"]: r for r in json.loads((tmp_path / "out" / "discovery.json").read_text())["trials"]}
    assert len(rows) == 18
    for t in ("b1c1t1", "b1c1t2", "b1c1t3"):
        assert not rows[t]["scored"] and "b1c1.yaml: field 'calipers': their line" in rows[t]["not_scored"], rows[t]
    assert sum(r["scored"] for r in rows.values()) == 15
    assert any(n.startswith("3 of 18 trials not scored: ") for n in res.notes)


def test_a_fit_at_the_end_of_a_physical_range_is_not_named():
    """A modulus five times the stated one (the scale's upper bound), a root or a rig at its softest,
    a pitch of 45 degrees: the effect is pressed against the end of what it can physically be, so it
    takes what it can of something else and is not named (``edge``); the bound on the null's side (a
    spring at its stiffest) and a flare's excess at its 25 mm search bound (excess and length trade
    off: true flares are fitted there) are not such ends."""
    from canebench.discovery.checks_text import failure_reasons
    from canebench.discovery.verdict import at_physical_edge
    from canebench.model.effects import EffectSpec

    def edge(text):
        return [(e["effect"], e["parameter"]) for e in at_physical_edge((EffectSpec.parse(text),))]

    assert edge("modulus_scale(scale=5)") == [("modulus_scale", "scale")]
    assert edge("modulus_scale(scale=0.2)") == [("modulus_scale", "scale")]
    assert edge("modulus_scale(scale=4.98)") == []
    assert edge("root_compliance(k_root=0.3)") == [("root_compliance", "k_root")]
    assert edge("root_compliance(k_root=3000)") == []  # its stiffest: the null's side
    assert edge("rig_compliance(k_rig=20)") == [("rig_compliance", "k_rig")]
    assert edge("rig_compliance(k_rig=100000)") == []
    assert edge("probe_misalignment(angle_deg=-45)") == [("probe_misalignment", "angle_deg")]
    assert edge("base_flare(excess_mm=25, length_mm=20)") == []
    at = at_physical_edge((EffectSpec.parse("modulus_scale(scale=5)"), EffectSpec.parse("root_compliance(k_root=440)")))
    assert failure_reasons({"failed": ["edge"], "at_edge": at, "alpha": 0.002}) == [
        "needs modulus_scale scale = 5 (its physical range 0.2 to 5), at the end of the range: the effect takes what "
        "it can of something it cannot be"]


def test_discover_withholds_a_modulus_scale_pressed_against_its_bound(tmp_path):
    """The bundled canes with their stated modulus written ten times too low: the data ask for a scale
    of 10, beyond the physical range's 5. The scale fitted at 5 is reported as partial, not named,
    and the result is flagged unexplained, with the reason in the notes."""
    import shutil

    import yaml

    from canebench.data.dataset import bundled_dataset, load_dataset
    from canebench.discovery.workflow import discover
    from canebench.execute.executors import make_executor

    d = tmp_path / "data"
    shutil.copytree(bundled_dataset(), d)
    for f in (d / "canes").glob("*.yaml"):
        doc = yaml.safe_load(f.read_text())
        doc.setdefault("material", {})["flexural_modulus"] = 4.57e8
        f.write_text(yaml.safe_dump(doc))
    res = discover(load_dataset(d, "b1*,b2*"), confirm=False, executor=make_executor("serial", 1, None), n_boot=10,
                   candidates=("modulus_scale",))
    assert res.named == [] and res.unexplained
    (p,) = res.partial
    assert p["effect"] == "modulus_scale" and p["params"]["scale"] == pytest.approx(5.0, rel=1e-6)
    assert res.adequacy["failed"][0] == "edge"
    assert any("needs modulus_scale scale = 5 (its physical range 0.2 to 5)" in n for n in res.notes)
