"""YAML as canebench reads it: PyYAML's safe loader, refusing a key given twice in one mapping.

PyYAML keeps the last of two equal keys without a word; in a cane description a second
``calipers:`` block would silently replace the measured calipers, and in a model file a second
``k_root`` the first (both found by a review that mutated inputs, docs/discovery.md session 66).
"""

from __future__ import annotations

from typing import Any

import yaml


class DuplicateKeyError(yaml.constructor.ConstructorError):
    """A mapping with a key given twice (a ``yaml.YAMLError``: callers' handlers name the file)."""


class _StrictLoader(yaml.SafeLoader):
    pass


def _mapping(loader: _StrictLoader, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
    # only the keys written in this mapping: one that overrides a merged one (<<) is YAML's way to
    # override, not a duplicate, so the check runs before the merge is flattened in
    seen: dict[Any, Any] = {}
    for key_node, _ in node.value:
        if key_node.tag == "tag:yaml.org,2002:merge":
            continue
        key = loader.construct_object(key_node, deep=deep)
        try:
            hash(key)
        except TypeError:
            continue  # the base constructor reports an unhashable key in its own words
        if key in seen:
            raise DuplicateKeyError("while constructing a mapping", node.start_mark,
                                    f"key {key!r} given twice (first on line {seen[key].line + 1})",
                                    key_node.start_mark)
        seen[key] = key_node.start_mark
    loader.flatten_mapping(node)
    return loader.construct_mapping(node, deep=deep)


_StrictLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _mapping)


def load_yaml(text: str) -> Any:
    """``yaml.safe_load`` that raises :class:`DuplicateKeyError` on a repeated key."""
    return yaml.load(text, Loader=_StrictLoader)  # noqa: S506 (a SafeLoader subclass)
