"""``hyst identify``: fit a physics model's parameters to CSV trajectories with IPOPT."""

from __future__ import annotations

import argparse

from hybrid.cli._options import (NONNEGATIVE_INT, POSITIVE_INT, add_csv_options, add_seed_option, add_solver_limits, dt_s,
                                load_csvs)

EPILOG = """\
example:
  hyst identify run1.csv run2.csv --model "lag+boucwen+linear" --test run3.csv \\
      --time time --input u --output y --rate 25 --starts 3 --out fit.json

  hyst identify data_1_*.txt --time Time --input "Tendon Disp." \
      --output "Angle x,Pos x,Pos y" --model "lag+gpi+poly+linear+arc" --out pose.json

Each CSV needs a header line; the columns named by --time/--input/--output are
read and resampled to --rate. --fixed holds a parameter (NAME=VALUE, or NAME at
its default); --free fits one its block holds by default (e.g. boucwen.n).

Several --output columns are fitted as one model: the chain of blocks keeps one
state, and each output reads its signal through its own map (the spec's last
'linear' becomes a cubic one per output), or, with '+arc' after 'linear', the tip's angle
and its position on a constant-curvature arc (--output ANGLE,X,Y or X,Y after the
angle). Each output's error counts over its own spread.
Exit status 0 only when the solver converged.
"""


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "identify", help="fit physics parameters to CSV trajectories (CasADi + IPOPT)",
        description="Fit the parameters of a physics model (blocks joined by '+') to one or "
                    "more CSV trajectories; print each parameter with its standard error and "
                    "write the fit as JSON.",
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("data", nargs="+", metavar="DATA.csv", help="training trajectories")
    p.add_argument("--model", default=None,
                   help="model spec (default: lag+boucwen+linear; with several --output columns 'auto': the spec "
                        "hyst fit's selection chooses for the first output, a cubic map per output)")
    p.add_argument("--test", action="append", nargs="+", default=[], metavar="T.csv",
                   help="held-out trajectories: report their RMSE")
    add_csv_options(p, several_outputs=True)
    p.add_argument("--starts", type=POSITIVE_INT, default=None,
                   help="number of starts (default: 3 for specs with a lag, backlash or Bouc-Wen block, "
                        "the extra ones skipped when the first fits down to the noise; else 1)")
    p.add_argument("--fixed", action="append", default=[], metavar="NAME[=VALUE]",
                   help="hold a parameter (repeatable)")
    p.add_argument("--free", action="append", default=[], metavar="NAME",
                   help="fit a parameter its block holds by default (repeatable)")
    p.add_argument("--warmup", type=NONNEGATIVE_INT, default=0, metavar="K",
                   help="with several --output columns: each run's first K samples set its state (fitted on the "
                        "angle, or the first output), and the error after them is fitted and reported, as a model "
                        "card scores each run (default 0: from rest at the first input)")
    p.add_argument("--x0", choices=("steady", "estimate"), default="steady",
                   help="initial states: steady at the first input, or estimated")
    add_solver_limits(p, 3000, "per start")
    add_seed_option(p, "seed of the extra starts")
    p.add_argument("--allow-failure", action="store_true",
                   help="write the result even if the solver did not converge (exit 1)")
    p.add_argument("--verbose", action="store_true", help="print IPOPT's iterations")
    p.add_argument("--out", required=True, metavar="FIT.json", help="where to write the JSON")
    p.set_defaults(func=run, out_kind="file", out_suffixes=(".json",))


def _parse_fixed(items: list[str]):
    from hybrid.cli._main import CLIError

    values, names = {}, []
    for item in items:
        if "=" in item:
            name, _, text = item.partition("=")
            try:
                values[name.strip()] = float(text)
            except ValueError:
                raise CLIError(f"--fixed {item!r}: the value must be a number, e.g. "
                               "--fixed boucwen.A=0.5.") from None
        else:
            names.append(item.strip())
    if names and values:
        raise CLIError("--fixed: give all as NAME=VALUE or all as NAME, not both.")
    return values or names or None


def run(args) -> int:
    from physics.data.io import write_json
    from identification import SolverSettings, identify
    from physics import Series

    from hybrid.cli._options import output_names

    train = load_csvs(args.data, args, warn_constant=True)
    if len(output_names(args)) > 1:
        return _several(args, train)
    args.model = args.model or "lag+boucwen+linear"
    if args.warmup:
        from hybrid.cli._main import CLIError

        raise CLIError("--warmup sets the runs' states in a fit of several --output columns; one output's fit starts "
                       "from --x0 (hyst fit scores after a warm-up window).")
    model = Series.from_spec(args.model, dt=dt_s(args))
    test_paths = [p for group in args.test for p in group]
    test = load_csvs(test_paths, args, held_out=True)
    fit = identify(model, train, fixed=_parse_fixed(args.fixed), free=args.free or None,
                   x0=args.x0, starts=args.starts, seed=args.seed, allow_failure=args.allow_failure,
                   solver=SolverSettings(max_iter=args.max_iter, max_wall_time=args.max_wall_time,
                                         verbose=args.verbose))
    out = fit.to_dict()
    out["train_files"] = [str(p) for p in args.data]
    print(fit.report())
    if test:
        pooled, per = fit.rmse(test)
        out.update(test_rmse=pooled, test_rmse_per_trajectory=list(per),
                   test_files=[str(p) for p in test_paths])
        print(f"test RMSE {pooled:.4g}  (" + ", ".join(f"{v:.3g}" for v in per) + ")")
    write_json(args.out, out)
    print(f"wrote {args.out}")
    return 0 if fit.success else 1


def _several(args, train) -> int:
    """``--output A,B,...``: one model of every output (:func:`identification.identify_outputs`)."""
    from physics.data.io import write_json
    from identification import SolverSettings, identify_outputs
    from hybrid.cli._main import CLIError
    from hybrid.cli._options import output_names
    from physics import Series

    if args.x0 != "steady" or args.free:
        raise CLIError("--x0 estimate and --free take one --output column; several outputs start from rest at the "
                       "first input and fit every parameter their blocks fit by default.")
    fixed = _parse_fixed(args.fixed) or []
    if isinstance(fixed, dict):
        raise CLIError("--fixed with several outputs holds parameters at their first fit's values: give names only "
                       "(--fixed arc.length).")
    outputs = output_names(args)
    test_paths = [p for group in args.test for p in group]
    test = load_csvs(test_paths, args, held_out=True)
    chain = {"starts": args.starts, "seed": args.seed,
             "solver": SolverSettings(max_iter=args.max_iter, max_wall_time=args.max_wall_time, verbose=args.verbose)}
    spec = args.model or "auto"
    tried = None
    if spec == "auto":  # the chain the selection chooses for the first output, read by maps or (three) an arc
        from hybrid.experiments import outputs_physics
        from identification.discovery import select_outputs_chain

        chosen = select_outputs_chain(train, outputs, warmup=args.warmup)
        if fixed:
            fit = identify_outputs(Series.from_spec(chosen, dt=dt_s(args)), train, outputs, fixed=fixed,
                                   warmup=args.warmup, chain_options=chain)
        else:
            fit, tried, _ = outputs_physics(chosen, train, outputs, warmup=args.warmup, how="selection",
                                            chain_options=chain)
    else:
        fit = identify_outputs(Series.from_spec(spec, dt=dt_s(args)), train, outputs, fixed=fixed,
                               warmup=args.warmup, chain_options=chain)
    out = {"model": fit.series.spec, "series": fit.series.to_dict(), "dt": fit.series.dt, "outputs": list(outputs),
           "parameters": fit.parameters,
           "standard_errors": fit.standard_errors, "train_rmse": fit.train_rmse, "status": fit.status,
           "iterations": fit.iterations, "wall_time_s": fit.wall_time_s, "warmup": fit.warmup,
           "train_files": [str(p) for p in args.data], **({} if tried is None else {"tried": tried})}
    how = f" (its chain chosen on '{outputs[0]}' by runs left out of the fit)" if spec == "auto" else ""
    if tried is not None:
        from hybrid.experiments._fit_outputs import tried_entries

        shown = ", ".join(tried_entries(tried, quote="'"))
        how += f" (held out: {shown}; kept '{tried['kept']}')"
    print(f"model {fit.series.spec}{how}, outputs {', '.join(outputs)}: {fit.status} after {fit.iterations} "
          f"iterations ({fit.wall_time_s:.1f} s)")
    for name, value in fit.parameters.items():
        se = fit.standard_errors.get(name)
        print(f"  {name:28s} {value:12.6g}" + ("  (held)" if se is None else f"  +/- {se:.3g}"))
    test_rmse = fit.rmse(test) if test else {}
    for name in outputs:
        print(f"  {name:28s} train RMSE {fit.train_rmse[name]:.4g}"
              + (f"  test RMSE {test_rmse[name]:.4g}" if test else ""))
    if test:
        out.update(test_rmse=test_rmse, test_files=[str(p) for p in test_paths])
    write_json(args.out, out)
    print(f"wrote {args.out}")
    return 0 if fit.status == "Converged" else 1
