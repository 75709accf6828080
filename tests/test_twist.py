"""The optional twist joint: a chain that converges to the beam with torsion.

Reference: a quarter-circle cantilever (radius R, clamped tangent to z,
curving in the x-z plane) under a tip force out of its plane bends and
twists: delta = F R^3 [pi/(4 EI) + (3 pi/4 - 2)/GJ], GJ = EI/(1 + nu)
(reference-values.md sec. 3). Without the twist joint the chain is rigid in
torsion and converges to the first term only.
"""

from __future__ import annotations

import numpy as np
import pytest

from canebench.data.cane import cane_from_dict
from canebench.execute.executors import SerialExecutor
from canebench.execute.runner import run_trials
from canebench.model.chain import build_chain
from canebench.model.config import ModelConfig
from canebench.probe.protocol import PROTOCOLS
from canebench.backends.pinocchio_backend import PinocchioStatic

R, D, E, NU = 1.0, 0.01, 4.57e9, 0.3
EI = E * np.pi * D**4 / 64


def quarter_circle():
    th = np.linspace(0, np.pi / 2, 400)
    pts = np.column_stack([R * (1 - np.cos(th)), np.zeros_like(th), R * np.sin(th)])
    L = float(np.linalg.norm(np.diff(pts, axis=0), axis=1).sum())  # the polyline's own length (chords)
    return cane_from_dict({
        "id": "qc", "polyline": {"raw": False, "points": pts.tolist()},
        "calipers": [{"s": 0.0, "diameter": D}, {"s": L, "diameter": D}],
        # the probe pushes horizontally along y, out of the x-z plane, at the tip
        "push_points": [{"id": "tip", "s": L, "direction": [0, 1, 0]}],
        "material": {"flexural_modulus": E},
    }, "quarter-circle")


def compliance(twist: bool, n: int) -> float:
    cfg = ModelConfig(segments=n, discretization="uniform", stiffness_formula="dual_length", gravity=0.0,
                      twist_joint=twist, poisson_ratio=NU)
    return 1.0 / PinocchioStatic(build_chain(quarter_circle(), "tip", cfg)).linear_stiffness()


def test_twist_chain_converges_to_the_torsion_closed_form():
    bend = R**3 * np.pi / (4 * EI)
    tors = R**3 * (3 * np.pi / 4 - 2) * (1 + NU) / EI
    ns = (20, 40, 80)
    with_twist = np.array([compliance(True, n) / (bend + tors) - 1 for n in ns])
    without = np.array([compliance(False, n) / bend - 1 for n in ns])
    # on a curved rod the chain converges at first order (each node's joint axes are the following
    # link's: one-sided): the error halves per doubling; 80 links are within 0.3 % of the closed form
    order = -np.polyfit(np.log(ns), np.log(np.abs(with_twist)), 1)[0]
    assert 0.8 < order < 2.2 and abs(with_twist[-1]) < 3e-3
    # without the joint it converges to the torsion-rigid rod (first order as well), missing the torsion share
    assert abs(without[-1]) < 1.5e-2 and np.all(np.diff(np.abs(without)) < 0)


def test_engines_that_compile_the_twist_joint_agree_and_the_others_refuse(bundled_trials):
    t = [t for t in bundled_trials if t.id == "b5c1t2"]  # the push point where torsion matters most
    cfg = ModelConfig(twist_joint=True, stiffness_formula="dual_length", discretization="uniform", segments=12)
    res = run_trials(t, ["mujoco", "pinocchio", "dart"], PROTOCOLS["fast"], cfg,
                     executor=SerialExecutor()).results.set_index("backend")
    assert res.loc["pinocchio", "status"] == "ok" and res.loc["mujoco", "status"] == "ok"
    assert res.loc["mujoco", "k_sim"] / res.loc["pinocchio", "k_sim"] - 1 == pytest.approx(0, abs=5e-3)
    assert res.loc["dart", "status"] == "failed" and "twist joint" in res.loc["dart", "reason"]
    plain = run_trials(t, ["pinocchio"], PROTOCOLS["fast"], cfg.replace(twist_joint=False),
                       executor=SerialExecutor()).results.iloc[0]
    assert res.loc["pinocchio", "k_sim"] < plain.k_sim  # a torsion joint can only soften the chain
