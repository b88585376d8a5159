"""The ``hyst`` command line: one program, one module per sub-command.

Each module in ``hybrid/cli/_commands`` defines ``register(subparsers)``, which adds
its parser and sets ``func`` (called with the parsed arguments, returns an exit
status). Heavy imports (torch, casadi) happen inside ``func`` so that
``hyst --help`` stays fast.
"""

from __future__ import annotations

import argparse
import importlib
import signal
import sys
import threading

from physics.data._interrupt import record_and_raise

from ._outputs import check_out

COMMANDS = ("simulate", "identify", "train", "predict", "reproduce", "compare", "discover",
            "fit", "export", "mpc", "ablate")


#: Optional packages and the extra that installs each (pyproject.toml).
EXTRAS = {"torch": "learning", "torchdiffeq": "learning", "pysindy": "discovery", "dask": "distributed",
          "distributed": "distributed"}


class CLIError(Exception):
    """A bad argument or file: reported as one line, exit status 2."""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="hyst",
        description="Hysteretic robot kinematics: physics (CasADi) plus neural networks.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in COMMANDS:
        importlib.import_module(f"hybrid.cli._commands.{name}").register(sub)
    return parser


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, record_and_raise)  # a press CasADi swallows still stops the command
    try:
        check_out(args, CLIError)  # before any work
        return int(args.func(args) or 0)
    except (CLIError, ValueError, FileNotFoundError, KeyError) as exc:
        msg = exc.args[0] if exc.args else repr(exc)
        print(f"hyst {args.command}: error: {msg}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"hyst {args.command}: interrupted; files already written are complete (writes are atomic), "
              "the one in progress was not written.", file=sys.stderr)
        return 130
    except OSError as exc:  # a write that failed after the checks (disk full, permissions changed)
        where = f" '{exc.filename}'" if exc.filename else ""
        print(f"hyst {args.command}: error: cannot write{where}: {exc.strerror or exc}", file=sys.stderr)
        return 2
    except ModuleNotFoundError as exc:
        top = (exc.name or "").split(".")[0]
        if top not in EXTRAS:
            raise
        print(f"hyst {args.command}: error: this command needs {top}, which is not installed. "
              f"Install it with: pip install 'hysteresis-hybrid[{EXTRAS[top]}]'", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
