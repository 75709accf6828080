"""The field traces' contacts, read once for a discovery (step 2 of :mod:`.workflow`).

Which trials a second body engages partway (an obstruction's elbow, :func:`field_onsets`); which
of those touch earlier than the field stage's contact knee, because the elbow pulled that knee
late (:func:`contacts_before_elbows`); which rise softly before their knee, and of those, which
are a contact before an obstruction and which the load cell drifting (:func:`early_contacts`,
:func:`split_early_contacts`). :func:`read_contacts` runs them in that order, then the field
stage again with the obstruction they name, so that an obstructed trial is scored up to its
elbow (an early contact's trial is not scored). No simulation: the screen's linear compliance is
the only model read.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from ..data.dataset import Trial
from ..data.rig import read_rig_csv
from ..errors import InputError
from ..execute.pipeline import SIM_TRAVEL_MM, field_stage
from ..measure.field import FieldFit, contact_samples, extract_field_stiffness
from ..model.config import ModelConfig
from ..model.effects import EffectSpec
from ..units import GF_TO_N
from .onsets import EarlyContact, Onset, detect_early_contact, detect_onset, ramp_is_the_cane
from .screen import trial_geometry

MIN_OBSTRUCTED = 1  # trials with a detected onset needed to name the obstruction


class Recontact(NamedTuple):
    """An obstructed trial's contact moved before the field stage's knee (:func:`contacts_before_elbows`)."""

    fit: FieldFit  #: the field fit of the record up to the elbow; its ``onset_mm`` is the contact
    record_end_mm: float  #: the elbow, mm of travel from the record's first sample: where it is cut

    @property
    def onset_mm(self) -> float:
        """The elbow, mm after the contact."""
        return self.record_end_mm - self.fit.onset_mm


def contacts_before_elbows(onsets: dict[str, float], fields: dict) -> dict[str, Recontact]:
    """The field fit of each obstructed trial's record up to its elbow, where that puts contact earlier.

    The field stage's contact knee is a flat-then-line hinge over the record until the force has
    risen 150 gf (:func:`~canebench.measure.field.extract_field_stiffness`). A soft cane's
    second body can engage within that: the one line then spans the cane's ramp and the steeper
    rise after the elbow, and the knee lands late, inside the ramp (an independent generator's
    softest obstructed trials, 0.02-0.04 N/mm: 6-10 mm late, and their onsets, counted from it,
    as much too early). Up to the elbow the record is flat, then the cane's line, and the same
    hinge finds the contact there. The elbow itself was found on the trace from the late knee,
    whose tare and origin were wrong: it is found again on the trace from the new contact
    (within the simulation's push, :data:`SIM_TRAVEL_MM`, as :func:`field_onsets` searches), and
    the record cut there is fitted once more (a self-test set's noisy 0.046 N/mm trial: the
    first cut kept three samples past the elbow, 0.072 N/mm; the second, one, 0.054 N/mm).
    Returned, by trial id, where the contact is at least one sample earlier than the knee and
    the record up to the elbow gives a usable slope. The obstruction effect then carries the cut
    (``record_end_mm``) with the onset counted from that contact, so every field stage of the
    run, the simulations' push lengths and the exported fits among them, reads the trial the
    same way.
    """
    out: dict[str, Recontact] = {}
    for tid, o in onsets.items():
        fr = fields[tid]
        rig = read_rig_csv(fr.trial.csv)

        def up_to(end: float) -> FieldFit:
            return extract_field_stiffness(rig.up_to(end), max_travel_mm=SIM_TRAVEL_MM)

        elbow = fr.fit.onset_mm + o  # from the record's first sample, as the knee
        ff = up_to(elbow)
        if not (ff.usable and ff.onset_mm < fr.fit.onset_mm - 0.25):
            continue
        x = rig.displacement_mm
        after = contact_samples(rig.force_gf, int(np.searchsorted(x, ff.onset_mm - 1e-9)))
        again = _elbow(x[after] - ff.onset_mm, (rig.force_gf[after] - ff.tare_gf) * GF_TO_N)
        if again is not None:
            ff2 = up_to(ff.onset_mm + again.onset_mm)
            if ff2.usable and ff2.onset_mm < fr.fit.onset_mm - 0.25:
                ff, elbow = ff2, ff.onset_mm + again.onset_mm
        out[tid] = Recontact(ff, elbow)
    return out


def early_contacts(fields: dict, knees: Mapping[str, float] | None = None) -> dict[str, EarlyContact]:
    """Soft contact ramps before the field stage's contact knee (:func:`onsets.detect_early_contact`),
    by trial id: candidates, which :func:`split_early_contacts` splits into contacts and drifts.

    ``knees`` (mm of travel from the record's first sample, by trial id) replaces a trial's knee:
    the contacts :func:`contacts_before_elbows` moved. Before the knee the field stage found, such
    a trial's ramp is the cane's own and the steeper rise after it the elbow (an independent
    generator's soft canes: two true obstructions were left out as early contacts, their onsets
    5-6 mm early, while the old knee was searched); before the moved contact, a ramp is what it
    is in any trial.
    """
    knees = knees or {}
    early = {}
    for tid, fr in fields.items():
        # (a trace fitted poorly as a whole is searched too: with an elbow it is scored up to it)
        if fr.fit is not None and fr.fit.rises and fr.trial.csv is not None and np.isfinite(fr.fit.onset_mm):
            rig = read_rig_csv(fr.trial.csv)
            e = detect_early_contact(rig.displacement_mm, rig.force_gf, knees.get(tid, fr.fit.onset_mm))
            if e is not None:
                early[tid] = e
    return early


def contact_levels(trials: list, geoms: dict, fields: dict,
                   exclude: set[str]) -> tuple[dict[str, float], dict[str, list[float]], list[float]]:
    """The model's stiffness per trial and the levels ln(k_field / k_model) an early contact is judged by.

    Returns k_model (N/mm, the baseline's linear compliance, :meth:`TrialGeometry.compliance`;
    NaN where that is not positive), each cane's ln ratios over its pushes with a usable slope
    outside ``exclude`` (pushes with an onset or a candidate of their own), and all of them pooled.
    """
    cane_of = {t.id: t.cane.id for t in trials}
    k_model = {tid: 1e-3 / c if (c := g.compliance()[0]) > 0 else math.nan for tid, g in geoms.items()}
    by_cane: dict[str, list[float]] = {}
    for tid, fr in fields.items():
        k = fr.k
        if tid in exclude or not (np.isfinite(k) and k > 0 and np.isfinite(k_model.get(tid, math.nan))):
            continue
        by_cane.setdefault(cane_of[tid], []).append(math.log(k / k_model[tid]))
    return k_model, by_cane, [v for vs in by_cane.values() for v in vs]


def split_early_contacts(early: dict, trials: list, geoms: dict, fields: dict,
                         onsets: dict) -> tuple[dict, dict]:
    """Split early-contact candidates into contacts (the ramp is the cane) and drifts.

    A candidate's levels are the median ln(k_field / k_model) of its cane's other pushes and of
    every push in the data (:func:`contact_levels`). It is a drift only when neither level puts
    the cane nearer the ramp's slope than the slope after the knee
    (:func:`onsets.ramp_is_the_cane`): a cane's other push can carry an elbow no test found (a
    self-test cane's did, 2.1 in ln above the model), and the data's median alone would ignore
    how much real canes differ from one another.
    """
    if not early:
        return early, {}
    cane_of = {t.id: t.cane.id for t in trials}
    k_model, by_cane, pooled = contact_levels(trials, geoms, fields, set(early) | set(onsets))
    kept, drifts = {}, {}
    for tid, e in early.items():
        levels = [float(np.median(v)) for v in (by_cane.get(cane_of[tid]), pooled) if v]
        k_m = k_model.get(tid, math.nan)  # NaN: no model of the trial (it is not scored): kept as is
        if not levels or not np.isfinite(k_m) or any(ramp_is_the_cane(e, k_m / GF_TO_N, lv) for lv in levels):
            kept[tid] = e
        else:
            drifts[tid] = e
    return kept, drifts


def _elbow(x_mm: np.ndarray, f_n: np.ndarray) -> Onset | None:
    """The elbow of a tared contact trace within the simulation's push (:data:`SIM_TRAVEL_MM`)."""
    within = x_mm <= SIM_TRAVEL_MM
    return detect_onset(x_mm[within], f_n[within])


def field_onsets(fields: dict) -> dict[str, float]:
    """Obstruction onsets (mm after contact) in the field traces, by trial id.

    Only the push the simulation makes is searched (its first :data:`SIM_TRAVEL_MM` of contact,
    the whole trace wherever contact ends within it, as every real trace does): an elbow past
    it changes no slope on either side, so it names nothing. Traces a straight line fits poorly
    are searched too: a strong elbow is what makes them so (the real b5c2t3's 27-fold one at
    37 mm leaves R^2 = 0.62). Up to its onset such a trace is scored like any other where it is
    a line there (those that are not are listed as not scored).
    """
    onsets: dict[str, float] = {}
    for tid, fr in fields.items():
        if fr.fit is not None and fr.fit.rises and fr.fit.displacement_mm is not None:
            o = _elbow(fr.fit.displacement_mm, fr.fit.force_n)
            if o is not None:
                onsets[tid] = o.onset_mm
    return onsets


@dataclass(frozen=True)
class FieldContacts:
    """What :func:`read_contacts` found, by trial id."""

    #: the field stage as the rig's records read, before any obstruction (the knees contacts are moved from)
    fields0: dict[str, Any]
    #: the field stage with :attr:`obstruction`: an obstructed trial scored up to its elbow
    fields: dict[str, Any]
    #: obstruction onsets, mm after contact (a moved contact's counted from it); early contacts left out
    onsets: dict[str, float]
    #: obstructed trials whose contact lies at least 0.25 mm before the field stage's knee (early contacts removed)
    recontact: dict[str, Recontact]
    #: soft contacts before an obstruction: such trials cannot be scored
    early: dict[str, EarlyContact]
    #: ramps before the knee read as the load cell drifting: scored as usual
    drifts: dict[str, EarlyContact]
    #: the baseline's configuration with the obstruction found (if any) as its only effect: the second
    #: field stage's, and the one the baseline engines run
    config: ModelConfig
    #: the screen's geometry of every trial (:func:`.screen.trial_geometry` on the base configuration),
    #: but one whose model cannot be built (its baseline run fails with the reason)
    geoms: dict[str, Any]
    #: seconds spent building :attr:`geoms`
    geometry_s: float

    @property
    def obstruction(self) -> tuple[EffectSpec, ...]:
        """The per-trial obstruction effect, or ``()`` when fewer than :data:`MIN_OBSTRUCTED` trials have an onset.

        It is :attr:`config`'s effects, read from there so the two cannot disagree.
        """
        return self.config.effects


def read_contacts(trials: list[Trial], fit_window_mm: float, cfg0: ModelConfig) -> FieldContacts:
    """Read every trace's contacts and fit each obstructed trial up to its elbow (the module docstring).

    Parameters
    ----------
    trials : list of Trial
    fit_window_mm : float
        The protocol's field fit window (:attr:`.probe.protocol.Protocol.fit_window_mm`).
    cfg0 : ModelConfig
        The baseline's configuration: its geometry tells a drift from a contact, and the
        second field stage runs it with the obstruction found as its effects.
    """
    fields0 = field_stage(trials, fit_window_mm)
    onsets = field_onsets(fields0)
    # a knee pulled late by an elbow inside its search: onset and field fit from the record up to
    # the elbow (the ramp before that knee is the cane's own, not an early contact)
    recontact = contacts_before_elbows(onsets, fields0)
    # a soft contact the field stage took for the tare: its knee is the obstruction's onset, and
    # its stiffness the obstruction's; such trials cannot be scored and are left out of the fit
    early = early_contacts(fields0, knees={k: rc.fit.onset_mm for k, rc in recontact.items()})
    t_g = time.perf_counter()  # the screen's geometry, needed here to tell a drift from a contact
    geoms = {}
    for t in trials:
        try:
            geoms[t.id] = trial_geometry(t, cfg0)
        except InputError:
            # no model of this trial can be built (calipers whose line gives no cane at the push): it has
            # no geometry here; its baseline run fails at the chain with the same reason, which the trial
            # table gives as why it is not scored
            pass
    geometry_s = time.perf_counter() - t_g
    early, drifts = split_early_contacts(early, trials, geoms, fields0, onsets)
    for tid in early:
        onsets.pop(tid, None)
        recontact.pop(tid, None)
    for tid, rc in recontact.items():
        onsets[tid] = rc.onset_mm
    obstruction: tuple[EffectSpec, ...] = ()
    if len(onsets) >= MIN_OBSTRUCTED:
        # a moved contact's trial carries the record's cut, so every field stage reads it alike
        obstruction = (EffectSpec("obstruction", (), tuple(sorted(
            (k, (("onset_mm", v),) + ((("record_end_mm", recontact[k].record_end_mm),) if k in recontact else ()))
            for k, v in onsets.items())), "per_trial"),)
    config = cfg0.replace(effects=obstruction)
    fields = field_stage(trials, fit_window_mm, config)
    return FieldContacts(fields0, fields, onsets, recontact, early, drifts, config, geoms, geometry_s)
