"""Exceptions that name the file and the field at fault."""

from __future__ import annotations


class CanebenchError(Exception):
    """Base class of every error canebench raises on purpose."""


class InputError(CanebenchError, ValueError):
    """Bad user input: malformed YAML/CSV, NaN, non-positive sizes, ...

    Parameters
    ----------
    source : str
        File (or other origin) the bad value came from.
    field : str
        Dotted path of the offending field, e.g. ``calipers[2].diameter``.
    message : str
        What is wrong with it.
    """

    def __init__(self, source: str, field: str, message: str) -> None:
        self.source = str(source)
        self.field = field
        self.message = message
        super().__init__(f"{self.source}: field '{field}': {message}")


class BackendUnavailable(CanebenchError):
    """A registered backend whose engine cannot be imported or used."""


class UnknownBackend(CanebenchError, KeyError):
    """A backend name that is not in the registry."""

    def __str__(self) -> str:  # KeyError quotes its message; keep it readable
        return str(self.args[0]) if self.args else "unknown backend"


class InputWarning(UserWarning):
    """Input that is possible but implausible (units, orientation, shape).

    The message names the file, the field, the value and the likely cause;
    ``--strict`` turns every such warning into an :class:`InputError`.
    """

    def __init__(self, source: str, field: str, message: str) -> None:
        self.source, self.field, self.message = str(source), field, message
        super().__init__(f"{self.source}: field '{field}': {message}")


def warn_input(source: str, field: str, message: str) -> None:
    """Emit an :class:`InputWarning` (an error under ``--strict``)."""
    import warnings

    warnings.warn(InputWarning(source, field, message), stacklevel=3)


def cell_text(value: object) -> str:
    """A table cell as an error message shows it: ``empty or NA`` when missing, else its value quoted.

    pandas reads an empty cell and the markers ``NA``, ``nan``, ``null`` alike, so the message names both.
    """
    try:
        missing = value is None or bool(value != value)  # NaN of any float type, NaT
    except TypeError:  # pandas' NA has no truth value
        missing = True
    if missing or (isinstance(value, str) and not value.strip()):
        return "empty or NA"
    item = getattr(value, "item", None)  # a numpy scalar reads as its Python value, not np.float64(...)
    return repr(item() if callable(item) else value)
