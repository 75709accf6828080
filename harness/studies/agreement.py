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
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import combinations
from pathlib import Path

import numpy as np
import pandas as pd

REFERENCE = "pinocchio"
TOL_REFERENCE = {"mujoco": 5e-3, "dart": 5e-3, "exudyn": 5e-3, "pybullet": 1e-2}
TOL_REFERENCE_DEFAULT = 5e-3
TOL_BASELINE = 1e-3


def baseline_path(protocol: str = "fast") -> Path:
    from canebench import reports

    return Path(reports.__file__).resolve().parent / "baselines" / f"agreement_{protocol}.csv"


def agreement_table(results: pd.DataFrame, reference: str = REFERENCE) -> pd.DataFrame:
    """Per trial and backend: k_sim, the reference's k and their relative difference."""
    ref = results[results.backend == reference].set_index("trial")["k_sim"]
    cols = ["trial", "backend", "answer", "protocol", "k_sim", "status", "reason", "wall_s", "n_links"]
    out = results[[c for c in cols if c in results.columns]].copy()
    out["k_ref"] = out.trial.map(ref)
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
        tol = TOL_REFERENCE.get(r.backend, TOL_REFERENCE_DEFAULT)
        if r.backend != REFERENCE and not (abs(r.rel_to_ref) <= tol):
            rows.append({"trial": r.trial, "backend": r.backend, "check": f"vs {REFERENCE}",
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


@dataclass
class AgreementResult:
    """What ``canebench agree`` measured: the matrix, the pairs, the gate and the run behind them."""

    table: pd.DataFrame
    pairs: pd.DataFrame
    gate: GateResult | None
    outcome: object  # RunOutcome
    baseline_path: Path
    baseline_found: bool

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
        table[["trial", "backend", "protocol", "k_sim", "status", "reason"]].to_csv(bpath, index=False)
        return AgreementResult(table, pairs, None, outcome, bpath, True)
    base = pd.read_csv(bpath) if bpath.exists() else None
    gate = check(table, base)
    gate.violations.to_csv(out / "violations.csv", index=False)
    return AgreementResult(table, pairs, gate, outcome, bpath, base is not None)
