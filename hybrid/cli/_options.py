"""Options several ``hyst`` commands share, declared once so that a flag means one thing everywhere.

The rate is given in Hz on the command line and checked here; :func:`dt_s` is the one place
it becomes a sample time in seconds.
"""

from __future__ import annotations

from collections.abc import Sequence

from hybrid.networks import NETWORKS

#: Default of ``--rate``: the seed paper's 25 Hz.
DEFAULT_RATE_HZ = 25.0


def _error(message: str) -> Exception:
    from hybrid.cli._main import CLIError

    return CLIError(message)


# ---------------------------------------------------------------------- rate
def add_rate_option(p, what: str = "model rate") -> None:
    """``--rate HZ``; ``what`` says what the rate is in this command."""
    p.add_argument("--rate", type=float, default=DEFAULT_RATE_HZ, help=f"{what}, Hz (default: {DEFAULT_RATE_HZ:g})")


def rate_hz(args) -> float:
    """``--rate``, checked to be > 0 Hz."""
    if not args.rate > 0:
        raise _error(f"--rate must be > 0 Hz. Got {args.rate} instead.")
    return args.rate


def dt_s(args) -> float:
    """The sample time ``--rate`` sets, s."""
    return 1.0 / rate_hz(args)


# ----------------------------------------------------------------------- CSV
def add_csv_options(p, rate: str = "resample to this rate") -> None:
    """The CSV column options and ``--rate`` (what the CSV files are resampled to)."""
    p.add_argument("--time", default="time", help="time column, s (default: %(default)s)")
    p.add_argument("--input", default="u", help="input column (default: %(default)s)")
    p.add_argument("--output", default="y", help="output column (default: %(default)s)")
    add_rate_option(p, rate)


def load_csvs(paths: Sequence[str], args) -> list:
    """The trajectories in ``paths``, read with the CSV options and resampled to ``--rate``."""
    from physics.data import load_csv

    rate = rate_hz(args)
    return [load_csv(p, time=args.time, input=args.input, output=args.output, rate_hz=rate) for p in paths]


# ------------------------------------------------------------- experiments
def add_seed_option(p, what: str) -> None:
    """``--seed N`` (default 0); ``what`` says what it seeds in this command."""
    p.add_argument("--seed", type=int, default=0, help=f"{what} (default: 0)")


def add_solver_limits(p, max_iter: int, what: str = "per fit") -> None:
    """``--max-iter N`` (the limit: the same answer on any machine) and ``--max-wall-time S``
    (a last safeguard, off by default; a fit it stops says so)."""
    p.add_argument("--max-iter", type=int, default=max_iter, metavar="N",
                   help=f"IPOPT iterations {what} (default: {max_iter})")
    p.add_argument("--max-wall-time", type=float, default=None, metavar="S",
                   help="safeguard: stop a solve after S seconds; the answer then depends on the machine "
                        "(default: off)")


def add_experiment_options(p, data: str, preset: str) -> None:
    """The options of the experiment commands; ``data`` and ``preset`` describe the choices of
    ``--data`` and ``--preset`` in this command."""
    p.add_argument("--data", default="virtual", help=data)
    p.add_argument("--preset", default="quick", metavar="{quick,paper}", help=preset)
    add_seed_option(p, "seed of the weights, the shuffling and the virtual data")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    p.add_argument("--no-figures", action="store_true", help="skip the figures")


def network_names() -> str:
    """The registered networks, for help texts: ``"fnn, fnn-hib, lstm"``."""
    return ", ".join(NETWORKS)


def parse_networks(text: str | None, default: Sequence[str], what: str = "network") -> tuple[str, ...]:
    """Comma-separated registry names (``default`` when ``text`` is None), each checked."""
    names = tuple(m.strip() for m in text.split(",")) if text else tuple(default)
    unknown = [m for m in names if m not in NETWORKS]
    if unknown:
        raise _error(f"unknown {what} {unknown[0]!r}. Must be one of {list(NETWORKS)}.")
    return names
