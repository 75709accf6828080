"""Stiffness formulas, and the whole chain checked against closed forms
(reference-values.md sec. 5: n equal links with torsional springs, tip load)."""

import numpy as np
import pytest

from canebench.data.cane import cane_from_dict
from canebench.model.chain import build_chain
from canebench.model.config import ModelConfig
from canebench.errors import InputError
from canebench.model.stiffness import joint_stiffness

E, D, L = 4.57e9, 0.01, 1.2
EI = E * np.pi * D**4 / 64


def test_formula_values():
    ei = np.full(4, 3.0)
    le = np.full(4, 0.5)
    np.testing.assert_allclose(joint_stiffness("paper", ei, le), 2 * 3.0 / 0.5)
    np.testing.assert_allclose(joint_stiffness("end_angle", ei, le), 3.0 / 0.5)
    dual = joint_stiffness("dual_length", ei, le)
    assert dual[0] == pytest.approx(2 * 3.0 / 0.5)  # clamp: half a link
    np.testing.assert_allclose(dual[1:], 3.0 / 0.5)  # interior: dual length = one link


def test_dual_length_without_context_is_series_of_half_links():
    ei = np.array([4.0, 2.0])
    le = np.array([0.2, 0.3])
    k = joint_stiffness("dual_length", ei, le)
    assert k[1] == pytest.approx(1 / (0.1 / 4.0 + 0.15 / 2.0))


def test_unknown_formula_names_the_field():
    with pytest.raises(InputError, match="stiffness_formula"):
        joint_stiffness("nope", np.ones(2), np.ones(2))


def straight_cantilever(n: int, formula: str):
    cane = cane_from_dict({
        "id": "straight", "polyline": {"raw": False, "points": [[0, 0, 0], [0, 0, L]]},
        "calipers": [{"s": 0.5, "diameter": D}],
        "push_points": [{"id": "tip", "s": L, "direction": [1, 0, 0]}],
        "material": {"flexural_modulus": E},
    })
    return build_chain(cane, "tip", ModelConfig(segments=n, gravity=0.0, stiffness_formula=formula))


@pytest.mark.parametrize("n", [3, 5, 10, 20])
@pytest.mark.parametrize("formula,ratio", [
    ("end_angle", lambda n: (n + 1) * (2 * n + 1) / (2 * 1 * n**2)),   # springs at link starts, c = 1
    ("paper", lambda n: (n + 1) * (2 * n + 1) / (2 * 2 * n**2)),       # c = 2
    ("dual_length", lambda n: 1 + 1 / (2 * n**2)),                     # Voronoi placement
])
def test_chain_tip_compliance_matches_closed_form(n, formula, ratio):
    from canebench.backends.pinocchio_backend import PinocchioStatic

    chain = straight_cantilever(n, formula)
    k = PinocchioStatic(chain).linear_stiffness()
    beam = L**3 / (3 * EI)
    # exact arithmetic identity: only round-off separates the two
    assert (1 / k) / beam == pytest.approx(ratio(n), rel=1e-9)


def test_reference_table_values():
    # the published table in reference-values.md, start placement
    table = {3: (1.5556, 0.7778), 5: (1.3200, 0.6600), 10: (1.1550, 0.5775), 20: (1.0763, 0.5381)}
    from canebench.backends.pinocchio_backend import PinocchioStatic

    for n, (c1, c2) in table.items():
        beam = L**3 / (3 * EI)
        r1 = 1 / PinocchioStatic(straight_cantilever(n, "end_angle")).linear_stiffness() / beam
        r2 = 1 / PinocchioStatic(straight_cantilever(n, "paper")).linear_stiffness() / beam
        assert r1 == pytest.approx(c1, abs=6e-5)  # table rounded to 4 decimals
        assert r2 == pytest.approx(c2, abs=6e-5)


def test_dual_length_with_context_integrates_compliance_exactly():
    from canebench.model.stiffness import StiffnessContext

    # EI(s) = 1 + s on nodes 0, 1, 3: dual segments [0, 0.5] and [0.5, 2]
    ctx = StiffnessContext(np.array([0.0, 1.0, 3.0]), lambda s: 1.0 + s)
    k = joint_stiffness("dual_length", np.array([1.5, 3.0]), np.array([1.0, 2.0]), ctx)
    np.testing.assert_allclose(k, [1 / np.log(1.5), 1 / np.log(3.0 / 1.5)], rtol=1e-12)
