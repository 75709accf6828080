import pytest

from canebench.backends.base import DynamicBackend
from canebench.errors import BackendUnavailable, UnknownBackend
from canebench.registry import discover, get_backend, register_backend, select


def test_builtins_come_through_entry_points():
    from importlib import metadata

    names = {ep.name for ep in metadata.entry_points(group="canebench.backends")}
    assert {"mujoco", "pinocchio"} <= names
    reg = discover()
    assert reg["mujoco"].available and reg["pinocchio"].available
    assert reg["mujoco"].version and reg["pinocchio"].kind == "static"


def test_unknown_backend_is_a_clear_error():
    with pytest.raises(UnknownBackend, match="nosuch"):
        select(["mujoco", "nosuch"])
    with pytest.raises(UnknownBackend, match="registered"):
        get_backend("nosuch")


def test_unavailable_backend_is_skipped_with_reason():
    class Missing(DynamicBackend):
        name, engine_module = "missing_engine", "definitely_not_an_installed_engine"

        def settings(self, proto):
            return {}

        def build(self, chain, proto):
            raise AssertionError

    info = register_backend(Missing)
    assert not info.available and "definitely_not_an_installed_engine" in info.reason
    usable, skipped = select(["mujoco", "missing_engine"])
    assert usable == ["mujoco"] and "missing_engine" in skipped
    with pytest.raises(BackendUnavailable):
        get_backend("missing_engine")


def test_tagged_registry_refuses_duplicates_and_selects_by_tag():
    from canebench.registry import DuplicateName, Registry, UnknownName

    r = Registry("thing")
    r.add("a", 1, ("x", "y"), "first")
    r.add("b", 2, ("x",))
    with pytest.raises(DuplicateName, match="thing 'a'"):
        r.add("a", 3)
    assert r.names("x") == ["a", "b"] and r.names("x", "y") == ["a"] and r.names() == ["a", "b"]
    assert r["a"] == 1 and r.description("a") == "first"
    with pytest.raises(UnknownName, match="known: a, b"):
        r["c"]


def test_every_selectable_kind_is_a_registry():
    from canebench.execute.executors import EXECUTORS
    from canebench.model.presets import PRESETS
    from canebench.model.stiffness import FORMULAS, register_formula
    from canebench.probe.protocol import PROTOCOLS
    from canebench.registry import BACKENDS, DuplicateName, Registry
    from canebench.studies import STUDIES

    for reg in (BACKENDS, FORMULAS, PROTOCOLS, PRESETS, EXECUTORS, STUDIES):
        assert isinstance(reg, Registry) and len(reg) > 0
    assert {"paper", "end_angle", "dual_length"} <= set(FORMULAS)
    assert PRESETS["paper"].modulus_pa == 4.57e9 and PRESETS["paper"].stiffness_formula == "paper"
    with pytest.raises(DuplicateName):  # a plugin cannot silently replace a built-in formula
        register_formula("paper", "impostor")(lambda ei, length, ctx=None: ei)
    assert FORMULAS.description("paper").startswith("K = 2EI/L")

