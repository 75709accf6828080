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
