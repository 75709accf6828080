"""The adequacy checks of a discovery result, one plain sentence each, for the CLI and the report.

Both print the same checks from ``discovery.json`` (:meth:`.workflow.DiscoveryResult.to_json`),
so they are worded once, here: the CLI indents the lines, the report escapes them into a
list. So is a name's close rival (:func:`rivals_text`). The reasons a model is withheld
(:func:`failure_reasons`), which the workflow writes into the result's own notes when a check
fails, say more: what each failed check means.
"""

from __future__ import annotations

import math
from typing import Any, Mapping

NAN = math.nan


def _left_out(canes: list[str]) -> str:
    """The canes the within-cane spread leaves out, as both texts name them."""
    return f"{', '.join(canes)}, which scatter{'s' if len(canes) == 1 else ''} most"


def rivals_text(named: dict[str, Any]) -> str:
    """``barely ahead of X: BIC +0.71`` for a name in ``discovery.json`` won by less than
    :data:`.selection.CLOSE_BIC` (its ``close_rivals``), else ``""``."""
    rivals = named.get("close_rivals") or []
    by_shape = [c for c in rivals if c.get("decided_by")]
    if by_shape:  # named against the BIC, by the traces' shape (.tiebreak)
        return "named over " + ", ".join(f"{c['candidate']} (BIC {-c['bic_above']:.2f} lower) by the traces' shape"
                                         for c in by_shape)
    r = ", ".join(f"{c['candidate']}: BIC +{c['bic_above']:.2f}" for c in rivals)
    return f"barely ahead of {r}" if r else ""


def fitted_entry(named: dict[str, Any]) -> bool:
    """Whether a ``named`` (or ``partial``) entry of ``discovery.json`` is a library effect the screen
    fitted (scope ``global`` or ``per_cane``), not the obstruction found per trial in the traces."""
    return named["scope"] != "per_trial"


def change_text(named: dict[str, Any]) -> str:
    """``ln k +0.412 (median; +0.105 to +0.873)`` for an effect in ``discovery.json`` that carries
    ``ln_k_change`` (what it alone changes ln k by on the scored trials), else ``""``."""
    c = named.get("ln_k_change")
    return f"ln k {c['median']:+.3f} (median; {c['min']:+.3f} to {c['max']:+.3f})" if c else ""


def scope_text(named: dict[str, Any]) -> str:
    """What the per-cane test (:mod:`.per_cane`) found for an effect in ``discovery.json`` that carries
    ``per_cane_test``: ``per cane: k_root 8.1 to 95 N m/rad over 18 canes (ln sd 0.74 +- 17 %; p = 2e-05)``
    or ``one value for all canes (per-cane test: p = 0.41)``; ``""`` where it was not tested."""
    t = named.get("per_cane_test")
    if not t:
        return ""
    if t["per_cane"]:
        v = t["values"].values()
        return (f"per cane: {t['parameter']} {min(v):.4g} to {max(v):.4g} {t['unit']} over {len(v)} canes "
                f"(ln sd {t['ln_sd_between_canes']:.2f}{_se_text(t)}; p = {t['p']:.2g})")
    if t["p"] >= t["alpha"]:
        return f"one value for all canes (per-cane test: p = {t['p']:.2g})"
    return (f"one value for all canes (per-cane test: p = {t['p']:.2g}, but the canes' own values move ln k by "
            f"{t['spread_mean_abs_ln_k']:.3f} only)")


def adequacy_lines(doc: dict[str, Any]) -> list[str]:
    """One sentence per adequacy check in ``doc["adequacy"]``, in the order the workflow runs them.

    Checks the result does not hold (an older file, too few canes) are left out.
    """
    ad = doc.get("adequacy") or {}
    alpha = ad.get("alpha")
    lines: list[str] = []

    def failed(p: Any) -> str:  # a p-value check's verdict
        return "; it is" if p is not None and alpha is not None and p < alpha else ""

    a = ad.get("after_cv")
    if a:
        b = ad.get("before") or {}
        lines.append(f"adequacy (held-out residual against the model's stiffness level, between {a['n_canes']} canes; "
                     f"null: the caliper line's shared error): r = {b.get('r', NAN):.2f} (p = {b.get('p', NAN):.2g}) "
                     f"before, r = {a['r']:.2f} (p = {a['p']:.2g}) after; the calipers' own error alone gives r about "
                     f"{a.get('null_median', NAN):.2f}"
                     + ("; their scatter exceeds what the residuals allow, so the null gives the line error all of "
                        "the between-cane spread (its most lenient form)" if a.get("geometry_bounded") else "")
                     + f"; below p = {alpha} the model is called incomplete" + failed(a.get("p")))
    wa = ad.get("within_after_cv")
    if wa:
        wb = ad.get("within_before") or {}
        tk = ad.get("within_taken_by")
        taken = ""
        if tk:
            taken = (f"; taken by {tk['effect']} added beside the named effects (r = {tk['r']:.2f}, p = "
                     f"{tk['p']:.2g}" + (f"; {', '.join(tk['at_bound'])} at its search bound" if tk.get("at_bound")
                                         else "") + "): the names stand, flagged unexplained")
        elif "within_tried" in ad:
            taken = "; not taken by an unnamed flare added beside the named ones: the names are withheld"
        lines.append(f"within canes (held-out residual against push height along each cane, {wa['n_canes']} canes; "
                     f"null: trial noise and the caliper line's error): r = {wb.get('r', NAN):.2f} (p = "
                     f"{wb.get('p', NAN):.2g}) before, r = {wa['r']:.2f} (null spread +-{2 * wa['null_sd']:.2f}, "
                     f"p = {wa['p']:.2g}) after; below p = {alpha} the model is called incomplete{taken}")
        if not tk and "within_tried" not in ad:
            lines[-1] += failed(wa.get("p"))
    wd = ad.get("within_dispersion")
    if wd:
        trimmed = (wa or {}).get("sd_trimmed_canes") or []
        lines.append("within-cane spread of the held-out residual (pooled over canes"
                     + (f", leaving out {_left_out(trimmed)} (all canes: {wa.get('sd_all', NAN):.3f})"
                        if trimmed else "")
                     + f"): {wd['sd']:.3f} in ln k, {wd['ratio']:.1f} times the caliper line's error alone "
                     f"({wd['geometry_sd']:.3f}); beyond {wd['factor']:.3g} times (and {wd['material']:.3g} in ln k) "
                     f"the model is called incomplete" + ("; it is" if wd["fails"] else ""))
    sh = ad.get("shape") or {}
    if sh.get("p") is not None:
        lines.append(f"shape (the traces' stiffening over the push): the fitted model changes it by "
                     f"{sh['predicted_mean']:+.3f} on average (spread {sh['predicted_spread']:.3f} across "
                     f"{sh['n_trials']} trials), the traces show {sh['beta']:.2f} of that change; p = {sh['p']:.2g} "
                     f"against {sh['share']:.2g} of it (below {alpha} the model is called incomplete{failed(sh['p'])})")
    elif sh.get("predicted_spread") is not None:
        lines.append(f"shape: the model changes the traces' stiffening by {sh['predicted_mean']:+.3f} on average and "
                     f"barely from trial to trial (spread {sh['predicted_spread']:.3f}): nothing to check")
    lv = sh.get("level") or {}
    if lv.get("mean") is not None:
        lines.append(f"the traces' stiffening over the push beyond the model's, mean over {lv['n_canes']} canes: "
                     f"{lv['mean']:+.3f} (allowance +-{lv['excess']:.2g}"
                     + (f"; p = {lv['p']:.2g} beyond it" if lv["p"] is not None and lv["p"] < 1 else "")
                     + f"); beyond it (p below {alpha}) the model is called incomplete"
                     + ("; it is" if lv["fails"] else ""))
    if ad.get("inadequate"):
        lines.append("the model fails a check: " + ("its effects are reported as partial, not named"
                                                   if doc.get("partial") else "the baseline does not account for the data"))
    return lines


def lookalike_notes(named: list[dict[str, Any]], partial: list[dict[str, Any]],
                    lowest_push_mm: list[float]) -> list[str]:
    """What a fitted flare cannot be told apart from, in stiffness data: one sentence, or none.

    A flare stiffens the cane below the pushes; so does a neighbouring cane (or a stake) touching
    it below them, a lateral spring support the library does not have. Pushed only above both,
    each changes a push's compliance by a quadratic in the push's position along the cane (for
    a point support, a perfect square); a root spring beside the flare lets the pair take that
    square on a cane. With three pushes a cane, spanning a fifth of its length, the data do not
    resolve the difference (docs/discovery.md: seed 8's set 38, named root + flare for a support
    at a third of each cane's length, below every push). ``named``: the result's names;
    ``partial``: the global names withheld (a flare there gets the note too: the support is then
    a candidate for what the library could not explain); ``lowest_push_mm``: each cane's lowest
    scored push, along the cane from its base.
    """
    found = [(n, how, names) for names, how in ((named, "named,"), (partial, "fitted but withheld as partial,"))
             for n in names if n["effect"] == "base_flare" and fitted_entry(n)]
    if not found or not lowest_push_mm:
        return []
    flare, how, names = found[0]
    root = any(n["effect"] == "root_compliance" and fitted_entry(n) for n in names)
    lo, hi = min(lowest_push_mm), max(lowest_push_mm)
    where = f"{lo:.0f} mm" if round(lo) == round(hi) else f"{lo:.0f}-{hi:.0f} mm"
    length = flare["params"].get("length_mm")
    decay = f" (its excess decays over {length:.0f} mm)" if length is not None else ""
    return [f"base_flare, {how} stiffens the cane toward its base{decay}; the canes' lowest pushes are {where} "
            f"along the cane: a neighbouring cane or stake touching it below them (a lateral spring support, not "
            f"in the library) changes their stiffness in much the same pattern"
            + (", and root_compliance beside the flare can match it" if root else "")
            + "; stiffness from pushes above both does not tell them apart, so look at the plants for such contact"]


def failure_reasons(adequacy: dict[str, Any]) -> list[str]:
    """Why the model fails its adequacy checks: one clause per check in ``adequacy["failed"]``.

    Each clause completes "the model ..." and says what the failed check means for the
    physics (it does not scale across canes, it leaves a cane's pushes scattered...), with
    the figures that decided it. Empty when every check passes.
    """
    failed = set(adequacy.get("failed") or ())
    alpha = adequacy.get("alpha")
    why: list[str] = []
    if "edge" in failed:
        why.append("needs " + ", ".join(f"{e['effect']} {e['parameter']} = {e['value']:.4g}"
                                        + (f" {e['unit']}" if e['unit'] not in ("", "1") else "")
                                        + f" (its physical range {e['low']:g} to {e['high']:g})"
                                        for e in adequacy["at_edge"])
                   + ", at the end of the range: the effect takes what it can of something it cannot be")
    if "trend" in failed:
        a = adequacy["after_cv"]
        why.append(f"does not scale across canes as the data do: the held-out residual "
                   f"{'falls' if a['r'] < 0 else 'rises'} with the model's stiffness level between canes "
                   f"(r = {a['r']:.2f}; the calipers' own error alone gives {a['null_median']:.2f}; "
                   f"p = {a['p']:.2g} < {alpha})")
    if "within" in failed:
        w = adequacy["within_after_cv"]
        why.append(f"does not share the stiffness along a cane as the data do: within canes the held-out "
                   f"residual {'falls' if w['r'] < 0 else 'rises'} with push height (r = {w['r']:.2f}, the "
                   f"calipers' error and trial noise alone give r within +-{2 * w['null_sd']:.2f}; p = "
                   f"{w['p']:.2g} < {alpha})")
    if "dispersion" in failed:
        d = adequacy["within_dispersion"]
        cut = adequacy["within_after_cv"].get("sd_trimmed_canes") or []
        why.append(f"leaves a cane's own pushes scattered about it: within canes the held-out residual "
                   f"spreads {d['sd']:.3f} in ln k"
                   + (f" (leaving out {_left_out(cut)})" if cut else "")
                   + f", {d['ratio']:.1f} times what the calipers' error alone gives "
                   f"({d['geometry_sd']:.3f}; the allowance, {d['factor']:.3g} times, is for the taper's shape "
                   f"below the calipers, which they do not see)")
    sh = adequacy.get("shape") or {}
    if "shape" in failed:
        why.append(f"bends the traces as they do not bend: it changes their stiffening over the push by "
                   f"{sh['predicted_mean']:+.3f} on average (spread {sh['predicted_spread']:.3f} across trials) "
                   f"and the traces show {sh['beta']:.2f} of that change (p = {sh['p']:.2g} < {alpha} "
                   f"against {sh['share']:.2g} of it)")
    if "shape_level" in failed:
        lv = sh["level"]
        why.append(f"does not bend the traces as they bend: over the push they "
                   f"{'soften' if lv['mean'] < 0 else 'stiffen'} by {abs(lv['mean']):.3f} more than it does, on "
                   f"average over {lv['n_canes']} canes (the allowance, {lv['excess']:.2g}, is for how a rig and an "
                   f"engine place contact; p = {lv['p']:.2g} < {alpha} beyond it)")
    return why


def _se_text(t: Mapping[str, Any]) -> str:
    """`` +- 17 %``: the standard error of ln omega from the test's sampling covariance (a relative
    error of omega), or ``""`` without one (discovery.json written before it)."""
    cov = t.get("cov_ln_median_ln_sd")
    return f" +- {100 * math.sqrt(cov[1][1]):.0f} %" if cov else ""
