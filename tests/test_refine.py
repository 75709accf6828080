"""A flare's size exponent, held during the selection and fitted afterwards (``discovery.refine``)."""

from __future__ import annotations

import math

import numpy as np
import pytest


def test_flare_size_exponent_spans_a_fixed_collar_and_a_share_of_the_diameter():
    """At q = 0 the flare is the absolute collar d + e exp(-s / l), bit for bit (every fit that never
    frees q must be unchanged); at q = 1 it is the share-of-diameter form the independent generators
    hide, d (1 + A exp(-s / l)) with A = e / 10 mm; in between, the excess is the geometric mean's
    power of the two."""
    from canebench.model.effects import EFFECTS

    flare = EFFECTS["base_flare"]
    s = np.linspace(0.0, 0.6, 13)
    d = np.linspace(0.024, 0.009, 13)
    e, ell = 6.0e-3, 0.12
    absolute = d + 1e-3 * 6.0 * np.exp(-s / (1e-3 * 120.0))  # the expression before session 66, as it was
    assert np.array_equal(flare(excess_mm=6.0, length_mm=120.0).diameter(s, d), absolute)
    share = d * (1.0 + (e / 0.010) * np.exp(-s / ell))
    np.testing.assert_allclose(flare(excess_mm=6.0, length_mm=120.0, size_exponent=1.0).diameter(s, d), share,
                               rtol=1e-12)
    half = flare(excess_mm=6.0, length_mm=120.0, size_exponent=0.5).diameter(s, d) - d
    np.testing.assert_allclose(half, np.sqrt((absolute - d) * (share - d)), rtol=1e-12)
    # a cane 10 mm thick takes the same excess whatever q is
    ten = np.full(3, 0.010)
    np.testing.assert_allclose(flare(excess_mm=4.0, size_exponent=0.7).diameter(s[:3], ten),
                               flare(excess_mm=4.0).diameter(s[:3], ten), rtol=1e-12)


def test_the_selection_holds_refined_parameters_at_their_null():
    from canebench.discovery.fit import Candidate

    sel = Candidate.of(("root_compliance", "base_flare"))
    assert ("base_flare", "size_exponent") not in sel.free and sel.refined == ()
    assert [p for n, p in sel.free if n == "base_flare"] == ["excess_mm", "length_mm"]
    # a spec the selection fits carries no size_exponent: the instance takes the null, 0
    spec = next(s for s in sel.specs(np.zeros(len(sel.free))) if s.name == "base_flare")
    assert "size_exponent" not in dict(spec.params) and spec.instance().p["size_exponent"] == 0.0
    ref = Candidate.of(("root_compliance", "base_flare"), (("base_flare", "size_exponent"),))
    assert ref.free[-1] == ("base_flare", "size_exponent") and ref.refined == (("base_flare", "size_exponent"),)


@pytest.fixture(scope="module")
def bundled_screen():
    """The screen of the bundled trials (18 canes whose caliper lines reach 13-33 mm at the ground)
    and seeded scatter: 0.1 in ln between canes, 0.02 within (the real trials' split)."""
    from canebench.data.dataset import bundled_dataset, load_dataset
    from canebench.discovery.screen import trial_geometry
    from canebench.discovery.screenset import ScreenSet
    from canebench.model.presets import PRESETS

    ss = ScreenSet.build([trial_geometry(t, PRESETS["beam-consistent"]) for t in load_dataset(bundled_dataset())])
    lkb = -np.log(ss.c0 * 1e3)
    _, inv = np.unique(ss.canes, return_inverse=True)
    return ss, lkb, inv


def _scatter(inv: np.ndarray, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.normal(0, 0.1, inv.max() + 1)[inv] + rng.normal(0, 0.02, len(inv))


def _refine(ss, lkb, lkf):
    from canebench.discovery.fit import Candidate, cross_validate
    from canebench.discovery.refine import refine
    from canebench.discovery.screenset import Anchored

    at = Anchored(ss, lkb)
    cv = cross_validate(Candidate.of(("base_flare",)), at, lkf)
    calls = []

    def reanchor(at_, cv_):  # the engine's re-anchoring replaced by a recorder
        calls.append(cv_.fit.candidate.refined)
        return at_, cv_

    cv2, _, tried = refine(cv, at, lkf, reanchor)
    return cv, cv2, tried, calls


def test_a_flare_that_grows_with_the_cane_is_refined(bundled_screen):
    """Hidden: a flare whose excess is 0.9 of each cane's diameter at the ground over 120 mm (q = 1),
    in the screen's own linear model plus scatter. The selection's flare (q = 0) leaves the thick
    canes too soft; the refinement frees q, finds it near 1 by a likelihood ratio far past
    REFINE_ALPHA and a lower held-out density, re-anchors the refined model (the recorder sees q
    free) and returns it. How near: the flare's excess and length trade off against q over these
    canes, so within 0.3 of the truth."""
    from canebench.discovery.refine import REFINE_ALPHA
    from canebench.discovery.screenset import Anchored
    from canebench.model.effects import EffectSpec

    ss, lkb, inv = bundled_screen
    hidden = (EffectSpec.parse("base_flare(excess_mm=9, length_mm=120, size_exponent=1)"),)
    lkf = Anchored(ss, lkb).predict(hidden) + _scatter(inv, 3)
    cv, cv2, tried, calls = _refine(ss, lkb, lkf)
    (r,) = tried
    assert (r.effect, r.parameter) == ("base_flare", "size_exponent")
    assert r.adopted and r.p < REFINE_ALPHA / 100 and r.cv_loss_refined < r.cv_loss_selected
    assert calls == [(("base_flare", "size_exponent"),)]
    q = dict(next(s for s in cv2.fit.specs if s.name == "base_flare").params)["size_exponent"]
    assert q > 0.7, r
    # what it is for: the canes left out are predicted better (the held-out residual's median |ln|)
    assert np.median(np.abs(cv2.residual)) < 0.8 * np.median(np.abs(cv.residual))


def test_a_fixed_collar_is_seldom_refined(bundled_screen):
    """Hidden: one 6 mm collar for every cane (q = 0). Over 20 seeds of scatter the refinement is
    adopted at most twice: at REFINE_ALPHA = 0.01 (conservative at the bound) the expected count is
    under 0.2, and two or more adoptions have probability under 2 % at a true rate of 0.01 (binomial);
    a test that adopts whatever lowers the likelihood (p ignored) adopts in most seeds. Where it is not
    adopted the selected model is returned unchanged and nothing is re-anchored."""
    from canebench.discovery.screenset import Anchored
    from canebench.model.effects import EffectSpec

    ss, lkb, inv = bundled_screen
    hidden = (EffectSpec.parse("base_flare(excess_mm=6, length_mm=150)"),)
    adopted, lower = 0, 0
    for seed in range(20):
        lkf = Anchored(ss, lkb).predict(hidden) + _scatter(inv, 100 + seed)
        cv, cv2, (r,), calls = _refine(ss, lkb, lkf)
        adopted += r.adopted
        lower += r.lr > 0.05
        if not r.adopted:
            assert cv2 is cv and calls == [] and math.isnan(r.value_adopted)
    assert adopted <= 2
    assert lower >= 5  # the fit does move q: the test, not the fitter, keeps it at 0


def test_refits_after_a_refinement_keep_it_and_drop_what_it_made_stale(bundled_screen):
    """A share-of-diameter flare (16 mm at 10 mm over 150 mm) alone hidden: with q held at 0 the
    selection adds a modulus scale to make up for the thick canes; once q is adopted the scale changes
    the model by less than MIN_CHANGE and the backward pass (which the workflow runs after an adoption)
    drops it, its refits keeping q free (an independent review found the scale left named, seed 3).
    The engine's re-anchoring keeps q too (a stand-in engine whose runs equal the screen)."""
    from types import SimpleNamespace

    from canebench.discovery import engine_runs
    from canebench.discovery.refine import refine
    from canebench.discovery.screenset import Anchored
    from canebench.discovery.selection import MIN_CHANGE, backward, forward_select
    from canebench.model.effects import EffectSpec

    ss, lkb, inv = bundled_screen
    at = Anchored(ss, lkb)
    lkf = at.predict((EffectSpec.parse("base_flare(excess_mm=16, length_mm=150, size_exponent=1)"),)) + _scatter(inv, 3)
    ident = lambda a, c: (a, c)  # noqa: E731
    sel = forward_select(("modulus_scale", "root_compliance", "rig_compliance", "base_flare"), at, lkf, ident, 0.05, 3,
                         MIN_CHANGE, 0)
    assert set(sel.current) == {"base_flare", "modulus_scale"}, sel.current
    cv, at2, (r,) = refine(sel.cv, sel.at, lkf, ident)
    assert r.adopted
    current, cv2, _, dropped = backward(sel.current, (), cv, at2, lkf, MIN_CHANGE, ident, [], 2)
    assert current == ("base_flare",) and dropped == ["modulus_scale"]
    assert cv2.fit.candidate.refined == (("base_flare", "size_exponent"),)
    engine = SimpleNamespace(backend="screen", log_k=lambda specs, label: at2.predict(tuple(specs)))
    _, cv3 = engine_runs.reanchor(engine, at2, cv2, lkf, [], 1, 1)
    assert cv3.fit.candidate.refined == (("base_flare", "size_exponent"),)
    assert dict(cv3.fit.specs[0].params)["size_exponent"] > 0.7


@pytest.mark.heavy
def test_the_thirteenth_generators_share_of_diameter_flare_is_named(tmp_path):
    """End to end, on data canebench did not make: the thirteenth independent generator's ds05
    (docs/independent-generator-13, written blind from the format documents), a collar d (1 + A
    exp(-s / l)) with A 0.55-0.80 on canes whose bases range 15-30 mm. Before the refinement the
    flare was fitted at its 25 mm bound and withheld as partial: its held-out residual rose with the
    model's stiffness between canes (the thick canes needed more collar). Now the flare is named
    alone with its size exponent freed and near 1, nothing is flagged, and the out-of-sample median
    |ln| falls by more than half (0.42 -> 0.08 in session 66). About two minutes."""
    import subprocess
    import sys
    from pathlib import Path

    from canebench.data.dataset import load_dataset
    from canebench.discovery.workflow import discover
    from canebench.execute.executors import make_executor

    here = Path(__file__).resolve().parents[1] / "docs" / "independent-generator-13"
    # run as a script (its folder on the path: it imports its own rod.py), writing into tmp_path
    subprocess.run([sys.executable, str(here / "make.py"), "--only", "ds05", "--out", str(tmp_path)], check=True,
                   capture_output=True)
    res = discover(load_dataset(tmp_path / "data" / "ds05"), confirm=False, n_boot=40,
                   executor=make_executor("serial", 1))
    assert [n["effect"] for n in res.named] == ["base_flare"] and not res.unexplained, (res.named, res.notes)
    (r,) = res.refinements
    assert r["adopted"] and r["value_adopted"] > 0.7, r
    q_lo, q_hi = res.named[0]["ci95"]["size_exponent"]
    assert q_lo > 0.5  # an exponent the data pin, not the bound alone
    assert res.gap["after_cv"]["median_abs_log_ratio"] < 0.5 * res.gap["before"]["median_abs_log_ratio"]
