"""``canebench export``: every exported file, loaded by its own consumer, gives the chain's stiffness.

References are computed from the chain the harness builds (Pinocchio's frame
Jacobian of ``chain_to_pinocchio`` at rest), never from the exported files;
the exported files are read by MuJoCo (MJCF), PyBullet (URDF + sidecar) and a
plain XML parser doing its own kinematics (SDF).
"""

from __future__ import annotations

import dataclasses
import filecmp
import json
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.spatial.transform import Rotation

from canebench import __version__
from canebench.cli import main
from canebench.data.cane import Caliper
from canebench.data.dataset import bundled_dataset, load_dataset
from canebench.model.chain import Chain, build_chain
from canebench.model.config import ModelConfig
from canebench.model.distributions import MODULUS_DISTRIBUTIONS
from canebench.model.presets import PRESETS

RTOL = 1e-3

MODEL_FILE = """\
canebench_model: 1
preset: beam-consistent
config: {segments: 8}
effects:
  - {effect: root_compliance, params: {k_root: 40.0}}
  - {effect: base_flare, params: {excess_mm: 3.0, length_mm: 120.0}}
  - {effect: probe_misalignment, params: {angle_deg: 10.0}}
"""


# ------------------------------------------------------------------ references and readers


def pinocchio_k(chain: Chain) -> float:
    """Small-deflection probe stiffness (N/m) from Pinocchio's own frame Jacobian at rest."""
    pin = pytest.importorskip("pinocchio")
    from canebench.backends.pinocchio_backend import chain_to_pinocchio

    model, fid = chain_to_pinocchio(chain)
    data = model.createData()
    q0 = pin.neutral(model)
    J = pin.computeFrameJacobian(model, data, q0, fid, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)[:3]
    g = np.asarray(chain.direction) @ J
    return float(1.0 / np.sum(g**2 / chain.joint_stiffness_vector()))


def mujoco_k(path: Path, force: float = 1e-3) -> float:
    """Probe stiffness of an MJCF file by MuJoCo statics: push +-force with the file's
    ``probe`` actuator, gravity off, and find the equilibrium from MuJoCo's own spring
    and actuator forces (q <- q + K^-1 (qfrc_passive + qfrc_actuator))."""
    import mujoco

    m = mujoco.MjModel.from_xml_path(str(path))
    m.opt.gravity[:] = 0.0
    d = mujoco.MjData(m)
    act = m.actuator("probe").id
    K = m.jnt_stiffness[m.dof_jntid]
    assert np.all(K > 0) and np.all(m.qpos_spring == 0)

    def displacement(F: float) -> float:
        d.qpos[:] = m.qpos0
        d.qvel[:] = 0.0
        d.ctrl[act] = F
        for _ in range(100):
            mujoco.mj_forward(m, d)
            r = d.qfrc_passive + d.qfrc_actuator
            if np.max(np.abs(r)) < 1e-14 * max(1.0, np.max(np.abs(d.qfrc_actuator))):
                break
            d.qpos[:] += r / K
        else:
            raise AssertionError("MuJoCo statics did not converge")
        return float(d.actuator_length[act])

    return 2.0 * force / (displacement(force) - displacement(-force))


def pybullet_k(urdf: Path, sidecar: dict) -> tuple[float, np.ndarray, dict]:
    """Probe stiffness of a URDF + sidecar in PyBullet: 1 / sum((u . J_i)^2 / K_i) with J from
    calculateJacobian at the 'probe' link and K from the sidecar; also the probe's world position
    and the PyBullet masses of the cane links."""
    p = pytest.importorskip("pybullet")
    from pybullet_utils import bullet_client

    c = bullet_client.BulletClient(connection_mode=p.DIRECT)
    try:
        body = c.loadURDF(str(urdf), useFixedBase=True, flags=p.URDF_USE_INERTIA_FROM_FILE)
        info = [c.getJointInfo(body, i) for i in range(c.getNumJoints(body))]
        movable = [i for i, ji in enumerate(info) if ji[2] != p.JOINT_FIXED]
        names = [info[i][1].decode() for i in movable]
        assert set(names) == set(sidecar["joints"])
        K = np.array([sidecar["joints"][n]["stiffness"] for n in names])
        assert all(sidecar["joints"][n]["rest_angle"] == 0.0 for n in names)
        probe = next(i for i, ji in enumerate(info) if ji[12].decode() == "probe")
        zeros = [0.0] * len(movable)
        lin, _ = c.calculateJacobian(body, probe, [0.0, 0.0, 0.0], zeros, zeros, zeros)
        st = c.getLinkState(body, probe, computeForwardKinematics=1)
        u = np.array(c.getMatrixFromQuaternion(st[5])).reshape(3, 3)[:, 0]
        g = u @ np.array(lin)
        masses = {ji[12].decode(): c.getDynamicsInfo(body, i)[0] for i, ji in enumerate(info)}
        return float(1.0 / np.sum(g**2 / K)), np.array(st[4]), masses
    finally:
        c.disconnect()


def sdf_k(path: Path) -> tuple[float, ET.Element]:
    """Probe stiffness from an SDF file's own poses, axes and springs (world-posed links,
    joints at their child's origin, axes in the child frame, frame 'probe' on its link)."""
    root = ET.parse(path).getroot()
    assert root.tag == "sdf" and root.get("version") == "1.7"
    model = root.find("model")

    def pose(e: ET.Element) -> tuple[np.ndarray, np.ndarray]:
        v = np.array(e.find("pose").text.split(), float)
        return v[:3], Rotation.from_euler("xyz", v[3:]).as_matrix()

    links = {ln.get("name"): pose(ln) for ln in model.findall("link")}
    joints = {}
    for jt in model.findall("joint"):
        assert jt.get("type") == "revolute"
        assert np.allclose(np.array(jt.find("pose").text.split(), float), 0.0)
        child, parent = jt.find("child").text, jt.find("parent").text
        assert child in links and (parent in links or parent == "world")
        dyn = jt.find("axis/dynamics")
        assert float(dyn.find("spring_reference").text) == 0.0
        joints[child] = (parent, np.array(jt.find("axis/xyz").text.split(), float),
                         float(dyn.find("spring_stiffness").text))
    fr = model.find("frame[@name='probe']")
    host = fr.get("attached_to")
    assert fr.find("pose").get("relative_to") == host
    pl, Rl = pose(fr)
    p0, R0 = links[host]
    point, u = p0 + R0 @ pl, R0 @ Rl[:, 0]
    comp, at = 0.0, host
    while at != "world":  # joints from the probe's link down to the clamp move the probe
        parent, axis, k = joints[at]
        o, R = links[at]
        comp += ((np.cross(R @ axis, point - o)) @ u) ** 2 / k
        at = parent
    return 1.0 / comp, model


# ------------------------------------------------------------------ fixtures


@pytest.fixture(scope="module")
def data():
    return load_dataset(bundled_dataset())


@pytest.fixture(scope="module")
def exported(tmp_path_factory, data):
    """Exports through the CLI under several model configurations; (folder, config, argv) each."""
    root = tmp_path_factory.mktemp("export")
    mf = root / "model.yaml"
    mf.write_text(MODEL_FILE)
    from canebench.model.modelfile import load_model_file

    cases = [
        (["--canes", "b1c*,b4c2"], PRESETS["default"]),
        (["--trials", "b2c3t2,b5c1t3", "--preset", "beam-consistent", "--set", "twist_joint=true"],
         PRESETS["beam-consistent"].replace(twist_joint=True)),
        (["--canes", "b6c1", "--push", "3", "--segments", "12", "--stiffness-formula", "end_angle",
          "--modulus", "3.1e9"], ModelConfig(segments=12, stiffness_formula="end_angle", modulus_pa=3.1e9)),
        (["--canes", "b3c3", "--model", str(mf)], load_model_file(mf)),
    ]
    out = []
    for i, (argv, cfg) in enumerate(cases):
        d = root / f"case{i}"
        assert main(["export", *argv, "--out", str(d)]) == 0
        out.append((d, cfg, argv))
    return out


def _chain_of(row: pd.Series, cfg: ModelConfig, data) -> Chain:
    cane = next(t.cane for t in data if t.cane.id == row.cane)
    return build_chain(cane, str(row.push_point), cfg)


# ------------------------------------------------------------------ round trips


def test_every_exported_model_gives_the_chains_stiffness(exported, data):
    from canebench.export.urdf import load_sidecar

    n = 0
    for d, cfg, argv in exported:
        man = pd.read_csv(d / "manifest.csv", dtype={"push_point": str})
        assert len(man) > 0
        for row in man.itertuples():
            chain = _chain_of(pd.Series(row._asdict()), cfg, data)
            assert row.chain_fingerprint == chain.fingerprint() and row.n_joints == chain.n_dof
            k_ref = pinocchio_k(chain)
            # MJCF in MuJoCo
            k_mj = mujoco_k(d / row.file_mjcf)
            assert abs(k_mj / k_ref - 1) < RTOL, (argv, row.name, k_mj, k_ref)
            # URDF + sidecar in PyBullet
            side = load_sidecar(d / row.file_springs)
            k_pb, probe_pos, masses = pybullet_k(d / row.file_urdf, side)
            assert abs(k_pb / k_ref - 1) < RTOL, (argv, row.name, k_pb, k_ref)
            assert np.allclose(probe_pos, chain.push_point, atol=1e-6)
            cane_mass = sum(masses[f"link{j}"] for j in range(chain.n_links))
            assert cane_mass == pytest.approx(chain.masses.sum(), rel=1e-12)
            # SDF by its own kinematics
            k_sdf, _ = sdf_k(d / row.file_sdf)
            assert abs(k_sdf / k_ref - 1) < RTOL, (argv, row.name, k_sdf, k_ref)
            assert row.k_linear_N_per_mm == pytest.approx(k_ref * 1e-3, rel=1e-9)
            n += 1
    assert n == 4 + 2 + 1 + 1


def test_the_model_file_and_options_reach_the_exported_physics(exported, data):
    """--model's effects and the shorthands change the exported stiffness (not ignored)."""
    d_opts, (d_model, cfg_model, _) = exported[2][0], exported[3]
    for d in (d_opts, d_model):
        row = pd.read_csv(d / "manifest.csv", dtype={"push_point": str}).iloc[0]
        plain = build_chain(next(t.cane for t in data if t.cane.id == row.cane), str(row.push_point), ModelConfig())
        assert abs(mujoco_k(d / row.file_mjcf) / pinocchio_k(plain) - 1) > 0.05
    assert len(cfg_model.effects) == 3
    side = json.loads((d_model / "manifest.json").read_text())
    assert [e for e in side["config"]["effects"]], "the model file's effects are recorded"


def test_mjcf_file_is_the_backends_model_exactly(exported, data, tmp_path):
    """The MJCF written at full precision reloads to the model the MuJoCo backend compiles
    (same builder), apart from the probe actuator and collision bits."""
    import mujoco

    from canebench.backends.mujoco_backend import MujocoBackend
    from canebench.probe.protocol import PROTOCOLS

    d, cfg, _ = exported[1]  # twist joints
    row = pd.read_csv(d / "manifest.csv", dtype={"push_point": str}).iloc[0]
    chain = _chain_of(row, cfg, data)
    sim = MujocoBackend().build(chain, PROTOCOLS["fast"])
    m_file = mujoco.MjModel.from_xml_path(str(d / row.file_mjcf))
    for f in ("body_pos", "body_quat", "body_mass", "body_inertia", "body_ipos", "jnt_axis", "jnt_stiffness",
              "dof_damping", "site_pos", "site_quat", "geom_size", "opt.timestep"):
        a, b = (getattr(m.opt, f[4:]) if f.startswith("opt.") else getattr(m, f) for m in (sim.m, m_file))
        np.testing.assert_array_equal(a, b, err_msg=f)
    assert m_file.opt.integrator == mujoco.mjtIntegrator.mjINT_DISCRETE
    i = mujoco.mj_name2id(m_file, mujoco.mjtObj.mjOBJ_TEXT, "canebench")
    meta = bytes(m_file.text_data[m_file.text_adr[i]:m_file.text_adr[i] + m_file.text_size[i] - 1]).decode()
    assert json.loads(meta)["chain_fingerprint"] == chain.fingerprint()


def test_sdf_structure_and_values(exported, data):
    d, cfg, _ = exported[1]  # twist joints: three joints and two intermediate links per cane link
    row = pd.read_csv(d / "manifest.csv", dtype={"push_point": str}).iloc[0]
    chain = _chain_of(row, cfg, data)
    _, model = sdf_k(d / row.file_sdf)
    assert model.get("name") == row["name"]
    joints = model.findall("joint")
    assert [j.get("name") for j in joints] == [f"j{i}{a}" for i in range(chain.n_links) for a in "xyz"]
    assert joints[0].find("parent").text == "world"
    K = np.array([float(j.find("axis/dynamics/spring_stiffness").text) for j in joints])
    np.testing.assert_array_equal(K, chain.joint_stiffness_vector())
    assert all(float(j.find("axis/dynamics/damping").text) == chain.damping for j in joints)
    for i in range(chain.n_links):
        ln = model.find(f"link[@name='link{i}']")
        assert float(ln.find("inertial/mass").text) == chain.masses[i]
        assert [float(ln.find(f"inertial/inertia/{t}").text) for t in ("ixx", "iyy", "izz")] == list(chain.inertias[i])
        for kind in ("visual", "collision"):
            cyl = ln.find(f"{kind}/geometry/cylinder")
            assert float(cyl.find("radius").text) == chain.diameters[i] / 2
            assert float(cyl.find("length").text) == chain.lengths[i]
        pos = np.array(ln.find("pose").text.split(), float)
        np.testing.assert_allclose(pos[:3], chain.nodes[i], atol=1e-15)
        np.testing.assert_allclose(Rotation.from_euler("xyz", pos[3:]).as_matrix(), chain.frames[i], atol=1e-12)
        dummy = float(model.find(f"link[@name='link{i}_x']/inertial/mass").text)
        assert 0 < dummy <= 1e-3 * chain.masses[i]


def test_urdf_sidecar_content_and_note(exported, data):
    from canebench.export.urdf import load_sidecar

    d, cfg, _ = exported[0]
    row = pd.read_csv(d / "manifest.csv", dtype={"push_point": str}).iloc[0]
    chain = _chain_of(row, cfg, data)
    text = (d / row.file_springs).read_text()
    for word in ("PyBullet", "TORQUE_CONTROL", "Isaac Lab", "ImplicitActuatorCfg", "Gazebo"):
        assert word in text.split("\nformat:")[0], word  # in the header comment
    side = load_sidecar(d / row.file_springs)
    assert side["urdf"] == Path(row.file_urdf).name
    assert [side["joints"][f"j{i}{a}"]["stiffness"] for i in range(chain.n_links) for a in "xy"] == \
        list(chain.joint_stiffness_vector())
    assert side["canebench"]["chain_fingerprint"] == chain.fingerprint()
    urdf = ET.parse(d / row.file_urdf).getroot()
    springs = {g.get("reference"): float(g.find("springStiffness").text) for g in urdf.findall("gazebo")
               if g.find("springStiffness") is not None}
    assert springs == {n: v["stiffness"] for n, v in side["joints"].items()}
    damp = {j.get("name"): float(j.find("dynamics").get("damping")) for j in urdf.findall("joint[@type='continuous']")}
    assert damp == {n: v["damping"] for n, v in side["joints"].items()}
    with pytest.raises(ValueError, match="not a canebench-joint-springs"):
        load_sidecar(d / row.file_urdf)


# ------------------------------------------------------------------ populations


def test_population_round_trip_and_manifest(tmp_path, data):
    out = tmp_path / "pop"
    assert main(["export", "--population", "7", "--seed", "11", "--distribution", "fruiting-duke",
                 "--canes", "b2*,b5c3", "--format", "mjcf,urdf", "--out", str(out)]) == 0
    man = pd.read_csv(out / "manifest.csv", dtype={"push_point": str})
    head = json.loads((out / "manifest.json").read_text())
    assert len(man) == 7 and list(man.draw) == list(range(7))
    assert set(man.seed) == {11} and set(man.distribution) == {"fruiting-duke"}
    assert set(man.canebench_version) == {__version__} and head["canebench_version"] == __version__
    assert head["seed"] == 11 and head["population"] == 7 and head["distribution"]["name"] == "fruiting-duke"
    assert "caliper" in head["what_is_drawn"] and "modulus" in head["what_is_drawn"]
    assert list(man.cane) == ["b2c1", "b2c2", "b2c3", "b5c3", "b2c1", "b2c2", "b2c3"]  # round robin
    dist = MODULUS_DISTRIBUTIONS["fruiting-duke"]
    assert man.modulus_pa.between(dist.lower_pa, dist.upper_pa).all() and man.modulus_pa.nunique() == 7
    assert not (out / "sdf").exists()
    canes = {t.cane.id: t.cane for t in data}
    for row in man.itertuples():
        # the manifest alone rebuilds the exported chain: the cane, its caliper scales, the modulus
        base = canes[row.cane]
        scales = [float(s) for s in row.caliper_scales.split(";")]
        drawn = dataclasses.replace(base, calipers=tuple(Caliper(c.where, c.diameter * s)
                                                         for c, s in zip(base.calipers, scales)))
        chain = build_chain(drawn, row.push_point, ModelConfig(modulus_pa=row.modulus_pa))
        assert chain.fingerprint() == row.chain_fingerprint
        assert row.diameter_scale_mean == pytest.approx(
            sum(c.diameter for c in drawn.calipers) / sum(c.diameter for c in base.calipers), rel=1e-12)
        k_ref = pinocchio_k(chain)
        assert abs(mujoco_k(out / row.file_mjcf) / k_ref - 1) < RTOL
        from canebench.export.urdf import load_sidecar

        assert abs(pybullet_k(out / row.file_urdf, load_sidecar(out / row.file_springs))[0] / k_ref - 1) < RTOL


def test_population_is_deterministic_for_a_seed(tmp_path, data):
    from canebench.export.bundle import export_population, select

    sel = select(data, by_trial=False)
    a = export_population(sel, ModelConfig(), tmp_path / "a", 6, seed=3)
    b = export_population(sel, ModelConfig(), tmp_path / "b", 6, seed=3)
    files = sorted(p.relative_to(tmp_path / "a") for p in (tmp_path / "a").rglob("*") if p.is_file())
    assert len(files) == 6 * 4 + 2
    _, mismatch, errors = filecmp.cmpfiles(tmp_path / "a", tmp_path / "b", [str(f) for f in files], shallow=False)
    assert not mismatch and not errors
    c = export_population(sel, ModelConfig(), tmp_path / "c", 3, seed=3)  # a draw does not depend on N
    pd.testing.assert_frame_equal(c.manifest, a.manifest.iloc[:3])
    d = export_population(sel, ModelConfig(), tmp_path / "d", 6, seed=4)
    assert not np.array_equal(d.manifest.modulus_pa, a.manifest.modulus_pa)
    assert a.manifest.equals(b.manifest)


def test_what_is_drawn_has_the_documented_distribution(data):
    """Moments of many draws: E has the named distribution's mean and sd; each caliper moves
    by sigma = max(caliper sd, the cane's fit residual sd)."""
    from canebench.export.bundle import select
    from canebench.export.population import draw_population, fit_residual_sd

    sel = select(data, by_trial=False)[:2]
    n = 2000
    draws = draw_population(sel, ModelConfig(), n, seed=5, distribution="dormant", caliper_sd_m=0.2e-3)
    E = np.array([d.record["modulus_pa"] for d in draws])
    dist = MODULUS_DISTRIBUTIONS["dormant"]
    assert abs(E.mean() - dist.mean_pa) < 4 * dist.sd_pa / np.sqrt(n)
    assert abs(E.std(ddof=1) / dist.sd_pa - 1) < 0.08
    for k, (cane, _) in enumerate(sel):
        sigma = max(0.2e-3, fit_residual_sd(cane, ModelConfig()))
        d0 = np.array([c.diameter for c in cane.calipers])
        dd = np.array([[c.diameter for c in d.cane.calipers] for d in draws[k::2]]) - d0
        assert np.all(np.abs(dd.mean(axis=0)) < 4 * sigma / np.sqrt(len(dd)))
        assert np.all(np.abs(dd.std(axis=0, ddof=1) / sigma - 1) < 0.1)
        assert draws[k].record["caliper_sd_m"] == sigma
        assert all(d.config.modulus_pa == d.record["modulus_pa"] for d in draws[k::2])


PER_CANE_MODEL = """\
canebench_model: 1
preset: beam-consistent
effects:
  - effect: root_compliance
    scope: per_cane
    params: {k_root: 30.0}
    local: {b1c1: {k_root: 5.0}, b2c1: {k_root: 200.0}}
    between_canes: {k_root: {median: 25.0, ln_sd: 0.6}}
  - {effect: modulus_scale, params: {scale: 0.8}}
"""


def test_a_population_draws_a_per_cane_effect_from_its_spread_between_canes(tmp_path, data):
    """A root fitted per cane (discovery's model file) gives each member a root drawn from the fitted
    log-normal, not the source cane's own value nor the global one; the other draws (modulus,
    calipers) are those of the same seed without it; the drawn value reaches the chain and the
    manifest."""
    from canebench.export.bundle import export_population, select
    from canebench.export.population import draw_population
    from canebench.model.effects import Spread
    from canebench.model.modelfile import load_model_file

    path = tmp_path / "model.yaml"
    path.write_text(PER_CANE_MODEL)
    cfg = load_model_file(path)
    root = next(e for e in cfg.effects if e.name == "root_compliance")
    assert root.between == (("k_root", Spread(25.0, 0.6, None)),) and root.scope == "per_cane"
    sel = [x for x in select(data, by_trial=False) if x[0].id in ("b1c1", "b2c1")]
    n = 4000
    draws = draw_population(sel, cfg, n, seed=9)
    k = np.array([d.record["effects_drawn"]["root_compliance"]["k_root"] for d in draws])
    # log-normal(ln 25, 0.6): the mean of ln k within 4 standard errors, its sd within 5 %
    assert abs(np.log(k).mean() - np.log(25.0)) < 4 * 0.6 / np.sqrt(n)
    assert abs(np.log(k).std(ddof=1) / 0.6 - 1) < 0.05
    # each member's chain takes its own drawn root (global, no cane's local value) and the scale as is
    for d in draws[:4]:
        specs = {e.name: e for e in d.config.effects}
        assert dict(specs["root_compliance"].params) == {"k_root": d.record["effects_drawn"]["root_compliance"]["k_root"]}
        assert not specs["root_compliance"].local and not specs["root_compliance"].between
        assert specs["modulus_scale"] == next(e for e in cfg.effects if e.name == "modulus_scale")
        fx = d.config.applied_effects(d.cane.id, None)
        assert fx.root_compliance() == pytest.approx(1.0 / d.record["effects_drawn"]["root_compliance"]["k_root"])
    # the modulus and calipers are the draws of the same seed with a model that has no spread
    plain = draw_population(sel, cfg.replace(effects=()), 6, seed=9)
    for a, b in zip(draws[:6], plain):
        assert a.record["modulus_pa"] == b.record["modulus_pa"]
        assert a.record["caliper_diameters_m"] == b.record["caliper_diameters_m"]
        assert "effects_drawn" not in b.record
    # the manifest carries the drawn value, and the exported chain is stiffer with the stiffer root
    res = export_population(sel, cfg, tmp_path / "pop", 6, seed=9, formats="mjcf")
    man = res.manifest
    np.testing.assert_allclose(man["root_compliance.k_root"], k[:6])
    from canebench.export.bundle import _k_linear
    from canebench.model.effects import EffectSpec

    for d, row in zip(draws[:6], man.itertuples()):
        member = build_chain(d.cane, d.push_id, d.config)
        assert row.k_linear_N_per_mm == pytest.approx(_k_linear(member) * 1e-3, rel=1e-12)
        # against the same member on the global root (30): stiffer exactly when its drawn root is
        at_30 = d.config.replace(effects=tuple(EffectSpec("root_compliance", (("k_root", 30.0),))
                                               if e.name == "root_compliance" else e for e in d.config.effects))
        assert (_k_linear(member) > _k_linear(build_chain(d.cane, d.push_id, at_30))) == (k[d.index] > 30.0)


def test_a_population_carries_the_spreads_sampling_error_where_the_model_file_gives_it():
    """With ``cov_ln`` (the sampling covariance of ln median and ln ln_sd), each new cane's value is
    drawn after (ln median, ln ln_sd) are drawn from their normal: ln v = m + s z with m ~ N(ln median,
    a), ln s ~ N(ln ln_sd, c), corr(m, ln s) = b / sqrt(a c). Its moments, written out here: E ln v =
    ln median, var ln v = a + ln_sd^2 exp(2 c) (E s^2 of a log-normal s), and the excess kurtosis of
    ln v is that of a normal scale mixture, 3 (E s^4 / (E s^2)^2 - 1) = 3 (exp(4 c) - 1) with a = 0.
    Checked on 100,000 draws, within 5 standard errors of each moment (the sd of a sample variance of
    a heavy-tailed variable is sqrt((kurtosis + 2) / n) of it, that of a sample kurtosis about
    sqrt(24 / n) for a normal, larger here, so the kurtosis band is 10 % plus 5 such errors). Without
    ``cov_ln`` the draw is the plug-in log-normal's, one standard normal each."""
    from canebench.model.effects import Spread

    n = 100_000
    for a, b, c in ((0.03, 0.0, 0.04), (0.0, 0.0, 0.09), (0.02, 0.015, 0.03), (0.02, -0.015, 0.03)):
        sp = Spread(25.0, 0.6, ((a, b), (b, c)))
        rng = np.random.default_rng(1)
        lv = np.log([sp.draw(rng) for _ in range(n)])
        var = a + 0.36 * np.exp(2 * c)
        assert abs(lv.mean() - np.log(25.0)) < 5 * np.sqrt(var / n)
        kurt_excess = float(np.mean((lv - lv.mean()) ** 4) / lv.var() ** 2 - 3)
        assert abs(lv.var() / var - 1) < 5 * np.sqrt((kurt_excess + 2) / n), (a, b, c, lv.var(), var)
        if a == 0:
            assert abs(kurt_excess - 3 * (np.exp(4 * c) - 1)) < 0.1 * 3 * (np.exp(4 * c) - 1) + 5 * np.sqrt(24 / n)
        # the correlation b: E (ln v - E ln v)^3 = 3 E[m s^2] = 6 b ln_sd^2 exp(2 c) (Stein's lemma), within 5
        # of the sample's standard errors; the sign of b flips it
        x = (lv - lv.mean()) ** 3
        want3 = 6 * b * 0.36 * np.exp(2 * c)
        assert abs(x.mean() - want3) < 5 * x.std() / np.sqrt(n), (a, b, c, x.mean(), want3)
    # a covariance of zeros is the plug-in log-normal, though drawn from three normals, not one
    rng, zero = np.random.default_rng(2), Spread(25.0, 0.6, ((0.0, 0.0), (0.0, 0.0)))
    lv0 = np.log([zero.draw(rng) for _ in range(n)])
    assert abs(lv0.std(ddof=1) / 0.6 - 1) < 0.02
    rng_a, rng_b = np.random.default_rng(3), np.random.default_rng(3)
    assert Spread(25.0, 0.6).draw(rng_a) == pytest.approx(25.0 * np.exp(0.6 * rng_b.standard_normal()), rel=1e-15)


def test_between_canes_in_a_model_file_is_checked_and_survives_a_round_trip(tmp_path):
    from canebench.errors import InputError
    from canebench.model.modelfile import load_model_file, write_model_file

    path = tmp_path / "model.yaml"
    path.write_text(PER_CANE_MODEL)
    cfg = load_model_file(path)
    write_model_file(tmp_path / "again.yaml", cfg, preset="beam-consistent")
    assert load_model_file(tmp_path / "again.yaml").effects == cfg.effects
    # and with the spread's sampling covariance; YAML 1.1 reads 2.5e1 (no sign in the exponent) as text
    path.write_text(PER_CANE_MODEL.replace("median: 25.0, ln_sd: 0.6}",
                                           "median: 2.5e1, ln_sd: 0.6, cov_ln: [[0.02, -0.004], [-0.004, 3e-2]]}"))
    cov = load_model_file(path)
    assert dict(cov.effects[0].between)["k_root"] == (25.0, 0.6, ((0.02, -0.004), (-0.004, 0.03)))
    write_model_file(tmp_path / "again.yaml", cov, preset="beam-consistent")
    assert load_model_file(tmp_path / "again.yaml").effects == cov.effects
    # a trial's model (job keys) does not carry it: the same physics whatever the spread
    assert all(not e.between for e in cfg.localized("b1c1", "b1c1t1").effects)
    for bad, field in (("{k_root: {median: -3, ln_sd: 0.5}}", "k_root.median"),
                       ("{k_root: {median: 20, ln_sd: .nan}}", "k_root.ln_sd"),
                       ("{k_rot: {median: 20, ln_sd: 0.5}}", "between_canes.k_rot"),
                       ("{k_root: {median: 20}}", "k_root"),
                       ("{k_root: {median: twenty, ln_sd: 0.5}}", "k_root"),
                       ("{k_root: {median: true, ln_sd: 0.5}}", "k_root"),
                       ("0", "between_canes"),
                       ("[20, 0.5]", "between_canes"),
                       ("{k_root: {median: 20, ln_sd: 0.5, cov: 1}}", "k_root"),
                       # the sampling covariance of (ln median, ln ln_sd): symmetric, positive semi-definite
                       ("{k_root: {median: 20, ln_sd: 0.5, cov_ln: [[0.02, 0.01], [0.0, 0.03]]}}", "k_root.cov_ln"),
                       ("{k_root: {median: 20, ln_sd: 0.5, cov_ln: [[-0.02, 0.0], [0.0, 0.03]]}}", "k_root.cov_ln"),
                       ("{k_root: {median: 20, ln_sd: 0.5, cov_ln: [[0.01, 0.05], [0.05, 0.01]]}}", "k_root.cov_ln"),
                       ("{k_root: {median: 20, ln_sd: 0.5, cov_ln: [[0.01, .nan], [.nan, 0.01]]}}", "k_root.cov_ln"),
                       ("{k_root: {median: 20, ln_sd: 0.5, cov_ln: [0.01, 0.0, 0.01]}}", "k_root.cov_ln"),
                       ("{k_root: {median: 20, ln_sd: 0.5, cov_ln: [[a, 0], [0, 0.01]]}}", "k_root.cov_ln"),
                       ("{k_root: {median: 20, ln_sd: 0.0, cov_ln: [[0.01, 0.0], [0.0, 0.01]]}}", "k_root.cov_ln"),
                       # beyond COV_LN_MAX (a draw could overflow) and LN_SD_MAX; a YAML int too large for a float
                       ("{k_root: {median: 20, ln_sd: 0.5, cov_ln: [[2.0, 0.0], [0.0, 0.01]]}}", "k_root.cov_ln"),
                       ("{k_root: {median: 20, ln_sd: 0.5, cov_ln: [[0.01, 0.0], [0.0, 0.5]]}}", "k_root.cov_ln"),
                       ("{k_root: {median: 20, ln_sd: 0.5, cov_ln: [[1.0e+200, 0], [0, 1.0e+200]]}}", "k_root.cov_ln"),
                       ("{k_root: {median: 20, ln_sd: 0.5, cov_ln: [[1%s, 0], [0, 0.01]]}}" % ("0" * 400), "k_root.cov_ln"),
                       ("{k_root: {median: 1%s, ln_sd: 0.5}}" % ("0" * 400), "k_root"),
                       ("{k_root: {median: 20, ln_sd: 7.0}}", "k_root.ln_sd")):
        path.write_text(PER_CANE_MODEL.replace("{k_root: {median: 25.0, ln_sd: 0.6}}", bad))
        with pytest.raises(InputError) as exc:
            load_model_file(path)
        assert str(path) in str(exc.value) and field in str(exc.value), (bad, str(exc.value))
    # only an effect that may be each cane's own, and only its parameter that switches it off: a log-normal
    # draw of a rig or a (signed) pitch, or of a collar's length, is not what discovery fits
    for effect, params, par in (("rig_compliance", "{k_rig: 300.0}", "k_rig"),
                                ("probe_misalignment", "{angle_deg: -10.0}", "angle_deg"),
                                ("base_flare", "{excess_mm: 3.0, length_mm: 120.0}", "length_mm")):
        path.write_text(f"canebench_model: 1\neffects:\n  - effect: {effect}\n    params: {params}\n"
                        f"    between_canes: {{{par}: {{median: 20, ln_sd: 0.5}}}}\n")
        with pytest.raises(InputError, match=f"{effect}.between_canes.{par}.*cannot vary between canes"):
            load_model_file(path)
    # a spread without canes' own values (a hand-written file) also stays out of a trial's model
    path.write_text(PER_CANE_MODEL.replace("    local: {b1c1: {k_root: 5.0}, b2c1: {k_root: 200.0}}\n", ""))
    spread_only = load_model_file(path)
    assert spread_only.effects[0].between and not spread_only.effects[0].local
    assert spread_only.localized("b1c1", "b1c1t1") == spread_only.replace(
        effects=tuple(dataclasses.replace(e, between=()) for e in spread_only.effects))
    # built in Python: lists hash and compare as the file's tuples; out-of-range values are named on use
    from canebench.model.effects import EffectSpec

    listed = EffectSpec("root_compliance", (("k_root", 30.0),), (), "per_cane",
                        (("k_root", (25, 0.6, [[0.02, -0.004], [-0.004, 0.03]])),))
    assert listed.between == cov.effects[0].between and hash(listed.between) == hash(cov.effects[0].between)
    for bad, field in (((25.0, 0.6, ((-0.02, 0.0), (0.0, 0.03))), "k_root.cov_ln"), ((25.0, -0.6), "k_root.ln_sd"),
                       ((25.0, 0.6, "x"), "between_canes.k_root"), ((25.0,), "between_canes.k_root")):
        with pytest.raises(InputError, match=field):
            ModelConfig(effects=(EffectSpec("root_compliance", (("k_root", 30.0),), (), "per_cane", (("k_root", bad),)),))


def test_a_population_draws_only_the_parameter_that_varies_and_warns_where_no_spread_was_written(data):
    """A collar per cane draws its excess; its length stays the fitted one and is not reported as
    drawn. A model with canes' own values but no spread (a file from before between_canes) gives
    each member its source cane's value, and says so."""
    from canebench.errors import InputWarning
    from canebench.export.bundle import select
    from canebench.export.population import draw_population
    from canebench.model.effects import EffectSpec

    sel = select(data, by_trial=False)[:2]
    collar = EffectSpec("base_flare", (("excess_mm", 3.0), ("length_mm", 120.0)), (), "per_cane",
                        (("excess_mm", (3.0, 0.5)),))
    draws = draw_population(sel, ModelConfig(effects=(collar,)), 3, seed=2)
    for d in draws:
        (spec,) = d.config.effects
        assert list(d.record["effects_drawn"]) == ["base_flare"]
        assert d.record["effects_drawn"]["base_flare"] == {"excess_mm": dict(spec.params)["excess_mm"]}
        assert dict(spec.params)["length_mm"] == 120.0
    own = EffectSpec("root_compliance", (("k_root", 30.0),), ((sel[0][0].id, (("k_root", 5.0),)),), "per_cane")
    with pytest.warns(InputWarning, match="no spread between canes"):
        d0 = draw_population(sel, ModelConfig(effects=(own,)), 1, seed=2)[0]
    assert d0.config.applied_effects(sel[0][0].id, None).root_compliance() == pytest.approx(1 / 5.0)
    # a per-trial effect's values (an obstruction's onsets) are not a cane's: no warning
    onsets = EffectSpec("obstruction", (), (("b1c1t2", (("onset_mm", 30.0),)),), "per_trial")
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error", InputWarning)
        draw_population(sel, ModelConfig(effects=(onsets,)), 1, seed=2)


# ------------------------------------------------------------------ bad input


@pytest.mark.parametrize("argv, says", [
    (["--format", "mjcf,obj"], "unknown export format 'obj'"),
    (["--format", "urfd"], "did you mean 'urdf'"),
    (["--population", "0"], "--population"),
    (["--population", "-3"], "must be >= 1"),
    (["--population", "ten"], "whole number"),
    (["--population", "2", "--seed", "-1"], "--seed"),
    (["--population", "2", "--distribution", "winter"], "winter"),
    (["--population", "2", "--modulus", "3e9"], "draws the modulus"),
    (["--distribution", "dormant"], "need --population"),
    (["--canes", "b1c1", "--push", "9"], "no push point with id '9'"),
    (["--trials", "b1c1t1", "--push", "2"], "--push"),
    (["--canes", "zz*"], "no trial matches"),
    (["--set", "stiffness_formula=dual-length"], "did you mean 'dual_length'"),
    (["--model", "/nonexistent/model.yaml"], "model file not found"),
])
def test_bad_input_is_a_clear_error(tmp_path, capsys, argv, says):
    out = tmp_path / "x"
    assert main(["export", *argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "canebench: error:" in err and says in err, err
    assert not (out / "manifest.csv").exists()


def test_trials_and_canes_are_exclusive(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["export", "--trials", "b1c1t1", "--canes", "b1c1"])
    assert exc.value.code == 2 and "not allowed with" in capsys.readouterr().err


def test_bench_export_reports_both_runs(capsys):
    """The benchmark runs (no timing asserted): one single export and a population, with ratios."""
    from canebench.studies.bench import bench_export

    df = bench_export(population=3, formats="mjcf")
    assert list(df.index) == ["single", "population"] and list(df.canes) == [1, 3]
    assert df.loc["single", "vs_single"] == 1.0 and (df.wall_s > 0).all()
    assert "population of 3" in capsys.readouterr().out
