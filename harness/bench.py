"""Benchmark: the paper protocol (40 kHz) against the fast one, same process.

Prints, per trial and backend, the stiffness from each protocol, their
relative difference and the difference from the Pinocchio static answer, and
the speed-up as a ratio of wall times measured in this run (no absolute
timing is asserted anywhere).
"""

from __future__ import annotations

import pandas as pd

from .chain import build_chain
from .config import ModelConfig
from .dataset import bundled_dataset, load_dataset
from .probe import run_probe
from .protocol import PROTOCOLS
from .registry import get_backend
from .run import field_fit_for


def bench_protocols(trials: str = "b1c1t1,b1c2t1,b3c1t2", backends: list[str] | None = None,
                    steps: int | None = None, config: ModelConfig | None = None) -> pd.DataFrame:
    config = config or ModelConfig()
    backends = backends or ["mujoco"]
    ref = get_backend("pinocchio")
    rows = []
    for t in load_dataset(bundled_dataset(), trials):
        chain = build_chain(t.cane, t.push_id, config)
        ff = field_fit_for(t)
        n = min(PROTOCOLS["paper"].max_steps, ff.n_steps if ff else 90, steps or 90)
        k_ref = run_probe(ref, chain, PROTOCOLS["fast"], n).fit().slope
        for b in backends:
            be = get_backend(b)
            out = {}
            for pname in ("paper", "fast"):
                tr = run_probe(be, chain, PROTOCOLS[pname], n)
                fit = tr.fit()
                out[pname] = (fit.slope if fit else float("nan"), tr.wall_s, tr.status)
            row = {
                "trial": t.id, "backend": b, "links": chain.n_links, "steps": n,
                "k_paper_N/mm": out["paper"][0] * 1e-3, "k_fast_N/mm": out["fast"][0] * 1e-3,
                "fast_vs_paper": out["fast"][0] / out["paper"][0] - 1,
                "paper_vs_pin": out["paper"][0] / k_ref - 1, "fast_vs_pin": out["fast"][0] / k_ref - 1,
                "wall_paper_s": out["paper"][1], "wall_fast_s": out["fast"][1],
                "speedup": out["paper"][1] / out["fast"][1],
            }
            rows.append(row)
            print(f"{t.id:8s} {b:8s} links={chain.n_links:2d} steps={n:2d}  k_paper={row['k_paper_N/mm']:.5g}  "
                  f"k_fast={row['k_fast_N/mm']:.5g} N/mm  fast/paper-1={row['fast_vs_paper']:+.2e}  "
                  f"paper/pin-1={row['paper_vs_pin']:+.2e}  fast/pin-1={row['fast_vs_pin']:+.2e}  "
                  f"speed-up x{row['speedup']:.1f}", flush=True)
    df = pd.DataFrame(rows)
    if len(df):
        tot = df.groupby("backend")[["wall_paper_s", "wall_fast_s"]].sum()
        for b, r in tot.iterrows():
            print(f"{b}: total paper/fast wall-time ratio x{r.wall_paper_s / r.wall_fast_s:.1f}; "
                  f"max |fast/paper-1| = {df[df.backend == b].fast_vs_paper.abs().max():.2e}")
    return df
