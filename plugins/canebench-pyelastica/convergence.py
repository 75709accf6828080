"""Convergence of the PyElastica plugin: stiffness against element count on the
two straight cantilevers (closed forms, reference-values sec. 1) and on the
bundled canes (against canebench's beam), probed like ``canebench converge``
probes the other continuum engines (fast protocol, 4 samples, gravity off).

    python plugins/canebench-pyelastica/convergence.py [--trials GLOBS] [--elements 10,20,40] [--out FILE.csv]

Needs the plugin and pyelastica installed (``pip install ./plugins/canebench-pyelastica``).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import pandas as pd

from canebench.backends.beam_backend import BeamBackend
from canebench.data.dataset import bundled_dataset, load_dataset
from canebench.model.chain import build_chain
from canebench.model.config import ModelConfig
from canebench.probe.driver import run_probe
from canebench.probe.protocol import PROTOCOLS
from canebench.studies.convergence import CANTILEVERS, CONTINUUM_STEPS, cantilever_stiffness, straight_cantilever
from canebench_pyelastica import PyElasticaBackend


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--trials", default="*")
    ap.add_argument("--elements", default="10,20,40")
    ap.add_argument("--cantilever-elements", default="10,20,40,80")
    ap.add_argument("--out", default="pyelastica_convergence.csv")
    a = ap.parse_args()
    proto, cfg = PROTOCOLS["fast"], ModelConfig(gravity=0.0)
    cases = [(c, straight_cantilever(c.startswith("tapered")), "tip") for c in CANTILEVERS]
    cases += [(t.id, t.cane, t.push_id) for t in load_dataset(bundled_dataset(), a.trials)]
    rows = []
    for tid, cane, pid in cases:
        chain = build_chain(cane, pid, cfg)
        cant = tid in CANTILEVERS
        k_ref = (cantilever_stiffness(tid.startswith("tapered")) if cant
                 else run_probe(BeamBackend(), chain, proto, CONTINUUM_STEPS).fit().slope)
        for n in map(int, (a.cantilever_elements if cant else a.elements).split(",")):
            t0 = time.perf_counter()
            tr = run_probe(PyElasticaBackend(n), chain, proto, CONTINUUM_STEPS)
            k = tr.fit().slope if tr.status == "ok" else np.nan
            rows.append({"trial": tid, "elements": n, "k": k, "k_ref": k_ref, "reference": "closed form" if cant
                         else "beam", "rel_error": k / k_ref - 1, "status": tr.status, "reason": tr.reason,
                         "relaxation_steps": tr.extras.get("relaxation_steps"), "wall_s": time.perf_counter() - t0})
            print(f"{tid:20s} {n:3d}  {rows[-1]['rel_error']:+.3e}  {rows[-1]['wall_s']:.2f} s", flush=True)
    df = pd.DataFrame(rows)
    df.to_csv(a.out, index=False)
    canes = df[~df.trial.isin(CANTILEVERS)]
    print(canes.groupby("elements").rel_error.agg(["median", lambda e: e.abs().max(), "count"])
          .rename(columns={"<lambda_0>": "worst |error|"}).to_string())


if __name__ == "__main__":
    main()
