"""``hyst discover``: name the effects a physics model is missing, add them, show the gap shrink."""

from __future__ import annotations

import argparse

from hybrid.cli._options import (NONNEGATIVE_FLOAT, POSITIVE_INT, add_csv_options, add_solver_limits, load_csvs,
                                 open_fraction, output_names)

EPILOG = """\
example:
  hyst discover run_f0.1.csv run_f0.3.csv run_f0.6.csv --start linear \\
      --time time --input u --output y --rate 25 --out discovery/

Each step fits the model (CasADi + IPOPT), diagnoses the residual with sparse
regression (pysindy) on terms labelled by effect (actuator_lag, time_delay,
backlash, hysteresis, static_nonlinearity, drift), adds the block of the best
candidate in signal order and keeps it only if the held-out error drops by a
clear margin. Runs at several frequencies tell rate-dependent effects from
rate-independent ones. With three or more files every third one is held out;
otherwise the last 30% of each. Writes DIR/report.json and figures
(residual_signature.png, loops.png, gap.png).

With --output "Angle x,Pos x,Pos y" the effects are named on the first output, and
the chain found then reads every output: a cubic map per output and, for three
(the tip's angle and position), a constant-curvature arc, kept where it is lower
on runs held out of the fit by more than 3 % (as hyst fit chooses). The model of
every output is written to DIR/physics.json, as hyst identify --output writes it.
"""


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "discover", help="name the effects a physics model misses and add them",
        description="Grow a physics model one named effect at a time until its held-out "
                    "error reaches the noise floor, or no candidate effect helps.",
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("data", nargs="+", metavar="DATA.csv", help="measured trajectories")
    p.add_argument("--start", default="linear", help="starting model spec (default: %(default)s)")
    add_csv_options(p, several_outputs=True)
    p.add_argument("--max-steps", type=POSITIVE_INT, default=6, help="most effects added (default: 6)")
    p.add_argument("--margin", type=open_fraction, default=0.2,
                   help="share of the gap to the noise floor a block must close (default: 0.2)")
    p.add_argument("--working-rate", type=NONNEGATIVE_FLOAT, default=200.0, metavar="HZ",
                   help="search faster data at about this rate (every k-th sample; the final model is "
                        "re-fitted at the data's rate); 0: the data's own rate (default: %(default)s)")
    add_solver_limits(p, 300, "per fit")
    p.add_argument("--no-figures", action="store_true", help="write report.json only")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.set_defaults(func=run, out_kind="dir")


def run(args) -> int:
    from pathlib import Path

    from physics.data.io import write_json
    from hybrid.cli._main import CLIError
    from identification import SolverSettings
    from identification.discovery import DiscoveryThresholds, discover, plot_gap, plot_loops, plot_residual_signature
    from physics import Series

    Series.from_spec(args.start)  # a bad spec fails here, with the list of block names
    runs = load_csvs(args.data, args, warn_constant=True)
    report = discover(runs, start=args.start, max_steps=args.max_steps,
                      thresholds=DiscoveryThresholds(margin=args.margin),
                      solver=SolverSettings(max_iter=args.max_iter, max_wall_time=args.max_wall_time), verbose=True,
                      working_rate_hz=args.working_rate or None)
    out = Path(args.out)
    print(f"named effects: {', '.join(report.named_effects) or 'none'}; final model "
          f"'{report.final_model}'; RMSE {report.rmse_start:.3g} -> {report.rmse_final:.3g} "
          f"(noise floor {report.noise_floor:.3g})")
    if report.failed_fits:
        print(f"{len(report.failed_fits)} fit(s) failed on the way; discovery went on with the others "
              "(report.json 'failed_fits'):")
        for f in report.failed_fits:
            print(f"  '{f['spec']}' {f['settings'] or ''}: {f['status']} after {f['iterations']} iterations")
    several = _several(args, runs, report.final_model, out) if len(output_names(args)) > 1 else None
    data = report.to_dict()
    if several is not None:
        data["outputs"] = several
    if not args.no_figures:
        figs = {"residual_signature": plot_residual_signature(report.start_model, runs,
                                                              out / "residual_signature.png"),
                "loops": plot_loops(report.start_model, report.model, runs, out / "loops.png"),
                "gap": plot_gap(report, out / "gap.png")}
        data["figures"] = {k: v.name for k, v in figs.items()}
    write_json(out / "report.json", data)
    print(f"wrote {out / 'report.json'}")
    return 0


def _several(args, runs, chain: str, out) -> dict:
    """``--output A,B,...``: the chain discovered on the first output read by every output
    (:func:`hybrid.experiments.outputs_physics`), written to ``out/physics.json``; what report.json says of it."""
    from hybrid.cli._main import CLIError
    from hybrid.experiments import outputs_physics
    from hybrid.experiments._compare import WARMUP
    from hybrid.experiments._fit_outputs import tried_entries
    from physics.data import DataError
    from physics.data.io import write_json

    outputs = output_names(args)
    try:
        fit, tried, record = outputs_physics(chain, runs, outputs, warmup=WARMUP, how="discovery")
    except DataError as exc:
        raise CLIError(str(exc)) from None
    write_json(out / "physics.json", {**record, "train_files": [str(p) for p in args.data]})
    specs = ", ".join(tried_entries(tried, quote="'"))
    print(f"every output: '{fit.series.spec}' (held out: {specs}; kept '{tried['kept']}'); train RMSE "
          + ", ".join(f"{o} {fit.train_rmse[o]:.4g}" for o in outputs) + f"; wrote {out / 'physics.json'}")
    return {"outputs": list(outputs), "model": fit.series.spec, "tried": tried, "train_rmse": fit.train_rmse,
            "physics": "physics.json"}
