"""The ``hyst`` command line."""

from __future__ import annotations

import sys

__all__ = ["main", "CLIError"]


def main(argv=None) -> int:
    """``hyst``: the command line. Its modules are imported here, so a Ctrl-C while they load (a second
    or two of scipy, casadi and torch) ends with one line and exit 130, like one during a command."""
    try:
        from ._main import main as run
    except KeyboardInterrupt:
        print("hyst: interrupted while starting; nothing was done", file=sys.stderr)
        return 130
    return run(argv)


def __getattr__(name: str):
    if name == "CLIError":
        from ._main import CLIError

        return CLIError
    raise AttributeError(f"module 'hybrid.cli' has no attribute {name!r}")
