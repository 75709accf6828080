"""Write a set of exported canes (or a population) and its manifest.

Layout of the output folder::

    mjcf/<name>.xml                      MuJoCo (MjSpec)
    sdf/<name>.sdf                       SDFormat 1.7
    urdf/<name>.urdf, <name>.springs.yaml  URDF + joint-spring sidecar
    manifest.csv, manifest.json          one row per exported chain

``<name>`` is ``<cane>_p<push point>`` (``_d<draw>`` appended in a
population). The manifest has no time stamp: the same inputs and seed give
byte-identical files.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable

import pandas as pd

from ..data.cane import CaneDescription
from ..errors import InputError
from ..model.chain import Chain, build_chain
from ..model.config import ModelConfig
from .common import chain_info

FORMATS = ("mjcf", "sdf", "urdf")


def parse_formats(spec: str | Iterable[str]) -> tuple[str, ...]:
    """``"mjcf,sdf"`` -> ``("mjcf", "sdf")``; unknown names are an input error naming the known ones."""
    names = [s.strip().lower() for s in (spec.split(",") if isinstance(spec, str) else spec) if s.strip()]
    if not names:
        raise InputError("--format", "format", f"no format given; known: {', '.join(FORMATS)}")
    bad = [n for n in names if n not in FORMATS]
    if bad:
        import difflib

        close = difflib.get_close_matches(bad[0], FORMATS, n=1)
        raise InputError("--format", "format", f"unknown export format {bad[0]!r}"
                         + (f"; did you mean {close[0]!r}?" if close else "") + f" (known: {', '.join(FORMATS)})")
    return tuple(dict.fromkeys(names))


def _k_linear(chain: Chain) -> float:
    """Small-deflection probe stiffness (N/m) of the chain, from the Pinocchio backend's formula."""
    try:
        from canebench.backends.pinocchio_backend import rest_linear_stiffness
    except Exception:  # Pinocchio not installed: the manifest says nan
        return math.nan
    return rest_linear_stiffness(chain)


def export_chain(chain: Chain, out: Path, name: str, formats: tuple[str, ...],
                 meta: dict[str, Any] | None = None) -> dict[str, str]:
    """Write ``chain`` in every format under ``out``; return {format: relative path(s)}."""
    files: dict[str, str] = {}
    for fmt in formats:
        d = out / fmt
        d.mkdir(parents=True, exist_ok=True)
        if fmt == "mjcf":
            from .mjcf import write_mjcf

            files["mjcf"] = str(write_mjcf(chain, d / f"{name}.xml", meta, name=name).relative_to(out))
        elif fmt == "sdf":
            from .sdf import write_sdf

            files["sdf"] = str(write_sdf(chain, d / f"{name}.sdf", name, meta).relative_to(out))
        elif fmt == "urdf":
            from .urdf import write_urdf

            u, s = write_urdf(chain, d / f"{name}.urdf", name, meta)
            files["urdf"], files["springs"] = str(u.relative_to(out)), str(s.relative_to(out))
    return files


@dataclass
class ExportResult:
    out: Path
    manifest: pd.DataFrame
    wall_s: float
    header: dict[str, Any] = field(default_factory=dict)

    def to_df(self) -> pd.DataFrame:
        return self.manifest


def _row(chain: Chain, name: str, files: dict[str, str], draw: dict[str, Any] | None) -> dict[str, Any]:
    info = chain_info(chain)
    row: dict[str, Any] = {"name": name, "cane": info["cane"], "push_point": info["push_point"]}
    if draw:
        row.update({k: draw[k] for k in ("draw", "seed", "distribution")})
    row["modulus_pa"] = chain.modulus
    row["diameter_factor"] = (info["config"] or {}).get("diameter_factor")
    if draw:
        row.update({k: draw[k] for k in ("caliper_sd_m", "caliper_scales", "diameter_scale_mean")})
        # an effect drawn from its spread between canes: one column per parameter, e.g. root_compliance.k_root
        row.update({f"{e}.{p}": v for e, ps in draw.get("effects_drawn", {}).items() for p, v in ps.items()})
    row.update({"n_links": chain.n_links, "n_joints": chain.n_dof, "k_linear_N_per_mm": _k_linear(chain) * 1e-3,
                "chain_fingerprint": info["chain_fingerprint"], **{f"file_{k}": v for k, v in files.items()},
                "synthetic": info["synthetic"], "assumptions": "; ".join(info["assumptions"]),
                "canebench_version": info["canebench_version"]})
    return row


def _write_manifest(out: Path, rows: list[dict[str, Any]], header: dict[str, Any]) -> pd.DataFrame:
    df = pd.DataFrame(rows)
    flat = df.copy()
    for col in flat.columns:  # lists as ';'-joined text in the CSV
        if flat[col].map(lambda v: isinstance(v, list)).any():
            flat[col] = flat[col].map(lambda v: ";".join(repr(float(x)) for x in v) if isinstance(v, list) else v)
    flat.to_csv(out / "manifest.csv", index=False)
    (out / "manifest.json").write_text(json.dumps({**header, "rows": rows}, indent=1, default=str) + "\n")
    return df


def export_set(items: list[tuple[CaneDescription, str, ModelConfig, dict[str, Any] | None]], out: str | Path,
               formats: Iterable[str] = FORMATS, header: dict[str, Any] | None = None,
               progress: Callable[[int, int], None] | None = None) -> ExportResult:
    """Export every (cane, push point id, configuration, draw record or None) and write the manifest."""
    from .. import __version__

    t0 = time.perf_counter()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    formats = parse_formats(formats)
    rows = []
    for i, (cane, push, cfg, draw) in enumerate(items):
        chain = build_chain(cane, push, cfg)
        name = f"{cane.id}_p{push}" + (f"_d{draw['draw']:04d}" if draw else "")
        meta = {"draw": draw} if draw else None
        files = export_chain(chain, out, name, formats, meta)
        rows.append(_row(chain, name, files, draw))
        if progress:
            progress(i + 1, len(items))
    head = {"canebench_version": __version__, "command": "canebench export", "formats": list(formats),
            "layout": "mjcf/<name>.xml, sdf/<name>.sdf, urdf/<name>.urdf + urdf/<name>.springs.yaml",
            **(header or {})}
    df = _write_manifest(out, rows, head)
    return ExportResult(out, df, time.perf_counter() - t0, head)


def export_canes(selection: list[tuple[CaneDescription, str]], config: ModelConfig, out: str | Path,
                 formats: Iterable[str] = FORMATS, **kw: Any) -> ExportResult:
    """One chain per (cane, push point id) under ``config``."""
    return export_set([(c, p, config, None) for c, p in selection], out, formats,
                      {"config": config.to_dict()}, **kw)


def export_population(selection: list[tuple[CaneDescription, str]], config: ModelConfig, out: str | Path, n: int,
                      seed: int, distribution: str = "all", formats: Iterable[str] = FORMATS,
                      caliper_sd_m: float | None = None, **kw: Any) -> ExportResult:
    """``n`` drawn canes (see :mod:`canebench.export.population`) and their manifest."""
    from .population import DEFAULT_CALIPER_SD_M, WHAT_IS_DRAWN, draw_population, get_distribution

    sd = DEFAULT_CALIPER_SD_M if caliper_sd_m is None else caliper_sd_m
    formats = parse_formats(formats)  # before any work
    draws = draw_population(selection, config, n, seed, distribution, sd)
    header = {"population": int(n), "seed": int(seed), "distribution": get_distribution(distribution).to_dict(),
              "caliper_sd_m": sd, "what_is_drawn": WHAT_IS_DRAWN,
              "selection": [f"{c.id}_p{p}" for c, p in selection], "config": config.to_dict()}
    return export_set([(d.cane, d.push_id, d.config, d.record) for d in draws], out, formats, header, **kw)


def select(trials: list, by_trial: bool, push: str | None = None) -> list[tuple[CaneDescription, str]]:
    """(cane, push point id) pairs from dataset trials: each trial's own push point
    (``by_trial``) or, once per cane, push point ``push`` (default: the cane's first)."""
    if by_trial:
        return [(t.cane, t.push_id) for t in trials]
    out, seen = [], set()
    for t in trials:
        c = t.cane
        if c.id in seen:
            continue
        seen.add(c.id)
        if push is None:
            out.append((c, c.push_points[0].id))
        else:
            c.push_point(str(push))  # raises naming the cane's file when it has no such push point
            out.append((c, str(push)))
    return out
