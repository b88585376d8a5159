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
from pathlib import Path

from physics.data.io import ENDING, Terminated, record_and_raise

from ._outputs import check_out

COMMANDS = ("simulate", "identify", "train", "predict", "reproduce", "compare", "discover",
            "fit", "export", "mpc", "ablate")


#: Optional packages and the extra that installs each (pyproject.toml).
EXTRAS = {"torch": "learning", "torchdiffeq": "learning", "pysindy": "discovery", "dask": "distributed",
          "distributed": "distributed"}


class CLIError(Exception):
    """A bad argument or file: reported as one line, exit status 2."""


class _UsageError(CLIError):
    """argparse refused the command line (unknown flag, bad number, missing argument)."""

    def __init__(self, prog: str, message: str):
        super().__init__(message)
        self.prog = prog


class _Parser(argparse.ArgumentParser):
    """argparse, with a refusal as one line ("hyst train: error: argument --epochs: ...") instead of
    the usage block; sub-command parsers are of the same class."""

    def error(self, message: str):
        raise _UsageError(self.prog, message)

    def _get_values(self, action, arg_strings):
        if action.option_strings and action.nargs is None and arg_strings == ["--"]:
            # "--rate=--": argparse drops the "--" and hands the option an empty list
            raise argparse.ArgumentError(action, "expected one argument")
        return super()._get_values(action, arg_strings)


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="hyst",
        description="Hysteretic robot kinematics: physics (CasADi) plus neural networks.",
    )
    from hybrid._version import __version__

    parser.add_argument("--version", action="version", version=f"hyst {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in COMMANDS:
        importlib.import_module(f"hybrid.cli._commands.{name}").register(sub)
    return parser


def main(argv=None) -> int:
    try:
        args = build_parser().parse_args(argv)
    except _UsageError as exc:
        print(f"{exc.prog}: error: {exc.args[0]} (see '{exc.prog} --help')", file=sys.stderr)
        return 2
    except KeyboardInterrupt:  # while the commands' modules are imported: nothing was written yet
        print("hyst: interrupted before any work.", file=sys.stderr)
        return 130
    on_main = threading.current_thread() is threading.main_thread()
    # presses CasADi swallows too; SIGTERM and SIGHUP (a closed terminal) raise like Ctrl-C, so files,
    # workers and compilers are cleaned up
    previous = {s: signal.signal(s, record_and_raise) for s in (signal.SIGINT, *ENDING)} if on_main else {}
    try:
        return _run(args)
    finally:
        if argv is None and on_main and _is_the_command():  # the process is ``hyst ...``: it ends here
            _end_quietly()
        else:
            for s, handler in previous.items():
                signal.signal(s, handler)


def _is_the_command() -> bool:
    """Whether this process runs ``hyst`` (its console script, or this module as a script), not a
    script or notebook that calls :func:`main` and goes on afterwards."""
    return Path(sys.argv[0] if sys.argv else "").stem in ("hyst", "_main")


def _end_quietly() -> None:
    """The command's work is over: its local workers are stopped here, and a Ctrl-C from now on is
    ignored (there is nothing left to interrupt), so the interpreter's exit prints nothing after the
    command's last line (loky's exit hook, waiting for its workers, printed a KeyboardInterrupt)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    for s in ENDING:  # a SIGTERM or SIGHUP now ends the process as it would any program
        signal.signal(s, signal.SIG_DFL)
    if "identification.discovery._pool" in sys.modules:
        sys.modules["identification.discovery._pool"].end_local_workers()


def _message(exc: BaseException) -> str:
    """One line: an OSError as "'file': reason", anything else its message, newlines folded."""
    if isinstance(exc, OSError) and exc.errno is not None:
        where = f"'{exc.filename}': " if exc.filename else ""
        msg = f"{where}{exc.strerror or exc}"
    elif isinstance(exc, KeyError) and len(exc.args) == 1 and not str(exc.args[0]).count(" "):
        msg = f"missing entry {exc.args[0]!r}"  # a bare KeyError('name') would print just name
    else:
        msg = str(exc.args[0]) if len(exc.args) == 1 else str(exc) or type(exc).__name__
    return " ".join(line.strip() for line in msg.splitlines() if line.strip())


def _run(args) -> int:
    try:
        check_out(args, CLIError)  # before any work
        return int(args.func(args) or 0)
    except (CLIError, ValueError, OSError, KeyError) as exc:  # OSError: a read or write that failed
        print(f"hyst {args.command}: error: {_message(exc)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as exc:  # Ctrl-C, or SIGTERM and SIGHUP (Terminated)
        ended = isinstance(exc, Terminated)
        how = ("hung up" if getattr(signal, "SIGHUP", None) == exc.signum else "terminated") if ended else "interrupted"
        print(f"hyst {args.command}: {how}; files already written are complete (writes are atomic), "
              "the one in progress was not written.", file=sys.stderr)
        return 128 + exc.signum if ended else 130
    except ModuleNotFoundError as exc:
        top = (exc.name or "").split(".")[0]
        if top not in EXTRAS:
            raise
        print(f"hyst {args.command}: error: this command needs {top}, which is not installed. "
              f"Install it with: pip install 'hysteresis-hybrid[{EXTRAS[top]}]'", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
