"""Cross-engine agreement and its regression gate.

``agreement_table`` turns a results table into the agreement matrix: per
trial and backend, the stiffness relative to the Pinocchio static answer of
the same chain (the exact answer every dynamic engine must converge to).
``pairwise`` summarises every pair of backends by the median and worst
absolute log ratio. ``check`` compares a fresh matrix with a committed
baseline and with Pinocchio and lists every violation.

Tolerances (relative stiffness):

* against Pinocchio: 0.5 % for MuJoCo, DART and Exudyn, 1 % for PyBullet (the
  issue's acceptance bounds); measured agreement is 10x tighter, so a breach
  means a modelling or integration error, not noise;
* against the baseline: 0.1 %. Every engine is deterministic on one machine
  (identical reruns), so 0.1 % only absorbs platform round-off; a modelling
  change of one part in a thousand shows up.

Continuum engines (backends tagged ``continuum``: ``mujoco_rod``,
``exudyn_beam``, plugins such as ``pyelastica``) do not simulate the chain,
so Pinocchio's chain answer is not theirs: they are compared with the
``beam`` reference (the geometrically exact rod of the same continuum, added
to the run whenever a continuum engine is), with their own tolerances. Each
is the sum of two measured parts, rounded up to two digits:

* the engine's discretization error against the beam at its default mesh,
  worst over the 54 bundled canes (``canebench converge``: small push,
  gravity off; README "Continuum engines"): ``mujoco_rod`` (40 elements)
  1.84e-3, second order (7.8e-3 at 20, 5.7e-4 at 80); ``exudyn_beam`` (20
  elements) 0.97e-3, which no longer changes with the mesh (0.96e-3 and
  0.97e-3 at 40 and 80): the shear and extension of the physical section in Exudyn's
  Timoshenko element, which the Kirchhoff reference does not have (with EA
  and GA 100 times stiffer the b1c1t1 gap falls from 3e-4 to 3e-5);
* the fit-window effect of a dynamic probe against a static answer: the PI
  law lags a stiff cane, so a dynamic engine's samples span a shorter
  displacement range than the static sweep's, and on a curved force curve
  the two slopes differ. It is the chain engines' whole difference from
  Pinocchio on the committed baseline (worst 1.18e-3, DART on b1c2t2; MuJoCo
  1.13e-3 there); on b1c2t2 the continuum engines' force at their own
  displacements is within 4.9e-4 (Exudyn) and 9.8e-4 (MuJoCo) of the
  beam's, while their slopes differ by 2.1e-3 and 2.4e-3.

So ``mujoco_rod`` 3.1e-3 (1.84e-3 + 1.18e-3) and ``exudyn_beam`` 2.2e-3
(0.97e-3 + 1.18e-3); measured on the full gate: 2.40e-3 and 2.14e-3 worst,
1.38e-3 and 0.60e-3 median. Other continuum engines: 1 % unless listed.

The beam itself is the continuum reference and is checked against the
baseline only.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import combinations
from pathlib import Path

import numpy as np
import pandas as pd

REFERENCE = "pinocchio"
#: the reference of continuum engines (they do not simulate the chain)
CONTINUUM_REFERENCE = "beam"
TOL_REFERENCE = {"mujoco": 5e-3, "dart": 5e-3, "exudyn": 5e-3, "pybullet": 1e-2,
                 "mujoco_rod": 3.1e-3, "exudyn_beam": 2.2e-3}
TOL_REFERENCE_DEFAULT = 5e-3
TOL_CONTINUUM_DEFAULT = 1e-2
TOL_BASELINE = 1e-3
#: built-in continuum engines, known without asking the registry (a plugin is recognised by its "continuum" tag)
CONTINUUM_BACKENDS = {"mujoco_rod", "exudyn_beam"}


def is_continuum(backend: str) -> bool:
    """True for an engine of the cane's continuum (not the chain), other than the beam reference itself."""
    if backend == CONTINUUM_REFERENCE:
        return False
    if backend in CONTINUUM_BACKENDS:
        return True
    try:
        import warnings

        from canebench.registry import discover

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            reg = discover()
        return backend in reg and "continuum" in reg[backend].tags
    except Exception:  # pragma: no cover - a broken registry leaves the chain reference
        return False


def reference_of(backend: str) -> str:
    """The backend whose stiffness ``backend`` is checked against (itself for the two references)."""
    if backend == CONTINUUM_REFERENCE:
        return CONTINUUM_REFERENCE
    return CONTINUUM_REFERENCE if is_continuum(backend) else REFERENCE


def tolerance_of(backend: str) -> float:
    if backend in TOL_REFERENCE:
        return TOL_REFERENCE[backend]
    return TOL_CONTINUUM_DEFAULT if is_continuum(backend) else TOL_REFERENCE_DEFAULT


def baseline_path(protocol: str = "fast") -> Path:
    from canebench import reports

    return Path(reports.__file__).resolve().parent / "baselines" / f"agreement_{protocol}.csv"


def agreement_table(results: pd.DataFrame, reference: str = REFERENCE) -> pd.DataFrame:
    """Per trial and backend: k_sim, its reference's k and their relative difference.

    The reference is ``reference`` (Pinocchio) for chain engines and
    :data:`CONTINUUM_REFERENCE` (the beam) for continuum engines (column
    ``reference``)."""
    cols = ["trial", "backend", "answer", "protocol", "k_sim", "status", "reason", "wall_s", "n_links"]
    out = results[[c for c in cols if c in results.columns]].copy()
    out["reference"] = [CONTINUUM_REFERENCE if reference_of(b) == CONTINUUM_REFERENCE else reference
                        for b in out.backend]
    k = results.set_index(["trial", "backend"])["k_sim"]
    k = k[~k.index.duplicated()]
    out["k_ref"] = [k.get((tr, ref), np.nan) for tr, ref in zip(out.trial, out.reference)]
    out["rel_to_ref"] = out.k_sim / out.k_ref - 1.0
    return out.reset_index(drop=True)


def pairwise(results: pd.DataFrame) -> pd.DataFrame:
    """Median and worst |ln(k_a / k_b)| over trials where both succeeded."""
    k = results[results.status.isin(["ok", "unscored"])].pivot(index="trial", columns="backend", values="k_sim")
    rows = []
    for a, b in combinations(sorted(k.columns), 2):
        lr = np.log(k[a] / k[b]).dropna()
        rows.append({"backend_a": a, "backend_b": b, "n": len(lr),
                     "median_abs_log_ratio": float(lr.abs().median()) if len(lr) else np.nan,
                     "max_abs_log_ratio": float(lr.abs().max()) if len(lr) else np.nan})
    return pd.DataFrame(rows)


@dataclass
class GateResult:
    violations: pd.DataFrame

    @property
    def ok(self) -> bool:
        return self.violations.empty


def check(table: pd.DataFrame, baseline: pd.DataFrame | None) -> GateResult:
    """Every (trial, backend) that failed, left its reference tolerance or
    drifted from the baseline."""
    rows = []
    base = None if baseline is None else baseline.set_index(["trial", "backend"])
    for r in table.itertuples():
        good = r.status in ("ok", "unscored")
        key = (r.trial, r.backend)
        in_base = base is not None and key in base.index
        if not good:
            # a failure is only accepted if the baseline records the same failure
            if not (in_base and base.loc[key, "status"] == r.status):
                rows.append({"trial": r.trial, "backend": r.backend, "check": "status", "value": np.nan,
                             "tolerance": np.nan, "detail": f"{r.status}: {r.reason}"})
            continue
        tol = tolerance_of(r.backend)
        ref = getattr(r, "reference", REFERENCE)
        if r.backend not in (REFERENCE, CONTINUUM_REFERENCE) and not (abs(r.rel_to_ref) <= tol):
            rows.append({"trial": r.trial, "backend": r.backend, "check": f"vs {ref}",
                         "value": r.rel_to_ref, "tolerance": tol, "detail": f"k={r.k_sim:.6g} ref={r.k_ref:.6g}"})
        if in_base:
            kb = base.loc[key, "k_sim"]
            drift = r.k_sim / kb - 1.0 if kb == kb else np.nan
            if not (abs(drift) <= TOL_BASELINE):
                rows.append({"trial": r.trial, "backend": r.backend, "check": "vs baseline", "value": drift,
                             "tolerance": TOL_BASELINE, "detail": f"k={r.k_sim:.6g} baseline={kb:.6g}"})
        elif base is not None:
            rows.append({"trial": r.trial, "backend": r.backend, "check": "vs baseline", "value": np.nan,
                         "tolerance": TOL_BASELINE, "detail": "not in the baseline"})
    cols = ["trial", "backend", "check", "value", "tolerance", "detail"]
    return GateResult(pd.DataFrame(rows, columns=cols))


BASELINE_COLUMNS = ["trial", "backend", "protocol", "k_sim", "status", "reason"]


def write_baseline(table: pd.DataFrame, path: Path) -> pd.DataFrame:
    """Merge ``table`` into the baseline at ``path``: its (trial, backend) rows replace the
    baseline's, every other baseline row is kept as it is (so running the new backends
    alone adds their rows without touching the others). Returns the rows of the
    existing baseline whose values this run changed (empty when only rows were added)."""
    new = table[BASELINE_COLUMNS].copy()
    changed = pd.DataFrame(columns=BASELINE_COLUMNS)
    if path.exists():
        old = pd.read_csv(path, keep_default_na=False, na_values=[""], dtype={"reason": str})
        key_old = list(zip(old.trial, old.backend))
        fresh = new.set_index(["trial", "backend"])
        both = [k for k in key_old if k in fresh.index]
        if both:
            o = old.set_index(["trial", "backend"]).loc[both]
            f = fresh.loc[both]
            diff = (o.k_sim != f.k_sim) & ~(o.k_sim.isna() & f.k_sim.isna()) | (o.status != f.status)
            changed = o[diff].reset_index()
        keep = old[[k not in fresh.index for k in key_old]]
        order = {k: i for i, k in enumerate(key_old)}
        merged = pd.concat([keep, new], ignore_index=True)
        # existing rows stay where they were; new rows follow, by trial and backend
        merged["_o"] = [order.get(k, len(order)) for k in zip(merged.trial, merged.backend)]
        merged = merged.sort_values(["_o", "trial", "backend"], kind="stable").drop(columns="_o")
    else:
        merged = new
    merged.to_csv(path, index=False)
    return changed


@dataclass
class AgreementResult:
    """What ``canebench agree`` measured: the matrix, the pairs, the gate and the run behind them."""

    table: pd.DataFrame
    pairs: pd.DataFrame
    gate: GateResult | None
    outcome: object  # RunOutcome
    baseline_path: Path
    baseline_found: bool
    baseline_changed: pd.DataFrame | None = None  # --update-baseline: existing rows whose values changed

    def to_df(self) -> pd.DataFrame:
        return self.table

    @property
    def passed(self) -> bool:
        return self.gate is not None and self.gate.ok


def run_agreement(trials: list, backends: list[str], protocol: object, out: Path, executor: object = None,
                  baseline: Path | None = None, update_baseline: bool = False, **run_kw: object) -> AgreementResult:
    """Probe ``trials`` on ``backends`` (Pinocchio added as the reference) and check the gate.

    Writes ``agreement.csv``, ``pairwise.csv`` and ``violations.csv`` into
    ``out`` beside the run's own exports; with ``update_baseline`` writes the
    baseline instead of checking it.
    """
    from ..execute.pipeline import field_stage, make_jobs
    from ..execute.runner import run_jobs
    from ..model.config import ModelConfig

    if REFERENCE not in backends:
        backends = [*backends, REFERENCE]
    if any(is_continuum(b) for b in backends) and CONTINUUM_REFERENCE not in backends:
        backends = [*backends, CONTINUUM_REFERENCE]
    fields = field_stage(trials, protocol.fit_window_mm)
    outcome = run_jobs(make_jobs(trials, backends, protocol, ModelConfig(), fields), out, executor, fields=fields,
                       **run_kw)
    bpath = Path(baseline) if baseline else baseline_path(protocol.name)
    table = agreement_table(outcome.results) if len(outcome.results) else pd.DataFrame()
    pairs = pairwise(outcome.results) if len(outcome.results) else pd.DataFrame()
    if outcome.interrupted:
        return AgreementResult(table, pairs, None, outcome, bpath, bpath.exists())
    table.to_csv(out / "agreement.csv", index=False)
    pairs.to_csv(out / "pairwise.csv", index=False)
    if update_baseline:
        bpath.parent.mkdir(parents=True, exist_ok=True)
        changed = write_baseline(table, bpath)
        return AgreementResult(table, pairs, None, outcome, bpath, True, changed)
    base = pd.read_csv(bpath) if bpath.exists() else None
    gate = check(table, base)
    gate.violations.to_csv(out / "violations.csv", index=False)
    return AgreementResult(table, pairs, gate, outcome, bpath, base is not None)
