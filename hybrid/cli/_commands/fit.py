"""``hyst fit``: measured runs to a model folder (physics, residual, CasADi step, model card)."""

from __future__ import annotations

import argparse
import sys

from hybrid.cli._options import (NONNEGATIVE_INT, add_csv_options, add_device_option, add_seed_option,
                                 add_selection_pool_options, check_scheduler, input_columns, load_csvs)

EPILOG = """\
examples:
  hyst fit runs/train/*.csv --test runs/test/*.csv --out model/       # select, identify, train, export
  hyst fit runs/*.csv --physics "lag+backlash+linear" --residual none --out model/
  hyst fit runs/*.csv --out model/ --resume                           # reuse the finished stages

Stages: physics (given by --physics, or auto: grown a block at a time, a block kept
only if it lowers the error on training runs left out of its fit), identify (IPOPT,
standard errors; each run's first --warmup samples set its state, as it is scored),
residual (--residual auto trains FNN-HIB and LSTM with every third run held out, or the
last branch of each of fewer than 3 runs, and keeps the best on them, or none when the
physics alone does as well; a network whose history is longer than the shortest run is
not tried), export (step.casadi, and C code where gcc is), model card (report.md, loops.png,
residual.png). `hyst predict`, `hyst export` and `hyst mpc` take MODEL_DIR.
Every --input column is used: `--input u,current` feeds the measured current to
the residual network (the step takes [u, current]; --residual none refuses it).
An input column that is constant, or repeats the output or time column, is refused.

Several --output columns (`--output "Angle x,Pos x,Pos y"`: the tip's angle and
position) make one model of all: the chain chosen for the first output keeps one
state, each output reads it through its own map, and the card gives each output's
RMSE beside a linear ARX of all outputs, its interval and their joint coverage. The
residual is one network of every output (--residual auto: kept only where it beats the
physics alone on the runs held out, each output's error over its own spread).
"""


def register(subparsers) -> None:
    from hybrid.networks import RESIDUALS

    p = subparsers.add_parser(
        "fit", help="measured runs to a model folder: physics, residual network, CasADi step and model card",
        description="Discover and identify the physics, train the residual network, export the step "
                    "function and write a model card, in one command.",
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("data", nargs="+", metavar="DATA.csv", help="training runs")
    p.add_argument("--test", nargs="+", default=[], metavar="T.csv", help="runs held out of every fit")
    p.add_argument("--physics", default="auto", metavar="SPEC|auto",
                   help="physics spec, or auto (default): chosen by leaving whole runs out")
    p.add_argument("--residual", default="auto", choices=RESIDUALS,
                   help="residual network (default: auto, chosen on held-out runs)")
    p.add_argument("--preset", default="quick", choices=("quick", "paper"),
                   help="training budget of the networks (default: %(default)s)")
    p.add_argument("--resume", action="store_true", help="reuse the stages already finished in MODEL_DIR")
    p.add_argument("--warmup", type=NONNEGATIVE_INT, default=10, metavar="K",
                   help="each run's first K measured samples set the model's state before it is scored (the card, "
                        "the residual's choice), and the export gets init(u_w, y_w) over K samples (default 10; "
                        "0: from rest)")
    add_selection_pool_options(p)
    p.add_argument("--group", default=None, metavar="KEY|PATTERN",
                   help="the condition each training run was recorded under (a day, a baseline): a regular "
                        "expression on the file names, whose first group (else the match) names it, e.g. "
                        "'day(\\d+)'. The intervals are calibrated leaving one whole condition out of the fit "
                        "(default: each run its own condition)")
    p.add_argument("--no-progress", action="store_true", help="do not print each stage")
    add_seed_option(p, "seed of the networks' training")
    add_device_option(p)
    add_csv_options(p, several_outputs=True)
    p.add_argument("--out", required=True, metavar="MODEL_DIR", help="the model folder to write")
    p.set_defaults(func=run, out_kind="dir")


def run(args) -> int:
    from hybrid.experiments._card import pooled
    from hybrid.experiments._fit import Columns, check_measured, fit_model_dir
    from hybrid.cli._options import output_names
    from identification.discovery import FALLBACK, PhysicsPolicy, Workers

    args.rate_given = None if args.rate == "auto" else args.rate
    command, measured = input_columns(args)  # every --input column is fed to the model, or refused here
    outputs = output_names(args)
    check_measured(args.residual, measured)
    check_scheduler(args.scheduler)
    train = load_csvs(args.data, args, refuse_constant=True)
    test = load_csvs(args.test, args, held_out=True) if args.test else []
    # the folder's physics policy: the spec or auto, the model folder's fallback, and where the selection's
    # fold fits run (--jobs processes, or the --scheduler's cluster)
    policy = PhysicsPolicy(args.physics, fallback=FALLBACK,
                           select_options={"workers": Workers(args.jobs, args.scheduler, args.device)})
    result = fit_model_dir(train, args.out, test=test, physics=policy, residual=args.residual,
                           preset=args.preset, seed=args.seed, resume=args.resume,
                           progress=not args.no_progress, warmup=args.warmup, group=args.group,
                           columns=Columns(args.time, command, outputs if len(outputs) > 1 else args.output,
                                           measured=measured))
    if result.outputs:
        return _print_several(args, result, command, measured)
    if result.substitution:  # the fallback stays; it is said, not silent
        print(f"warning: {result.substitution}", file=sys.stderr)
    by_set = {}
    for row in result.rows:
        by_set.setdefault(row["set"], []).append(row)
    rmses = ", ".join(f"{k} RMSE {pooled(rows, 'model_rmse'):.4g}" for k, rows in by_set.items())
    reused = f" (reused: {', '.join(result.reused)})" if result.reused else ""
    print(f"model rate {args.rate:g} Hz ({'the files' if args.rate_given is None else 'given by --rate'}); "
          f"columns time '{args.time}', input '{args.input}', output '{args.output}' (kept in the folder: "
          "hyst predict reads new files with them)")
    print(f"physics '{result.spec}', residual {result.residual}: {rmses}{reused}")
    _print_measured(command, measured, result)
    if result.intervals is not None:
        tested = [r for r in result.rows if r["set"] == "test" and "coverage" in r]
        seen = (f"; on the test runs they cover {sum(r['coverage'] for r in tested) / len(tested):.1%}"
                if tested else "")
        pieces = all(str(r).endswith("]") for r in result.intervals.runs_)  # "run.csv[40:80]": a piece of a run
        print(f"intervals: {result.intervals.level:.0%}, calibrated on {len(result.intervals.runs_)} held-out "
              f"{'pieces of the runs' if pieces else 'runs'}, "
              f"half-width {result.calibration['half_width']:.4g} in the data{seen} (hyst predict --interval)")
        report = result.calibration.get("report") or {}
        if report.get("notes"):
            print(("" if report["enough"] else "warning: ") + " ".join(report["notes"]))
    else:
        print(f"intervals: none ({result.calibration.get('why', 'not calibrated')})")
    print(f"wrote {result.path}: report.md, physics.json, "
          + ("" if result.residual == "none" else "model.pt, ")
          + ("" if result.intervals is None else "intervals.json, ") + "step.casadi, loops.png, residual.png")
    return 0


def _print_measured(command: str, measured, result) -> None:
    """Whether the measured inputs are read, and what the exported step takes."""
    if measured and result.dropped:
        print(f"measured inputs {', '.join(map(repr, measured))}: not read: the physics alone, which ignores them, "
              f"did better held out than every network that reads them (the exported step takes [{command}])")
    elif measured:
        print(f"measured inputs {', '.join(map(repr, measured))}: read by the {result.residual} residual network "
              f"beside the command (the exported step takes [{', '.join([command, *measured])}])")


def _print_several(args, result, command: str, measured) -> int:
    """The summary of a model folder of several outputs: each output's RMSE beside the ARX's, its interval."""
    from hybrid.experiments._fit_outputs import arx_ahead, summary, tried_entries

    table = summary(result.rows, result.outputs)
    print(f"model rate {args.rate:g} Hz ({'the files' if args.rate_given is None else 'given by --rate'}); "
          f"columns time '{args.time}', input '{args.input}', outputs '{args.output}' (kept in the folder)")
    tried = result.tried
    if len(tried.get("specs", {})) > 1:
        shown = ", ".join(tried_entries(tried, quote="'"))
        print(f"tried held out (each output's mean square error over its spread): {shown}; kept '{tried['kept']}'")
    network = "no residual network" if result.residual == "none" else f"residual {result.residual} of every output"
    reused = f" (reused: {', '.join(result.reused)})" if result.reused else ""
    print(f"physics '{result.spec}' (one state, read by every output), {network}{reused}:")
    _print_measured(command, measured, result)
    for part, entries in table.items():
        for name in result.outputs:
            e = entries[name]
            cover = f", interval covers {e['coverage']:.1%}" if "coverage" in e else ""
            print(f"  {part:5s} {name:16s} RMSE {e['model_rmse']:.4g} (linear ARX of all outputs {e['arx_rmse']:.4g})"
                  + cover)
    ahead = arx_ahead(result.calibration)
    if ahead:
        print(f"warning: on the runs held out of the fits a linear ARX of all outputs did better on {', '.join(ahead)} "
              "than the model; the folder keeps the model (see report.md)", file=sys.stderr)
    if result.intervals:
        joint = "; ".join(f"{part} {entries['joint_coverage']:.1%}" for part, entries in table.items())
        half = ", ".join(f"{o} {result.calibration['half_width'][o]:.4g}" for o in result.outputs)
        print(f"intervals: {result.calibration['level']:.0%} per output, half-widths {half}; every output inside "
              f"at once (joint): {joint} (hyst predict --interval)")
        print(f"intervals calibrated on {result.calibration['source']}; conditions: {result.calibration['conditions']}")
    else:
        print(f"intervals: none ({result.calibration.get('why', 'not calibrated')})")
    print(f"wrote {result.path}: report.md, physics.json, " + ("" if result.residual == "none" else "model.pt, ")
          + ("intervals.json, " if result.intervals else "")
          + "step.casadi, loops.png")
    return 0
