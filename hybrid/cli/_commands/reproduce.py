"""``hyst reproduce``: the seed paper's Table I (FNN, FNN-HIB, LSTM; forward and inverse)."""

from __future__ import annotations

import argparse

from hybrid.cli._options import POSITIVE_INT, add_experiment_options, check_data, parse_networks

EPILOG = """\
examples:
  hyst reproduce --out results/table1                       # virtual catheter, quick preset (< 5 min)
  hyst reproduce --data catheter_2023 --out results/cath    # real catheter: train set 1, test set 2
  hyst reproduce --data results/demo --preset paper --out results/paper   # a simulated folder, 500 epochs

writes OUT/table.csv (direction,model,test,rmse,nrmse; test 'all' = pooled), OUT/table.md,
OUT/lstm_modes.csv (LSTM window vs carried-state prediction), OUT/figures/*.png,
OUT/models/<direction>_<model>.pt (+ .json metadata) and OUT/run.json.
"""


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "reproduce", help="train FNN, FNN-HIB and LSTM forward and inverse; write the paper's Table I",
        description="Train the seed paper's three networks (FNN, FNN with a 50-sample history buffer, "
                    "2-layer LSTM) forward (tendon -> angle) and inverse (angle -> tendon), score them on "
                    "the test trajectories and write the paper's Table I and Fig. 7-like figures.",
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_experiment_options(
        p, data="'virtual' (default: the paper's protocol on the virtual catheter), 'catheter_2023', or a "
                "folder with train/*.csv and test/*.csv (time,u,y) from `hyst simulate --paper-dataset`",
        preset="quick (default): early stopping, strided windows, a few minutes; "
               "paper: 500 epochs on every window (about 2 h on 2 free cores)")
    # Undocumented overrides for tests and experiments.
    p.add_argument("--epochs", type=POSITIVE_INT, default=None, help=argparse.SUPPRESS)
    p.add_argument("--stride", type=POSITIVE_INT, default=None, help=argparse.SUPPRESS)
    p.add_argument("--max-train", type=POSITIVE_INT, default=None, help=argparse.SUPPRESS)
    p.add_argument("--models", default=None, help=argparse.SUPPRESS)
    p.set_defaults(func=run, out_kind="dir")


def run(args) -> int:
    from hybrid.experiments._datasets import load_data
    from hybrid.experiments._presets import check_preset
    from hybrid.experiments._reproduce import MODELS, reproduce
    from physics.data import DataSplit

    models = parse_networks(args.models, MODELS, what="model")
    check_preset(args.preset)
    overrides = {k: v for k, v in (("epochs", args.epochs), ("stride", args.stride)) if v is not None}
    if args.device != "cpu":  # recorded in run.json's overrides
        overrides["device"] = args.device
    check_data(args)
    split = load_data(args.data, seed=args.seed)
    if args.max_train is not None:
        split = DataSplit(split.train[:args.max_train], split.test)
    result = reproduce(split, args.out, preset=args.preset, seed=args.seed, models=models, overrides=overrides,
                       progress=False if args.no_progress else None, figures=not args.no_figures,
                       data_name=args.data)
    out = result.out
    print(f"trained {len(models)} models x 2 directions on {len(split.train)} trajectories "
          f"in {result.seconds:.0f} s; tested on {len(split.test)}")
    print((out / "table.md").read_text())
    print(f"results in {out}: table.csv, table.md, lstm_modes.csv, run.json, figures/ ({'none' if args.no_figures else 'png'}), "
          f"models/")
    return 0
