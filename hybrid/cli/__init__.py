"""The ``hyst`` command line."""

from ._main import CLIError, main

__all__ = ["main", "CLIError"]
