"""The ``canebench`` command line (one module per command)."""

from .main import build_parser, main  # noqa: F401
