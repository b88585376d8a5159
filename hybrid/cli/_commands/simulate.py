"""``hyst simulate``: measured-looking data from the virtual catheter."""

from __future__ import annotations

import argparse
from pathlib import Path

from hybrid.cli._options import (DURATION, POSITIVE_FLOAT, POSITIVE_INT, add_rate_option,
                                 add_seed_option, bounded_float, rate_hz)

EPILOG = """\
examples:
  hyst simulate --effects lag,hysteresis,backlash --freq 0.15 --baseline mid --seed 0 --out run.csv
  hyst simulate --signal multisine --duration 60 --seed 3 --out multisine.csv
  hyst simulate --paper-dataset --out results/demo

The CSV holds time,u,y (commanded tendon displacement in mm, measured tip angle
in deg) and the true states: q_actual (actuator position after lag and delay),
q_backlash and z (when on) and y_true (the noise-free angle). --paper-dataset
runs the seed paper's protocol (train 0.1-0.5 Hz, test 0.15 and 0.45 Hz, three
baselines each) into DIR/train, DIR/test and DIR/manifest.json (written last).
Effects: lag, delay, backlash, hysteresis, nonlinearity, drift.
"""


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "simulate", help="simulate the virtual catheter (one run or the paper's dataset)",
        description="Simulate the virtual single-tendon catheter and write 'measured' data.",
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--effects", default="lag,hysteresis,backlash",
                   help="comma-separated effects to switch on, or none for the linear catheter (default: %(default)s)")
    p.add_argument("--input", choices=("measured", "command"), default="measured",
                   help="what column u is: the measured tendon displacement after the actuator "
                        "(as the real data) or the motor command (default: %(default)s)")
    p.add_argument("--signal", choices=("decaying", "multisine", "steps"), default="decaying",
                   help="command shape (default: %(default)s, the paper's decaying sinusoid)")
    p.add_argument("--freq", type=POSITIVE_FLOAT, default=0.1, help="decaying sinusoid frequency in Hz (default: %(default)s)")
    p.add_argument("--baseline", choices=("zero", "mid", "end"), default="zero",
                   help="decaying sinusoid baseline (default: %(default)s)")
    p.add_argument("--qmax", type=bounded_float(0, 10, " (mm)"), default=3.0,
                   help="decaying sinusoid amplitude in mm, at most 10 (the tendon travels 0-6 mm; "
                        "default: %(default)s)")
    p.add_argument("--duration", type=DURATION, default=None,
                   help="seconds (default: 7 cycles for decaying, 60 s otherwise)")
    add_seed_option(p, "noise and signal seed")
    p.add_argument("--noise", type=bounded_float(0, 1000, " (deg)", strict=False), default=0.15,
                   help="sensor noise std in deg, at most 1000 (default: %(default)s)")
    add_rate_option(p, "output sample rate")
    p.add_argument("--oversample", type=POSITIVE_INT, default=10,
                   help="integration steps per output sample (default: %(default)s)")
    p.add_argument("--paper-dataset", action="store_true",
                   help="run the paper's whole protocol; --out is then a folder")
    p.add_argument("--out", required=True, help="output CSV file (or folder with --paper-dataset)")
    p.set_defaults(func=run, out_kind="file")


def _signal(args):
    from physics.virtual import DecayingSinusoid, Multisine, RandomSteps

    if args.signal == "decaying":
        cycles = 7.0 if args.duration is None else args.duration * args.freq
        return DecayingSinusoid(frequency_hz=args.freq, baseline=args.baseline, q_max_mm=args.qmax,
                                cycles=cycles)
    duration = 60.0 if args.duration is None else args.duration
    if args.signal == "multisine":
        return Multisine(duration_s=duration, seed=args.seed)
    return RandomSteps(duration_s=duration, seed=args.seed)


def _write_paper_dataset(catheter, out: Path) -> dict:
    from physics.data.io import write_json
    from physics.virtual import paper_protocol

    split = paper_protocol(catheter)
    files = []
    for part, dataset in (("train", split.train), ("test", split.test)):
        for traj in dataset:
            rel = f"{part}/{traj.source}.csv"
            traj.to_csv(out / rel)
            files.append({"file": rel, "split": part, "frequency_hz": traj.meta["frequency_hz"],
                          "baseline": traj.meta["baseline"], "samples": traj.n})
    manifest = {
        "generator": "hyst simulate --paper-dataset",
        "effects": catheter.get_params()["effects"],
        "parameters": catheter.get_params(),
        "truth_model": {"spec": catheter.truth_model().spec,
                        "params": catheter.truth_model().param_dict()},
        "seed": catheter.seed,
        "noise_floor_deg": catheter.noise_floor,
        "rate_hz": catheter.rate_hz,
        "columns": ["time", "u", "y", *split.train[0].extra],
        "units": {"time": "s", "u": "mm", "y": "deg"},
        "files": files,
    }
    write_json(out / "manifest.json", manifest)  # last: its presence means the set is complete
    return manifest


#: Fewest samples per cycle of --freq, and fewest samples in a file.
MIN_PER_CYCLE, MIN_SAMPLES = 4, 10
#: Most integration steps of one run (--duration x --rate x --oversample).
MAX_STEPS = 10**8


def _check(args) -> None:
    """The options together: a sinusoid the rate can carry, a file of a useful length, a run that fits in memory."""
    from hybrid.cli._main import CLIError

    rate = rate_hz(args)
    if args.signal == "decaying" and args.freq > rate / MIN_PER_CYCLE:
        raise CLIError(f"--freq {args.freq:g} Hz is too fast for --rate {rate:g} Hz (at least {MIN_PER_CYCLE} "
                       f"samples per cycle: --freq <= {rate / MIN_PER_CYCLE:g}); lower --freq or raise --rate.")
    duration = (7.0 / args.freq if args.signal == "decaying" else 60.0) if args.duration is None else args.duration
    if args.paper_dataset:
        return
    if duration * rate + 1 < MIN_SAMPLES:
        raise CLIError(f"--duration {duration:g} s at --rate {rate:g} Hz gives fewer than {MIN_SAMPLES} samples; "
                       f"use --duration >= {(MIN_SAMPLES - 1) / rate:g}.")
    if duration * rate * args.oversample > MAX_STEPS:
        raise CLIError(f"--duration {duration:g} s at --rate {rate:g} Hz with --oversample {args.oversample} is "
                       f"{duration * rate * args.oversample:.3g} steps (the limit is {MAX_STEPS:.0e}); lower one of them.")


def run(args) -> int:
    from physics.virtual import VirtualCatheter, parse_effects

    from hybrid.cli._main import CLIError
    from physics.data import DataError

    _check(args)
    if not args.effects.strip():
        raise CLIError("--effects is empty; give the effects to switch on (e.g. --effects lag,hysteresis), "
                       "or --effects none for the linear catheter.")
    effects = parse_effects("" if args.effects.strip().lower() == "none" else args.effects)  # names the vocabulary
    catheter = VirtualCatheter(effects, input=args.input, noise_std_deg=args.noise, seed=args.seed, rate_hz=rate_hz(args),
                               oversample=args.oversample)
    out = Path(args.out)
    if args.paper_dataset:
        if out.suffix.lower() == ".csv":
            raise ValueError(f"--paper-dataset writes a folder; --out {out} looks like a file. "
                             "Give a folder, e.g. --out results/demo.")
        manifest = _write_paper_dataset(catheter, out)
        n_train = sum(f["split"] == "train" for f in manifest["files"])
        print(f"wrote {n_train} training and {len(manifest['files']) - n_train} test trajectories "
              f"to {out}/train and {out}/test, manifest {out / 'manifest.json'}")
    else:
        try:
            traj = catheter.run(_signal(args))
        except DataError as exc:
            if "non-finite" not in str(exc):
                raise
            raise CLIError(f"the simulation overflowed (a non-finite output) with --qmax {args.qmax:g} mm; the "
                           "catheter's tendon travels a few mm: give an amplitude of that order.") from None
        traj.to_csv(out)
        print(f"wrote {traj.n} samples ({traj.duration:.1f} s at {args.rate:g} Hz, "
              f"columns time,u,y,{','.join(traj.extra)}) to {out}")
    print(f"noise floor: {catheter.noise_floor:g} deg (std of the sensor noise)")
    return 0
