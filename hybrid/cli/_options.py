"""Options several ``hyst`` commands share, declared once so that a flag means one thing everywhere.

The rate is given in Hz on the command line and checked here; :func:`dt_s` is the one place
it becomes a sample time in seconds.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Sequence

from hybrid.networks import NETWORKS

#: Default of ``--rate``: the seed paper's 25 Hz.
DEFAULT_RATE_HZ = 25.0


def _error(message: str) -> Exception:
    from hybrid.cli._main import CLIError

    return CLIError(message)


# ------------------------------------------------------------ option types
# argparse calls these on the text of an option; a refusal becomes "argument --flag: <message>",
# so every number a command takes is checked once, here, and named by its flag.

#: Most samples one run may hold (--duration x --rate, or a CSV file's span x --rate): 80 MB a column of
#: float64, and every command keeps several columns and more per sample; beyond it a number is a typo.
MAX_SAMPLES = 10**7
#: Most integration steps of one ``hyst simulate`` run (--duration x --rate x --oversample): the simulator
#: holds about 4 KB a step (1e6 steps: 4 GB and 40 s).
MAX_SIMULATED_STEPS = 10**6
#: Highest --rate, Hz: one second at it already fills :data:`MAX_SAMPLES`.
MAX_RATE_HZ = float(MAX_SAMPLES)
#: Longest --duration, s (about 28 h, longer than any bench run): the multisine's design grid alone holds
#: 100 points a second.
MAX_DURATION_S = 1e5
#: Longest horizon of an exported controller, samples: its matrices grow with its square (``hyst export
#: --controller --horizon 2000`` takes 1.3 GB and a minute; 100000 asked for 75 GB). ``hyst mpc``'s horizon
#: is bounded by its reference (whose length is bounded by :data:`MAX_SAMPLES`); its NLP is sparse.
MAX_HORIZON = 1000
#: Longest measured window an exported model's init (``hyst export --warmup K``) or estimator (``--estimator
#: WINDOW``) is built over, samples: its graph grows with the window (10**5 samples: 250 MB for the linear
#: map; 10**8 was killed for memory after 6 minutes, with OUT already written), and 10**4 is 5 s at 2 kHz.
MAX_WINDOW = 10**4
#: Largest whole number a count option takes (a C int: what IPOPT, torch and the generated C code hold).
MAX_INT = 2**31 - 1


def _number(kind, low: float | None, strict: bool, high: float | None = None, unit: str = ""):
    noun = "an integer" if kind is int else "a number"
    bounds = [f"{'>' if strict else '>='} {low:g}" if low is not None else "",
              (f"<= {high}" if kind is int else f"<= {high:g}") if high is not None else ""]
    want = f"{noun} {' and '.join(b for b in bounds if b)}{unit}".strip()

    def convert(text: str):
        try:
            value = kind(text)
        except (TypeError, ValueError, OverflowError):
            raise argparse.ArgumentTypeError(f"must be {want}; got {text!r}") from None
        if kind is float and not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"must be a finite number; got {text!r}")
        if low is not None and (value < low or (strict and value == low)) or high is not None and value > high:
            raise argparse.ArgumentTypeError(f"must be {want}; got {text!r}")
        return value

    convert.__name__ = want  # argparse names the type in some messages
    return convert


#: Option types: ``type=POSITIVE_INT`` etc.
POSITIVE_INT = _number(int, 1, strict=False, high=MAX_INT)
NONNEGATIVE_INT = _number(int, 0, strict=False, high=MAX_INT)
POSITIVE_FLOAT = _number(float, 0, strict=True)
NONNEGATIVE_FLOAT = _number(float, 0, strict=False)
FRACTION = _number(float, 0, strict=False, high=1)  # 0 <= x <= 1
SEED = _number(int, 0, strict=False, high=2**32 - 1)  # what numpy and torch both take
RATE = _number(float, 0, strict=True, high=MAX_RATE_HZ, unit=" (Hz)")  # a sample rate: --rate
DURATION = _number(float, 0, strict=True, high=MAX_DURATION_S, unit=" (s)")  # a length of time: --duration
HORIZON = _number(int, 1, strict=False, high=MAX_HORIZON, unit=" (samples)")  # export --controller --horizon
WINDOW = _number(int, 1, strict=False, high=MAX_WINDOW, unit=" (samples)")  # export --warmup, --estimator


def bounded_float(low: float, high: float, unit: str = "", strict: bool = True):
    """An option type for a number ``> low`` (``>= low`` when not ``strict``) and ``<= high`` (``unit``
    shown in the refusal, e.g. " (mm)")."""
    return _number(float, low, strict=strict, high=high, unit=unit)


def LO_HI(text: str) -> tuple[float, float]:  # noqa: N802 - an option type like POSITIVE_FLOAT
    """``LO,HI``: two finite numbers with LO < HI (bounds: --u-bounds, --y-bounds)."""
    try:
        lo, hi = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected LO,HI (two numbers), got {text!r}") from None
    if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
        raise argparse.ArgumentTypeError(f"expected LO,HI with LO < HI, both finite, got {text!r}")
    return lo, hi


def OUTPUT_LO_HI(text: str) -> tuple[str | None, tuple[float, float]]:  # noqa: N802 - an option type
    """``[OUTPUT:]LO,HI``: bounds (:func:`LO_HI`), on the named output of a model of several (``"Angle x:20,60"``;
    without a name, on the output the command tracks); ``(name or None, (lo, hi))``."""
    name, sep, numbers = str(text).rpartition(":")
    if sep and not name.strip():
        raise argparse.ArgumentTypeError(f"expected OUTPUT:LO,HI with an output's column name before ':', or LO,HI; "
                                         f"got {text!r}")
    return (name.strip() or None), LO_HI(numbers)


def bound_index(args, n_y: int, track: int | None) -> int | None:
    """``--y-bounds OUTPUT:LO,HI`` (parsed by :func:`OUTPUT_LO_HI`; ``args.y_bounds`` then holds ``(lo, hi)``):
    the index of the bounded output of a model of several, None where the bounds are the tracked output's;
    a refusal for a model of one output, without ``--track``, or a name the fit does not have."""
    name, args.y_bounds = args.y_bounds if args.y_bounds is not None else (None, None)
    if name is None:
        return None
    if n_y == 1 or track is None:
        raise _error(f"--y-bounds {name!r}:... names the bounded output of a model of several outputs, with --track "
                     f"naming the tracked one; '{args.model}' has {n_y} output(s)"
                     + (" and no --track" if n_y > 1 else "") + ". Give --y-bounds LO,HI for the tracked output.")
    names = fit_outputs(args.model, n_y)
    if name not in names:
        raise _error(f"--y-bounds {name!r}:... is not an output of '{args.model}'; its outputs are {', '.join(names)}.")
    return names.index(name)


def jobs_count(text: str) -> int:
    """``--jobs``: a number of worker processes >= 1, or -1 for one per core."""
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value == -1 or 1 <= value <= 1024:
        return value
    raise argparse.ArgumentTypeError(f"must be a whole number from 1 to 1024, or -1 for one per core; got {text!r}")


#: Seconds to wait for a Dask scheduler to accept a connection before giving up.
CONNECT_TIMEOUT_S = 5.0


def check_scheduler(address: str | None) -> None:
    """Fail fast, naming ``--scheduler``, when no server accepts connections at ``address``
    (Dask itself waits 30 s and then raises a traceback)."""
    import socket
    from urllib.parse import urlsplit

    if address is None:
        return
    parts = urlsplit(address if "://" in address else f"tcp://{address}")
    try:
        host, port = parts.hostname, parts.port
    except ValueError:
        host, port = None, None
    if parts.scheme not in ("tcp", "tls") or not host or port is None:
        raise _error(f"--scheduler {address!r} is not an address like tcp://host:8786.")
    try:
        socket.create_connection((host, port), timeout=CONNECT_TIMEOUT_S).close()
    except OSError as exc:
        reason = "timed out" if isinstance(exc, TimeoutError) else (exc.strerror or str(exc))
        raise _error(f"--scheduler {address}: no Dask scheduler answers there ({reason}). Start one "
                     "(`dask scheduler`), or leave --scheduler out.") from None


def add_selection_pool_options(p) -> None:
    """``--jobs N`` and ``--scheduler ADDRESS``: where the physics selection's fold fits run."""
    p.add_argument("--jobs", type=jobs_count, default=-1, metavar="N",
                   help="worker processes for the physics selection's fold fits (default -1: one per core; 1: "
                        "here, one after another); the same choice and numbers whatever N")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="run the physics selection's fold fits on the workers of a running Dask scheduler, e.g. "
                        "tcp://host:8786 (the same choice and numbers as here; Ctrl-C cancels them there)")


def open_fraction(text: str) -> float:
    """A number strictly between 0 and 1."""
    value = FRACTION(text)
    if not 0 < value < 1:
        raise argparse.ArgumentTypeError(f"must be a number > 0 and < 1; got {text!r}")
    return value


def LEVEL(text: str) -> float:  # noqa: N802 - an option type like POSITIVE_FLOAT
    """An interval level: a number strictly between 0 and 1 (0.9 for 90 %)."""
    try:
        return open_fraction(text)
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(f"an interval level must be a number > 0 and < 1, e.g. 0.9 for 90 %; "
                                         f"got {text!r}") from None


def validation_fraction(text: str) -> float:
    """A share of the data held out: >= 0 and < 1."""
    value = FRACTION(text)
    if value >= 1:
        raise argparse.ArgumentTypeError(f"must be a number >= 0 and < 1; got {text!r}")
    return value


def nonempty(what: str):
    """A text option that must not be blank (``--physics ""``); ``what`` says what to give."""
    def convert(text: str) -> str:
        if not text.strip():
            raise argparse.ArgumentTypeError(f"is empty; give {what}")
        return text.strip()
    return convert


# ---------------------------------------------------------------------- rate
def add_rate_option(p, what: str = "model rate") -> None:
    """``--rate HZ``; ``what`` says what the rate is in this command."""
    p.add_argument("--rate", type=RATE, default=DEFAULT_RATE_HZ,
                   help=f"{what}, Hz (default: {DEFAULT_RATE_HZ:g})")


def add_model_rate_option(p, what: str = "model rate") -> None:
    """``--rate HZ`` of the commands that run a saved model: by default its own (:func:`model_rate`)."""
    p.add_argument("--rate", type=RATE, default=None, metavar="HZ",
                   help=f"{what}, Hz: the model's own (default; {DEFAULT_RATE_HZ:g} Hz for a physics spec or a model "
                        "that records none); another rate is refused")


def RATE_OR_AUTO(text: str):  # noqa: N802 - an option type like POSITIVE_FLOAT
    """``--rate`` of the CSV commands: a number > 0 (Hz) or ``auto``."""
    if text.strip().lower() == "auto":
        return "auto"
    try:
        return RATE(text)
    except argparse.ArgumentTypeError as exc:
        raise argparse.ArgumentTypeError(f"{exc}, or 'auto' for the files' own rate") from None


def rate_hz(args) -> float:
    """``--rate``, checked to be > 0 Hz (``auto`` is resolved by :func:`load_csvs`)."""
    if args.rate == "auto":
        raise _error("--rate auto is the training files' own rate, known once they are read; give --rate HZ.")
    if not args.rate > 0:
        raise _error(f"--rate must be > 0 Hz. Got {args.rate} instead.")
    check_run_length(args, args.rate)
    return args.rate


def check_run_length(args, rate: float) -> None:
    """Refuse, before anything is allocated, a run the machine cannot hold: ``--duration`` x ``--rate``
    samples beyond :data:`MAX_SAMPLES` (``hyst mpc``), or times ``--oversample`` integration steps beyond
    :data:`MAX_SIMULATED_STEPS` (``hyst simulate``), naming the flags and the limit. Commands whose length
    comes from a file are checked as it is read (:func:`load_csvs`)."""
    run = _run_duration_s(args)
    if run is None:
        return
    duration, given = run
    oversample = getattr(args, "oversample", None)
    limit, what = (MAX_SIMULATED_STEPS, "integration steps") if oversample else (MAX_SAMPLES, "samples")
    n = duration * rate * (oversample or 1)
    if n > limit:
        over = f" with --oversample {oversample}" if oversample else ""
        flags = "--duration, --rate or --oversample" if oversample else "--duration or --rate"
        if "--freq" in given or "paper" in given:
            flags = ("raise --freq, or lower " if "--freq" in given else "lower ") + "--rate or --oversample"
        else:
            flags = f"lower {flags}"
        raise _error(f"{given} at --rate {rate:g} Hz{over} is {n:.3g} {what}; the limit is {limit:.0e} (what fits "
                     f"in memory): {flags}.")


def _run_duration_s(args) -> tuple[float, str] | None:
    """Seconds of the run a command generates and how they were set: ``--duration``, else ``hyst
    simulate``'s default (the longest run of the paper's protocol, 7 cycles of ``--freq``, or 60 s);
    None for a reference file."""
    if getattr(args, "reference", "sine") not in ("sine", "steps") or not hasattr(args, "duration"):
        return None
    if getattr(args, "paper_dataset", False):
        from physics.virtual import TEST_FREQUENCIES, TRAIN_FREQUENCIES

        longest = 7.0 / min(TRAIN_FREQUENCIES + TEST_FREQUENCIES)
        return longest, f"the paper dataset's longest run ({longest:g} s)"
    if args.duration is not None:
        return float(args.duration), f"--duration {args.duration:g} s"
    if getattr(args, "signal", None) == "decaying":
        return 7.0 / args.freq, f"7 cycles of --freq {args.freq:g} Hz ({7.0 / args.freq:g} s)"
    return 60.0, "the default --duration of 60 s"


def dt_s(args) -> float:
    """The sample time ``--rate`` sets, s."""
    return 1.0 / rate_hz(args)


# ----------------------------------------------------------------------- CSV
AUTO_RATE_HELP = ("rate the CSV files are resampled to and the model runs at, Hz; auto (default): the rate the "
                  "training files were recorded at (the median step of their stamps, to the digits the stamps carry: "
                  "500.8 stays 500.8; irregular stamps are made uniform)")


def add_csv_options(p, rate: str = AUTO_RATE_HELP, several_outputs: bool = False) -> None:
    """The CSV column options and ``--rate`` (what the CSV files are resampled to; by default the
    rate they were recorded at); ``several_outputs``: ``--output`` may name several columns."""
    p.add_argument("--time", default="time", help="time column, s (default: %(default)s)")
    p.add_argument("--input", default="u", help="input column, or comma-separated columns: the command first, then "
                   "measured inputs the networks also read, e.g. 'Tendon Disp.,Motor Curr.' (default: %(default)s)")
    if several_outputs:
        p.add_argument("--output", type=OUTPUT_COLUMNS, default="y", help="output column, or comma-separated columns "
                       "fitted as one model, e.g. 'Angle x,Pos x,Pos y' (default: %(default)s)")
    else:
        p.add_argument("--output", type=ONE_OUTPUT, default="y", help="output column (default: %(default)s)")
    p.add_argument("--rate", type=RATE_OR_AUTO, default="auto", metavar="HZ|auto", help=rate)
    p.add_argument("--units", type=UNITS, default=None, metavar="IN,OUT",
                   help="units of the input and output columns, e.g. mm,deg (default: from a header ending in "
                        "'[unit]' or '(unit)', else none); shown on the model card's axes and tables")


def load_csvs(paths: Sequence[str], args, warn_constant: bool = False, *, refuse_constant: bool = False,
              refuse_copies: bool = True, held_out: bool = False) -> list:
    """The trajectories in ``paths``, read with the CSV options and resampled to ``--rate``; with
    ``warn_constant``, a warning (stderr) for each whose input does not move. ``--rate auto`` becomes
    the rate of the first files read (the training runs), so later files (tests) share it.

    Input columns no model can learn from are refused in one line (:func:`check_input_values`):
    with ``refuse_copies`` (default: the runs are fitted or scored on) one that repeats the output
    or the time column in any file; with ``refuse_constant`` (the training runs of ``hyst fit``)
    one that does not move in any of the files. A file given twice is refused, and with ``held_out``
    (the --test runs) one of the training files (``args.data``)."""
    import sys

    from physics.data import load_csvs as read
    from physics.data import is_constant

    check_distinct_files(paths, args.data if held_out else None)
    command, measured = input_columns(args)
    outputs = output_names(args)
    units = getattr(args, "units", None) or ("", "")
    notes: list[str] = []  # what looks wrong in the files' time stamps (gaps, milliseconds)
    trajs = read(paths, time=args.time, input=command, output=outputs[0], extra=measured + outputs[1:],
                 check_outliers=True,
                 rate_hz="auto" if args.rate == "auto" else rate_hz(args), input_unit=units[0], output_unit=units[1],
                 max_samples=MAX_SAMPLES, warn=notes.append)
    if args.rate == "auto" and trajs:
        args.rate = trajs[0].meta["rate_hz"]
    check_input_values(paths, trajs, args, constant=refuse_constant, copies=refuse_copies)
    if refuse_constant or warn_constant:  # the runs a model is identified from
        check_output_moves(trajs, args)
    for note in notes:  # after every refusal: a refused command prints one line
        print(f"hyst {args.command}: warning: {note}", file=sys.stderr)
    for path, traj in zip(paths, trajs):
        if warn_constant and is_constant(traj.u):
            print(f"hyst {args.command}: warning: {path}: the input (--input column {command!r}) is constant "
                  f"({traj.u[0]:g}), so no effect can be told from this run; give runs that move the input.",
                  file=sys.stderr)
    return trajs


def check_distinct_files(paths: Sequence[str], train: Sequence[str] | None = None) -> None:
    """Refuse a file given twice among ``paths`` (its run would count twice: in the fit, and as two
    conditions of the intervals' calibration), or, when ``paths`` are held out, one of the ``train`` files."""
    import os

    seen: dict[str, str] = {}
    for path in paths:
        if not str(path).strip():  # '' would be read as '.', "a folder"
            raise _error("a CSV file's path is empty (''); give the path of a CSV file.")
        key = os.path.realpath(path)
        if key in seen:
            raise _error(f"{path} is given twice (also as {seen[key]}); give each run once.")
        seen[key] = str(path)
    both = [p for p in (train or []) if os.path.realpath(p) in seen]
    if both:
        raise _error(f"{both[0]} is both a training run and a held-out run (--test); a held-out run is left out "
                     "of the fit: give it once.")


def check_input_values(paths: Sequence[str], trajs: Sequence, args, constant: bool, copies: bool) -> None:
    """Refuse an ``--input`` column no model can learn from, naming it and the fix: with ``copies``, one
    equal, sample for sample, to the output or the time column of a file (a mislabelled column: the model
    would be handed its answer, or learn the clock); with ``constant``, one that does not move in any of
    ``trajs`` (pooled: a run held at rest among moving ones is still data)."""
    import numpy as np

    from physics.data import is_constant

    if not trajs:
        return
    command, measured = input_columns(args)
    what = {command: "the command", **{name: "a measured input" for name in measured}}
    fix = {command: "name the column that holds the command (first in --input)",
           **{name: "drop it from --input" for name in measured}}
    for path, traj in zip(paths, trajs):
        columns = {command: traj.u, **{name: traj.extra[name] for name in measured}}
        for name, values in columns.items() if copies else ():
            for other, ref, why in ((f"output column '{args.output}'", traj.y, "the model would be handed its answer"),
                                    (f"time column '{args.time}'", traj.time, "the model would learn the clock")):
                spread = float(np.ptp(ref))  # a copy of a constant column is a constant column: refused below
                if spread > 0 and np.max(np.abs(values - ref)) <= 1e-9 * max(spread, float(np.max(np.abs(ref)))):
                    raise _error(f"--input column {name!r} ({what[name]}) repeats the {other} sample for sample in "
                                 f"{path}: {why}, not the system; {fix[name]}.")
    for name in (command, *measured) if constant else ():
        pooled = np.concatenate([traj.u if name == command else traj.extra[name] for traj in trajs])
        if is_constant(pooled):
            raise _error(f"--input column {name!r} ({what[name]}) is constant ({pooled[0]:g}) in every training run, "
                         f"so no model can learn from it; {fix[name]}, or give runs where it moves.")


def check_output_moves(trajs: Sequence, args) -> None:
    """Refuse training runs whose ``--output`` column does not move in any of them: no parameter can be
    identified from it (a time constant fitted to a constant comes out arbitrary, with no spread)."""
    import numpy as np

    from physics.data import is_constant

    pooled = np.concatenate([traj.y for traj in trajs]) if trajs else np.zeros(0)
    if pooled.size and is_constant(pooled):
        where = "every training run" if len(trajs) > 1 else str(trajs[0].source or "the training run")
        raise _error(f"--output column {args.output!r} is constant ({pooled[0]:g}) in {where}, so nothing can be "
                     "identified from it; name the column that holds the measured output, or give runs where it "
                     "moves.")


def UNITS(text: str) -> tuple[str, str]:  # noqa: N802 - an option type like POSITIVE_FLOAT
    """``--units IN,OUT``: two unit names (either may be empty: ``,deg``)."""
    parts = [p.strip() for p in str(text).split(",")]
    if len(parts) != 2 or not any(parts) or any(len(p) > 32 or any(c in p for c in "\n\r\t") for p in parts):
        raise argparse.ArgumentTypeError(f"expected IN,OUT such as mm,deg; got {text!r}")
    return parts[0], parts[1]


def input_columns(args) -> tuple[str, tuple[str, ...]]:
    """``--input``: the command's column and the measured inputs' columns after it."""
    names = [n.strip() for n in str(args.input).split(",")]
    if not all(names) or len(set(names)) != len(names):
        raise _error(f"--input {args.input!r}: give distinct column names separated by commas, the command first.")
    for flag, role, why in (("--output", "output", "the model would be handed its answer"),
                            ("--time", "time", "the model would learn the clock")):
        given = getattr(args, flag[2:], None)
        for column in (_names(given) if flag == "--output" and given is not None else [given]):
            if column in names:
                fix = "name the command's column first in --input" if column == names[0] else "drop it from --input"
                raise _error(f"--input {args.input!r} names the {role} column {column!r} ({flag}): {why}, not the "
                             f"system; {fix}.")
    return names[0], tuple(names[1:])


def _names(text) -> list[str]:
    return [n.strip() for n in str(text).split(",")]


def OUTPUT_COLUMNS(text: str) -> str:  # noqa: N802 - an option type like POSITIVE_FLOAT
    """``--output A,B,C``: distinct column names (kept as the text; :func:`output_names` splits it)."""
    names = _names(text)
    if not all(names) or len(set(names)) != len(names):
        raise argparse.ArgumentTypeError(f"give distinct column names separated by commas; got {text!r}")
    return str(text)


def ONE_OUTPUT(text: str) -> str:  # noqa: N802
    """``--output`` of a command that models one output: a column name that is not a list."""
    names = _names(OUTPUT_COLUMNS(text))
    if len(names) > 1:
        raise argparse.ArgumentTypeError(f"{text!r} names {len(names)} columns, and this command models one output so "
                                         "far (hyst fit, identify, discover and train fit several): give one column")
    return str(text)


def output_names(args) -> tuple[str, ...]:
    """``--output``: one column, or several separated by commas (checked by the option's type)."""
    names = tuple(_names(args.output))
    if getattr(args, "time", None) in names:
        raise _error(f"--output {args.output!r} names the time column {args.time!r}: the model would learn the clock; "
                     "name the measured output.")
    return names


# ------------------------------------------------------------- experiments
def add_seed_option(p, what: str) -> None:
    """``--seed N`` (default 0); ``what`` says what it seeds in this command."""
    p.add_argument("--seed", type=SEED, default=0, help=f"{what} (default: 0)")


def add_device_option(p) -> None:
    """``--device cpu|auto|cuda|cuda:N`` (default cpu): where the networks train."""
    p.add_argument("--device", type=_device, default="cpu", metavar="DEVICE",
                   help="where the networks train: cpu (default), auto (a CUDA GPU where torch sees one, else the "
                        "CPU), cuda or cuda:N; the trained models come back to the CPU, so saved models, exports "
                        "and the card run anywhere")


def _device(text: str) -> str:
    from physics.data import DataError
    from physics.data._checks import check_device

    try:
        return check_device(text)
    except DataError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def add_solver_limits(p, max_iter: int, what: str = "per fit") -> None:
    """``--max-iter N`` (the limit: the same answer on any machine) and ``--max-wall-time S``
    (a last safeguard, off by default; a fit it stops says so)."""
    p.add_argument("--max-iter", type=POSITIVE_INT, default=max_iter, metavar="N",
                   help=f"IPOPT iterations {what} (default: {max_iter})")
    p.add_argument("--max-wall-time", type=POSITIVE_FLOAT, default=None, metavar="S",
                   help="safeguard: stop a solve after S seconds; the answer then depends on the machine "
                        "(default: off)")


def add_experiment_options(p, data: str, preset: str) -> None:
    """The options of the experiment commands; ``data`` and ``preset`` describe the choices of
    ``--data`` and ``--preset`` in this command."""
    p.add_argument("--data", default="virtual", help=data)
    p.add_argument("--preset", default="quick", metavar="{quick,paper}", help=preset)
    add_seed_option(p, "seed of the weights, the shuffling and the virtual data")
    add_device_option(p)
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    p.add_argument("--no-figures", action="store_true", help="skip the figures")


def check_data(args) -> None:
    """``--data`` read before any training: a folder's ``manifest.json`` must be valid JSON (the
    experiments read it after minutes of work otherwise)."""
    from pathlib import Path

    from physics.data.io import read_json

    folder = Path(args.data)
    if args.data not in ("virtual", "catheter_2023") and (folder / "manifest.json").exists():
        manifest = read_json(folder / "manifest.json", "manifest (`hyst simulate --paper-dataset`)")
        if not isinstance(manifest, dict) or not isinstance(manifest.get("files", []), list):
            raise _error(f"{folder / 'manifest.json'} is not a data manifest (an object with a 'files' list); "
                         "write the folder again with `hyst simulate --paper-dataset`.")


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


# -------------------------------------------------------------- saved models
ALLOW_EXTERNAL_HELP = ("read a .casadi model even if it calls an external library or is compiled on load: that "
                       "runs the library's native code, so only for files you trust (like unpickling)")


def add_model_options(p) -> None:
    """``--mode`` (a network's state) and ``--allow-external`` of the commands that read any saved model."""
    p.add_argument("--mode", choices=("carried", "window"), default=None,
                   help="LSTM state: carried (h, c) or window (input buffer); only for networks with these modes")
    p.add_argument("--allow-external", action="store_true", help=ALLOW_EXTERNAL_HELP)


def load_model(args, source: str):
    """The model at ``source`` (``hybrid.export.load``) at ``--rate`` (None: its own rate, else 25 Hz),
    honouring ``--allow-external``."""
    from hybrid.export import load

    rate = None if getattr(args, "rate", None) in (None, "auto") else rate_hz(args)
    return load(source, rate, allow_external=getattr(args, "allow_external", False))


def fit_outputs(source: str, n_y: int) -> tuple[str, ...]:
    """The output columns a fit of several outputs names (``hyst identify --output A,B,C``'s JSON, or the card of
    a ``hyst fit --output A,B,C`` folder), checked against its ``n_y`` outputs."""
    from pathlib import Path

    from hybrid.export._load import MODEL_DIR_MANIFEST, read_card
    from physics.data.io import read_json

    if (Path(source) / MODEL_DIR_MANIFEST).is_file():
        names = read_card(source).get("outputs")
    elif str(source).endswith(".pt"):  # a network of several outputs (hyst train --output A,B,C): its sidecar
        sidecar = Path(source).with_suffix(".json")
        names = (read_json(sidecar, "checkpoint sidecar").get("settings") or {}).get("outputs") if sidecar.is_file() else None
    else:
        names = read_json(source, "model file").get("outputs") if str(source).endswith(".json") else None
    if not (isinstance(names, list) and len(names) == n_y and all(isinstance(o, str) for o in names)):
        raise _error(f"'{source}' has {n_y} outputs but no list of their {n_y} column names ('outputs'); fit it "
                     "again with `hyst identify --output A,B,...`.")
    return tuple(names)


def model_outputs(model) -> int:
    """How many outputs a loaded model has: a physics Series's ``n_y``, a network's ``n_outputs_``, else one."""
    return int(getattr(model, "n_y", getattr(model, "n_outputs_", 1)))


def measured_indices(args, names) -> list[int]:
    """``--measure-outputs A,B``: the indices (ascending) of the outputs it names among ``names`` (a fit's outputs,
    :func:`fit_outputs`), each named once, or a refusal in one line."""
    picked = [n.strip() for n in str(args.measure_outputs).split(",")]
    if any(n not in names for n in picked) or len(set(picked)) != len(picked):
        raise _error(f"--measure-outputs {args.measure_outputs!r}: name each measured output once, among the model's "
                     f"outputs {', '.join(names)}.")
    return sorted(list(names).index(n) for n in picked)


def track_index(args, n_y: int, model: str) -> int | None:
    """``--track OUTPUT``: its index among the outputs a fit of several names (:func:`fit_outputs`); None without
    it. Refused for a model of one output, and for a name the fit does not have; ``model`` names the model in
    the refusal (``"--model fit.json"``, ``"'fit.json'"``)."""
    if n_y == 1:
        if args.track is not None:
            raise _error(f"--track {args.track!r} picks one output of a model of several; {model} has one output. "
                         "Leave --track out.")
        return None
    if args.track is None:
        return None
    names = fit_outputs(args.model, n_y)
    if args.track not in names:
        raise _error(f"--track {args.track!r} is not an output of {model}; its outputs are {', '.join(names)}.")
    return names.index(args.track)


def model_rate(args, source: str, model, then: str = "") -> float:
    """Settle ``--rate`` on the rate the model loaded from ``source`` runs at
    (:func:`hybrid.export._load.model_rate_hz`) and return it, Hz: the model's own when ``--rate``
    is left out, a refusal naming both rates when ``--rate`` is another (``then`` says what running at
    the model's rate means in the command), ``--rate`` (default :data:`DEFAULT_RATE_HZ`) for a model
    that stores none."""
    from hybrid.export._load import model_rate_hz

    own = model_rate_hz(source, model)
    given = None if args.rate in (None, "auto") else rate_hz(args)
    if given is not None and own is not None and abs(given - own) > 1e-9 * own:
        raise _error(f"--rate {given:.10g} Hz is not the {own:.10g} Hz '{source}' runs at; leave --rate out"
                     + (f" ({then})." if then else "."))
    args.rate = own if own is not None else given or DEFAULT_RATE_HZ
    return args.rate


def export_options(args, model, default_mode: str | None = None, **options) -> dict:
    """The options of ``export_model`` for ``model``: ``--mode`` (else ``default_mode``) when its network
    has that mode, a refusal in flag terms when ``--mode`` was given for one that has not."""
    net = getattr(model, "network_", None) or getattr(getattr(model, "residual_", None), "network_", None)
    modes = tuple(getattr(net, "modes", ()))
    if args.mode is not None and args.mode not in modes:
        what = f"a {net.name} network, whose only mode is {', '.join(modes)}" if net is not None and modes else \
            f"a {type(model).__name__} (no network state)"
        raise _error(f"--mode {args.mode} does not apply: the model is {what}. Leave --mode out.")
    mode = args.mode or (default_mode if default_mode in modes else None)
    return {**options, **({"mode": mode} if mode else {})}
