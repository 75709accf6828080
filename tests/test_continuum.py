"""The continuum engines (MuJoCo's 1D elastic flex, Exudyn's geometrically
exact beam) against closed forms, the beam reference and each other.

Every expected value below comes from /work/shared/reference-values.md (the
closed forms, cited by section) or from the beam reference; the tolerances
are the measured discretization errors of ``canebench converge`` (README
"Continuum engines") with the margin stated at each assertion. All probes are
the harness's own (``run_probe``, fast protocol), a few 0.5 mm samples with
gravity off unless said otherwise.
"""

import dataclasses

import mujoco
import numpy as np
import pandas as pd
import pytest

from canebench.backends import mujoco_rod_backend as mr
from canebench.backends.beam_backend import BeamBackend
from canebench.backends.exudyn_beam_backend import ExudynBeamBackend
from canebench.backends.mujoco_rod_backend import FlexLayoutError, MujocoRodBackend
from canebench.data.cane import cane_from_dict
from canebench.model.chain import build_chain
from canebench.model.config import ModelConfig
from canebench.probe.driver import run_probe
from canebench.probe.protocol import PROTOCOLS
from canebench.registry import discover
from canebench.studies.agreement import TOL_REFERENCE, agreement_table, check
from canebench.studies.convergence import cantilever_stiffness, continuum_convergence, straight_cantilever

FAST = PROTOCOLS["fast"]
E, L, D0, D1, NU = 4.57e9, 1.2, 0.012, 0.006, 0.3


def k_probe(backend, chain, steps=4):
    tr = run_probe(backend, chain, FAST, steps)
    assert tr.status == "ok", tr.reason
    return tr.fit().slope  # N/m


@pytest.fixture(scope="module")
def uniform():
    return build_chain(straight_cantilever(False), "tip", ModelConfig(gravity=0.0))


@pytest.fixture(scope="module")
def tapered():
    return build_chain(straight_cantilever(True), "tip", ModelConfig(gravity=0.0))


def quarter_circle(azimuth, R=0.5, d=0.012):
    """Quarter-circle cantilever (reference-values sec. 3): vertical at the clamp, horizontal at the tip."""
    phi = np.linspace(0, np.pi / 2, 401)
    pts = np.column_stack([R - R * np.cos(phi), 0 * phi, R * np.sin(phi)])
    cane = cane_from_dict({
        "id": "quarter-circle", "polyline": {"raw": False, "points": pts.tolist()},
        "calipers": [{"s": 0.0, "diameter": d}, {"s": float(np.pi / 2 * R * 0.999), "diameter": d}],
        "push_points": [{"id": "tip", "s": float(np.pi / 2 * R * (1 - 1e-6)), "direction": list(azimuth)}],
        "material": {"flexural_modulus": E}, "provenance": {"synthetic": True, "notes": "closed-form case"},
    }, "<quarter circle>")
    return build_chain(cane, "tip", ModelConfig(gravity=0.0))


# ---------------------------------------------------------------- MuJoCo rod


@pytest.mark.parametrize("n", [10, 20])
def test_mujoco_rod_uniform_cantilever_is_the_voronoi_chain(uniform, n):
    """The discrete elastic rod stores EI/(l0+l1) |kappa b|^2 per vertex: a chain
    with springs EI/(dual length) at its nodes, whose tip compliance is
    1 + 1/(2n^2) of the beam's (sec. 5, Voronoi placement) once the clamp is a
    stub below the base. Measured within 7e-5 of it; 2e-4 allows the stub (1 %
    of an element) and the dynamic probe."""
    ratio = k_probe(MujocoRodBackend(n), uniform) / cantilever_stiffness(False)
    assert ratio == pytest.approx(1 / (1 + 1 / (2 * n**2)), abs=2e-4)


def test_mujoco_rod_clamped_on_its_first_element_is_the_start_spring_chain(uniform):
    """MuJoCo's plain clamp (``<pin id="0 1"/>`` on the cane's first two
    points) fixes the whole first element: the rod is then a chain of n-1 links
    of length L/n clamped at the second vertex, compliance (n-1)(2n-1)/(2n^2)
    of the beam's (sec. 5, start springs with c = 1, on n-1 links). Measured
    within 1e-4 of it (17 % stiff at 10 elements, first order): why the
    backend clamps a stub instead."""
    n = 10
    ratio = k_probe(MujocoRodBackend(n, clamp="first-edge"), uniform) / cantilever_stiffness(False)
    assert ratio == pytest.approx(2 * n**2 / ((n - 1) * (2 * n - 1)), abs=2e-4)


def test_mujoco_rod_tapered_cantilever_converges_at_second_order(tapered):
    """Per-vertex stiffness of the tapered section against the closed form
    64PL^3/(3 pi E d0^3 d1) (sec. 1): measured -6.9e-3 at 10 elements and
    -1.7e-3 at 20 (ratio 4.0)."""
    e10 = k_probe(MujocoRodBackend(10), tapered) / cantilever_stiffness(True) - 1
    e20 = k_probe(MujocoRodBackend(20), tapered) / cantilever_stiffness(True) - 1
    assert abs(e20) < 2.5e-3
    assert 3.0 < e10 / e20 < 5.0


def test_mujoco_rod_one_documented_radius_checks_the_circle_section_and_misses_the_taper(tapered):
    """With ``taper="uniform"`` MuJoCo computes EI from its documented circle
    section, I = pi r^4 / 4, for the one flex radius (the diameter at the middle
    of the probed span, 0.75 d0 here): the tapered cantilever then answers as a
    uniform one of that diameter, k = 3 E I(0.75 d0) / L^3 = 0.75^4 / (d1/d0)
    of the tapered closed form (sec. 1), i.e. 37 % soft; with 20 elements the
    compliance is 1 + 1/(2n^2) (Voronoi chain, sec. 5) plus the stub's: with
    documented stiffnesses only, the base vertex's spring is 2EI/(h + stub), which
    adds 1.5 stub/h / n (the base spring's share of the tip compliance is
    3/(2n)). Measured within 1e-5 (a wrong area moment, e.g. pi r^4 / 2, would
    be off by 2x)."""
    n = 20
    ratio = k_probe(MujocoRodBackend(n, taper="uniform"), tapered) / cantilever_stiffness(True)
    assert ratio == pytest.approx(0.75**4 / (D1 / D0) / (1 + 1 / (2 * n**2) + 1.5 * mr.STUB / n), rel=2e-4)


def test_mujoco_rod_quarter_circle_out_of_plane_bends_and_twists():
    """Out-of-plane tip load on a quarter circle: F R^3 [pi/(4EI) + (3pi/4-2)/GJ],
    GJ = EI/(1+nu) (sec. 3): the rod's rest curvature and its twist joints carry
    torsion. Measured +1.9e-3 at 20 elements (+5.7e-4 at 40)."""
    chain = quarter_circle([0, 1, 0])
    EI = E * np.pi * 0.012**4 / 64
    k_closed = 1 / (0.5**3 * (np.pi / (4 * EI) + (3 * np.pi / 4 - 2) * (1 + NU) / EI))
    assert k_probe(MujocoRodBackend(20), chain) / k_closed - 1 == pytest.approx(0, abs=4e-3)


def test_mujoco_rod_bundled_cane_against_the_beam(bundled_trials):
    """A bundled cane with gravity, 10 samples (5 mm): within the agreement
    tolerance of the beam (0.31 %; measured -0.13 % here, worst small-push
    error over the 54 canes 0.18 % at 40 elements)."""
    t = next(t for t in bundled_trials if t.id == "b1c1t1")
    chain = build_chain(t.cane, t.push_id, ModelConfig())
    k, kb = k_probe(MujocoRodBackend(), chain, 10), k_probe(BeamBackend(), chain, 10)
    assert abs(k / kb - 1) < TOL_REFERENCE["mujoco_rod"]


def test_mujoco_rod_probe_actuator_is_the_chain_backends_pid():
    """The MjSpec-built PID (ctrlspec 1) compiles to exactly the chain backend's MJCF ``<pid input="pos"/>``."""
    xml = ('<mujoco><worldbody><site name="r"/><body><joint type="slide"/><geom size=".1"/><site name="p"/></body>'
           '</worldbody><actuator><pid name="probe" site="p" refsite="r" gear="1 0 0 0 0 0" kp="750" ki="100" '
           'kv="20" input="pos"/></actuator></mujoco>')
    ref = mujoco.MjModel.from_xml_string(xml)
    spec = mujoco.MjSpec.from_string(xml.split("<actuator>")[0] + "</mujoco>")
    a = spec.add_actuator(name="probe", target="p", refsite="r", trntype=mujoco.mjtTrn.mjTRN_SITE,
                          gear=[1, 0, 0, 0, 0, 0])
    a.set_to_pid(kp=750, ki=100, kv=20, ctrlspec=1)
    m = spec.compile()
    for f in ("actuator_gainprm", "actuator_biasprm", "actuator_dynprm", "actuator_dyntype", "actuator_gaintype",
              "actuator_biastype", "actuator_actnum", "actuator_ctrlspec"):
        assert np.array_equal(getattr(m, f), getattr(ref, f)), f


def test_mujoco_rod_refuses_a_flex_layout_it_does_not_know(uniform):
    """The per-vertex taper writes into mjModel.flex_bending only after finding
    MuJoCo's documented stiffness there; anything else fails the build."""
    spec, info = mr.build_spec(uniform, 1e-3, True, (750, 100, 20), 10)
    m = spec.compile()
    mr.set_vertex_stiffness(m, uniform, info)  # the layout it knows
    m2 = spec.compile()
    adr = int(m2.flex_bendingadr[0])
    m2.flex_bending[adr + 1 + mr._KB] *= 1.5  # a record that is not EI/(l0+l1) of the compiled radius
    with pytest.raises(FlexLayoutError, match="flex_bending"):
        mr.set_vertex_stiffness(m2, uniform, info)


def test_mujoco_rod_failing_cases(uniform, bundled_trials):
    # a chain without its continuum: the build fails the trial with the reason
    tr = run_probe(MujocoRodBackend(10), dataclasses.replace(uniform, rod=None), FAST, 3)
    assert tr.status == "failed" and "no rod geometry" in tr.reason
    # the probe on the clamped first element (first-edge clamp, 2 elements: probe at the second vertex)
    short = dataclasses.replace(uniform, meta={**uniform.meta, "s_push": 0.3})
    tr = run_probe(MujocoRodBackend(2, clamp="first-edge"), short, FAST, 3)
    assert tr.status == "failed" and "clamped edge" in tr.reason
    with pytest.raises(ValueError, match="taper"):
        MujocoRodBackend(10, taper="conical")
    with pytest.raises(ValueError, match="clamp"):
        MujocoRodBackend(10, clamp="hinged")
    tr = run_probe(MujocoRodBackend(1), uniform, FAST, 3)
    assert tr.status == "failed" and "at least 2 elements" in tr.reason
    # a modulus 10^4 too high: the harness fails the trial instead of reporting a stiffness
    t = next(t for t in bundled_trials if t.id == "b1c1t1")
    stiff = build_chain(t.cane, t.push_id, ModelConfig(modulus_pa=1e14))
    tr = run_probe(MujocoRodBackend(10), stiff, FAST, 12)
    assert tr.status == "failed" and ("too stiff" in tr.reason or "covered" in tr.reason)


# ---------------------------------------------------------------- Exudyn beam


def test_exudyn_beam_cantilevers_converge_at_second_order(uniform, tapered):
    """Two-node geometrically exact elements with one-point integration: tip
    compliance (1 - 1/(4n^2)) of the beam's on the uniform cantilever (measured
    +2.46e-3 at 10 elements, +5.8e-4 at 20: ratio 4.2); the tapered one is
    within 6e-5 at 20 (sec. 1). Bounds: |e20| < 1e-3 and < 5e-4, order 2."""
    e10 = k_probe(ExudynBeamBackend(10), uniform) / cantilever_stiffness(False) - 1
    e20 = k_probe(ExudynBeamBackend(20), uniform) / cantilever_stiffness(False) - 1
    assert 0 < e20 < 1e-3 and 3.5 < e10 / e20 < 5.0
    assert abs(k_probe(ExudynBeamBackend(20), tapered) / cantilever_stiffness(True) - 1) < 5e-4


def test_exudyn_beam_quarter_circle_out_of_plane_bends_and_twists():
    """sec. 3 as for the MuJoCo rod: measured +1.65e-3 at 20 elements (+3.4e-4 at 40)."""
    chain = quarter_circle([0, 1, 0])
    EI = E * np.pi * 0.012**4 / 64
    k_closed = 1 / (0.5**3 * (np.pi / (4 * EI) + (3 * np.pi / 4 - 2) * (1 + NU) / EI))
    assert k_probe(ExudynBeamBackend(20), chain) / k_closed - 1 == pytest.approx(0, abs=4e-3)


def test_exudyn_beam_bundled_cane_against_the_beam(bundled_trials):
    """With gravity, 10 samples: within the agreement tolerance (0.22 %; measured
    -0.06 % here, worst small-push difference over the 54 canes 0.097 % at 20
    elements: the Timoshenko section's shear and extension, which the Kirchhoff
    beam does not have)."""
    t = next(t for t in bundled_trials if t.id == "b1c1t1")
    chain = build_chain(t.cane, t.push_id, ModelConfig())
    k, kb = k_probe(ExudynBeamBackend(), chain, 10), k_probe(BeamBackend(), chain, 10)
    assert abs(k / kb - 1) < TOL_REFERENCE["exudyn_beam"]


def test_exudyn_beam_element_ignores_its_section_damping_matrix():
    """Why the exudyn_beam backend damps through connectors: Exudyn 1.13's
    ObjectBeamGeometricallyExact accepts BeamSection.dampingMatrix without
    error (the BeamSection documentation says elements reject parameters they
    do not use) and ignores it: the free vibration is the same to rounding with
    no damping and with damping = 1 s x stiffness, while relative rotational
    dampers change it. If this fails, Exudyn now honours the matrix and the
    backend could use it instead."""
    from canebench.reports.continuum_engine_findings import exudyn_free_vibration

    undamped = exudyn_free_vibration(0.0, 0.0)
    section = exudyn_free_vibration(1.0, 0.0)
    connectors = exudyn_free_vibration(0.0, 0.01)
    amplitude = np.ptp(undamped)
    assert amplitude > 0
    assert np.max(np.abs(section - undamped)) < 1e-9 * amplitude
    assert np.max(np.abs(connectors - undamped)) > 0.05 * amplitude


# ---------------------------------------------------------------- harness integration


def test_continuum_backends_are_registered_with_their_tags():
    reg = discover()
    for name in ("mujoco_rod", "exudyn_beam"):
        assert reg[name].available, reg[name].reason
        assert "continuum" in reg[name].tags and reg[name].kind == "dynamic"


def test_agreement_checks_continuum_engines_against_the_beam():
    res = pd.DataFrame([
        {"trial": "t1", "backend": "pinocchio", "k_sim": 0.100, "status": "ok", "reason": ""},
        {"trial": "t1", "backend": "mujoco", "k_sim": 0.1003, "status": "ok", "reason": ""},
        {"trial": "t1", "backend": "beam", "k_sim": 0.120, "status": "ok", "reason": ""},
        {"trial": "t1", "backend": "mujoco_rod", "k_sim": 0.1198, "status": "ok", "reason": ""},
        {"trial": "t1", "backend": "exudyn_beam", "k_sim": 0.1210, "status": "ok", "reason": ""},
    ])
    table = agreement_table(res).set_index("backend")
    assert table.loc["mujoco", "reference"] == "pinocchio" and table.loc["mujoco_rod", "reference"] == "beam"
    assert table.loc["mujoco_rod", "rel_to_ref"] == pytest.approx(0.1198 / 0.120 - 1)
    v = check(table.reset_index(), None).violations
    # mujoco_rod is 0.17 % from the beam (within 0.31 %), exudyn_beam 0.83 % (beyond 0.22 %); the beam is 20 %
    # from Pinocchio's chain but is a reference, not an engine of the chain
    assert list(v.backend) == ["exudyn_beam"] and v.check.iloc[0] == "vs beam"


def test_convergence_study_rows_on_the_uniform_cantilever(tmp_path):
    from canebench.reports.convergence import continuum_section, continuum_summary

    df = continuum_convergence([("uniform-cantilever", straight_cantilever(False), "tip")], elements=(5, 10))
    assert (df.status == "ok").all()
    rod = df[(df.backend == "mujoco_rod") & (df.variant == "per-vertex")].set_index("elements")
    # second order, and the closed form of the Voronoi chain (sec. 5)
    assert rod.rel_error_closed[5] / rod.rel_error_closed[10] == pytest.approx(4, rel=0.1)
    assert df[df.backend == "mujoco"].wall_ratio.iloc[0] == 1.0
    summ = continuum_summary(df)
    assert set(summ.backend) == {"mujoco_rod", "exudyn_beam", "mujoco"}
    df.to_csv(tmp_path / "continuum_convergence.csv", index=False)
    html = continuum_section(tmp_path)
    assert "Continuum engines" in html and (tmp_path / "continuum_convergence.png").exists()
    assert continuum_section(tmp_path / "nowhere") == ""


def test_converge_cli_refuses_bad_element_counts(tmp_path, capsys):
    from canebench.cli import main

    assert main(["converge", "--continuum", "--continuum-elements", "10,forty", "--out", str(tmp_path / "a")]) == 2
    assert main(["converge", "--continuum", "--continuum-elements", "1,10", "--out", str(tmp_path / "b")]) == 2
    assert "continuum_elements" in capsys.readouterr().err
