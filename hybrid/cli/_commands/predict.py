"""``hyst predict``: run a saved model over CSV trajectories, sequentially as a controller would."""

from __future__ import annotations

import argparse

from hybrid.cli._options import add_csv_options, load_csvs

EPILOG = """\
example:
  hyst train run1.csv --model fnn-hib --out models/fnn_hib.pt
  hyst predict models/fnn_hib.pt run2.csv --out pred.csv

Writes time,u,y,y_pred (one row per sample at --rate; for an inverse model u is
the wanted output path and y_pred the predicted input) and prints the RMSE.
"""


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "predict", help="predict with a saved model (from `hyst train`) on a CSV trajectory",
        description="Load a learned or hybrid checkpoint and predict over a trajectory.",
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("model", metavar="MODEL.pt", help="checkpoint written by `hyst train`, physics fit JSON "
                   "(`hyst identify`) or model folder (`hyst fit`)")
    p.add_argument("data", metavar="DATA.csv", help="trajectory to predict")
    add_csv_options(p)
    p.add_argument("--out", required=True, metavar="PRED.csv", help="predictions to write")
    p.set_defaults(func=run, out_kind="file", out_suffixes=(".csv",))


def run(args) -> int:
    import numpy as np

    from physics.data._atomic import atomic_path
    from hybrid.cli._main import CLIError
    from hybrid.export import load
    from physics.data import rmse

    from pathlib import Path

    from hybrid.export._load import MODEL_DIR_MANIFEST
    from physics import Series

    folder = (Path(args.model) / MODEL_DIR_MANIFEST).is_file()
    if not folder and not str(args.model).endswith((".pt", ".json")):
        raise CLIError(f"No checkpoint at '{args.model}': predict reads a .pt written by `hyst train --out`, "
                       "a fit JSON or a folder written by `hyst fit`.")
    model = load(args.model)
    # a physics fit predicts by simulating from its initial state
    predict = (lambda t: model.simulate(t.u)) if isinstance(model, Series) else getattr(model, "predict", None)
    if predict is None:
        raise CLIError(f"'{args.model}' is not a learned or hybrid checkpoint; predict reads a .pt written by "
                       "`hyst train --out`.")
    traj = load_csvs([args.data], args)[0]
    if getattr(model, "direction", "forward") == "inverse":
        traj = traj.swap()
    pred = predict(traj)
    with atomic_path(args.out) as tmp:
        np.savetxt(tmp, np.column_stack([traj.time, traj.u, traj.y, pred]), delimiter=",",
                   fmt="%.17g", header="time,u,y,y_pred", comments="")
    print(f"wrote {traj.n} predictions to {args.out}; RMSE {rmse(traj.y, pred):.4g}")
    return 0
