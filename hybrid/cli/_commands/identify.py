"""``hyst identify``: fit a physics model's parameters to CSV trajectories with IPOPT."""

from __future__ import annotations

import argparse

from hybrid.cli._options import POSITIVE_INT, add_csv_options, add_seed_option, add_solver_limits, dt_s, load_csvs

EPILOG = """\
example:
  hyst identify run1.csv run2.csv --model "lag+boucwen+linear" --test run3.csv \\
      --time time --input u --output y --rate 25 --starts 3 --out fit.json

Each CSV needs a header line; the columns named by --time/--input/--output are
read and resampled to --rate. --fixed holds a parameter (NAME=VALUE, or NAME at
its default); --free fits one its block holds by default (e.g. boucwen.n).
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
    p.add_argument("--model", default="lag+boucwen+linear",
                   help="model spec (default: %(default)s)")
    p.add_argument("--test", action="append", nargs="+", default=[], metavar="T.csv",
                   help="held-out trajectories: report their RMSE")
    add_csv_options(p)
    p.add_argument("--starts", type=POSITIVE_INT, default=None,
                   help="number of starts (default: 3 for specs with a lag, backlash or Bouc-Wen block, "
                        "the extra ones skipped when the first fits down to the noise; else 1)")
    p.add_argument("--fixed", action="append", default=[], metavar="NAME[=VALUE]",
                   help="hold a parameter (repeatable)")
    p.add_argument("--free", action="append", default=[], metavar="NAME",
                   help="fit a parameter its block holds by default (repeatable)")
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

    train = load_csvs(args.data, args, warn_constant=True)
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
