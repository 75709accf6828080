"""Model files: a complete model configuration, with fitted effects, on disk.

Written by the discovery workflow (``canebench discover``), read by
``canebench run --model FILE`` and ``canebench export --model FILE``::

    canebench_model: 1
    preset: beam-consistent          # the configuration the effects are added to
    config: {gravity: 9.81}          # optional overrides of that preset
    effects:
      - effect: root_compliance
        scope: global
        params: {k_root: 120.0}
        ci95: {k_root: [95.0, 150.0]} # informative; not used by the model
        local: {b1c1: {k_root: 80.0}} # values for one cane (or one trial: b1c1t2)
        between_canes: {k_root: {median: 110.0, ln_sd: 0.5}}  # how it varies between canes
                                      # (a per-cane fit's); a population export draws from it
    provenance: {...}                 # what produced it (informative)

YAML or JSON (JSON is YAML). Every field is validated with the file's name.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import yaml

from ..data.strict_yaml import load_yaml
from ..errors import InputError
from .config import ModelConfig
from .effects import EffectSpec

FORMAT_VERSION = 1
KNOWN_KEYS = {"canebench_model", "preset", "config", "effects", "provenance", "baseline"}


def load_model_file(path: str | Path) -> ModelConfig:
    """The :class:`ModelConfig` a model file describes.

    Raises
    ------
    InputError
        Missing or malformed file, unknown keys, unknown preset, effect or
        parameter, invalid values (the message names the file and field).
    """
    from .presets import PRESETS

    src = str(path)
    try:
        text = Path(path).read_text()
    except FileNotFoundError:
        raise InputError(src, "<file>", "model file not found") from None
    except (UnicodeDecodeError, IsADirectoryError) as exc:
        raise InputError(src, "<file>", f"not a readable text file: {exc}") from None
    try:
        doc = load_yaml(text)
    except yaml.YAMLError as exc:
        raise InputError(src, "<file>", f"malformed YAML/JSON: {exc}") from None
    if not isinstance(doc, dict):
        raise InputError(src, "<file>", "expected a mapping with 'effects' (and optionally 'preset', 'config')")
    unknown = set(doc) - KNOWN_KEYS
    if unknown:
        raise InputError(src, sorted(unknown)[0], f"unknown key; known: {', '.join(sorted(KNOWN_KEYS))}")
    if doc.get("canebench_model", FORMAT_VERSION) != FORMAT_VERSION:
        raise InputError(src, "canebench_model", f"format version {doc['canebench_model']!r} is not {FORMAT_VERSION}")
    preset = doc.get("preset", "default")
    if not isinstance(preset, str) or preset not in PRESETS:
        raise InputError(src, "preset", f"unknown preset {preset!r}; known: {', '.join(PRESETS)}")
    base = PRESETS[preset]
    over = doc.get("config") or {}
    if not isinstance(over, dict):
        raise InputError(src, "config", "expected a mapping of model settings")
    if "effects" in over:
        raise InputError(src, "config.effects", "effects go in the top-level 'effects' list")
    cfg = base.with_overrides(over, source=src)
    effects = doc.get("effects") or []
    if not isinstance(effects, list):
        raise InputError(src, "effects", "expected a list of effects")
    specs = []
    for i, e in enumerate(effects):
        if not isinstance(e, dict):
            raise InputError(src, f"effects[{i}]", "expected a mapping with 'effect' and 'params'")
        spec = EffectSpec.parse({k: v for k, v in e.items()
                                 if k in ("effect", "name", "params", "local", "scope", "between_canes")},
                                f"{src}: effects[{i}]")
        spec.validate(f"{src}: effects[{i}]")
        specs.append(spec)
    try:
        out = cfg.replace(effects=tuple(specs))
    except InputError as exc:
        raise InputError(src, exc.field, exc.message) from None
    for i, spec in enumerate(specs):  # a file refused is not warned about too
        spec.warn_implausible(f"{src}: effects[{i}]")
    return out


def model_document(config: ModelConfig, preset: str = "default", ci95: dict[str, dict] | None = None,
                   provenance: dict[str, Any] | None = None) -> dict[str, Any]:
    """The model file's content for ``config`` as differences from ``preset``."""
    from .presets import PRESETS

    base = PRESETS[preset].to_dict()
    now = config.to_dict()
    over = {k: v for k, v in now.items() if k != "effects" and v != base.get(k)}
    effects = []
    for e in config.effects:
        d = e.to_dict()
        if ci95 and e.name in ci95:
            d["ci95"] = ci95[e.name]
        effects.append(d)
    return {"canebench_model": FORMAT_VERSION, "preset": preset, "config": over, "effects": effects,
            "provenance": provenance or {}}


def write_model_file(path: str | Path, config: ModelConfig, preset: str = "default",
                     ci95: dict[str, dict] | None = None, provenance: dict[str, Any] | None = None) -> Path:
    """Write a model file (YAML) that :func:`load_model_file` reads back to ``config``."""
    doc = model_document(config, preset, ci95, provenance)
    path = Path(path)
    path.write_text(yaml.safe_dump(json.loads(json.dumps(doc, default=float)), sort_keys=False))
    return path
