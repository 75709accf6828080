"""``canebench export``: canes (or a drawn population) as MJCF, SDF and URDF + spring sidecar."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from ..errors import InputError

from . import common


def add_parser(sub: argparse._SubParsersAction) -> None:
    e = sub.add_parser("export", help="write canes' chains as MJCF, SDF, URDF (+ joint-spring sidecar); populations")
    e.add_argument("--field", help="dataset directory (push_points.csv + trials/); default: bundled synthetic set")
    sel = e.add_mutually_exclusive_group()
    sel.add_argument("--trials", help="comma-separated globs on trial ids: one chain per trial, probed at its push "
                                      "point")
    sel.add_argument("--canes", help="comma-separated globs on cane ids: one chain per cane (default: every cane)")
    e.add_argument("--push", help="push point id for the probe site with --canes (default: each cane's first)")
    e.add_argument("--format", default="mjcf,sdf,urdf", help="comma-separated: mjcf, sdf, urdf (default: all)")
    e.add_argument("--out", help="output folder (default canebench-runs/export-<time>)")
    common.add_model_options(e)
    e.add_argument("--segments", help="shorthand for --set segments=N")
    e.add_argument("--stiffness-formula", help="shorthand for --set stiffness_formula=NAME")
    e.add_argument("--modulus", help="shorthand for --set modulus_pa=PA")
    g = e.add_argument_group("population")
    g.add_argument("--population", metavar="N", help="draw N canes (modulus and caliper diameters; see README)")
    g.add_argument("--seed", default="0", help="seed of the population (default 0)")
    g.add_argument("--distribution", default=None, help="named modulus distribution (default: all)")
    g.add_argument("--caliper-sd-mm", default=None, help="caliper reading noise sd in mm (default 0.15)")
    e.add_argument("--strict", action="store_true", help="treat input warnings as errors")
    e.set_defaults(fn=main)


def _int(value: str, flag: str, low: int) -> int:
    try:
        v = int(str(value).strip())
    except ValueError:
        raise InputError(flag, flag.lstrip("-"), f"must be a whole number, got {value!r}") from None
    if v < low:
        raise InputError(flag, flag.lstrip("-"), f"must be >= {low}, got {v}")
    return v


def config(a: argparse.Namespace) -> Any:
    """The model configuration: --model FILE or --preset, then --set, then the shorthands."""
    short = {key: getattr(a, flag) for flag, key in (("segments", "segments"), ("stiffness_formula",
             "stiffness_formula"), ("modulus", "modulus_pa")) if getattr(a, flag) is not None}
    cfg = common.model_config(a)
    return cfg.with_overrides(short) if short else cfg


def main(a: argparse.Namespace) -> int:
    from ..data.dataset import bundled_dataset, load_dataset
    from ..export.bundle import export_canes, export_population, parse_formats, select
    from ..export.population import get_distribution

    common.input_warnings(a.strict)
    # every argument is checked before any folder is made or file written
    formats = parse_formats(a.format)
    population = None if a.population is None else _int(a.population, "--population", 1)
    if population is None and (a.distribution or a.caliper_sd_mm):
        raise InputError("--distribution", "population", "--distribution and --caliper-sd-mm need --population N")
    if population is not None and a.modulus is not None:
        raise InputError("--modulus", "population", "a population draws the modulus from --distribution")
    if a.push is not None and a.trials:
        raise InputError("--push", "push", "--trials already names each push point; use --push with --canes")
    seed, sd, dist = _int(a.seed, "--seed", 0), None, a.distribution or "all"
    get_distribution(dist)
    if a.caliper_sd_mm is not None:
        try:
            sd = float(a.caliper_sd_mm) * 1e-3
        except ValueError:
            raise InputError("--caliper-sd-mm", "caliper_sd", f"not a number: {a.caliper_sd_mm!r}") from None
    cfg = config(a)
    data_dir = Path(a.field) if a.field else bundled_dataset()
    trials = load_dataset(data_dir, a.trials or a.canes)
    selection = select(trials, by_trial=bool(a.trials), push=a.push)
    out = common.out_dir(a.out, "export")
    if population is None:
        res = export_canes(selection, cfg, out, formats)
        what = f"{len(selection)} chain(s)"
    else:
        res = export_population(selection, cfg, out, population, seed, dist, formats, caliper_sd_m=sd)
        what = f"population of {population} from {len(selection)} cane(s), seed {seed}, distribution {dist}"
    print(f"canebench export: {what} as {','.join(formats)} in {res.wall_s:.2f} s -> {out}")
    print(f"  manifest: {out / 'manifest.csv'}, {out / 'manifest.json'}")
    return 0
