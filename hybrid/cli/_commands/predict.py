"""``hyst predict``: run a saved model over CSV trajectories, sequentially as a controller would."""

from __future__ import annotations

import argparse

from hybrid.cli._options import (LEVEL, NONNEGATIVE_INT, POSITIVE_INT, add_csv_options, load_csvs, load_model,
                                model_outputs, model_rate)

EPILOG = """\
example:
  hyst train run1.csv --model fnn-hib --out models/fnn_hib.pt
  hyst predict models/fnn_hib.pt run2.csv --out pred.csv

  hyst predict model/ run2.csv --out pred.csv        # the folder's warm-up: its card's RMSE for a run it scored
  hyst predict model/ run2.csv --warmup 0 --out pred.csv   # from rest at the first input

Writes time,u,y,y_pred (one row per sample at --rate; for an inverse model u is
the wanted output path and y_pred the predicted input) and prints the RMSE. With
--warmup K the first K samples are the measured window the model sets its state
from; the rows and the RMSE are those of the samples after it. A model folder
(`hyst fit`) starts, unless --warmup says otherwise, as its card scored each run:
after the folder's own warm-up window; other models start from rest at the first input. With --interval 0.9
(a model folder) also y_lo,y_hi,outside: the bounds of a 90 % interval and a flag
where the input leaves the training data. With both --interval and --measure-every N the
band learns from the measurements: centred on the free run plus the error forecast from
the measured errors (the last one and a running offset), its width scaled to the run's own
forecast misses and adapted from the misses (adaptive conformal inference,
hybrid.intervals.AdaptiveIntervals); 'outside' then also flags the samples after a measured
error beyond the offline band, and with --warmup every sample of a run whose warm-up window
lies outside the training data.
""" 


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "predict", help="predict with a saved model (from `hyst train`) on a CSV trajectory",
        description="Load a learned or hybrid checkpoint and predict over a trajectory.",
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("model", metavar="MODEL.pt", help="checkpoint written by `hyst train`, physics fit JSON "
                   "(`hyst identify`) or model folder (`hyst fit`)")
    p.add_argument("data", metavar="DATA.csv", help="trajectory to predict")
    add_csv_options(p, rate="resample to this rate, Hz (default, or auto: the rate the model runs at, the one it "
                           "was fitted at; another rate is refused)")
    p.add_argument("--out", required=True, metavar="PRED.csv", help="predictions to write")
    p.add_argument("--warmup", type=NONNEGATIVE_INT, default=None, metavar="K",
                   help="set the model's state from the CSV's first K measured samples (input and output) and "
                        "predict the rest; 0 starts from rest at the first input (default: a model folder's own "
                        "warm-up, the one its card scored each run after; 0 for other models)")
    p.add_argument("--measure-every", type=POSITIVE_INT, default=None, metavar="N",
                   help="the output is measured every N samples (from the first predicted one): each sample is "
                        "predicted from the measurements before it, through a moving-horizon estimator of the "
                        "model's state and output offset (forward models); writes a 'measured' column")
    p.add_argument("--measure-outputs", default=None, metavar="A,B",
                   help="with --measure-every, a model of several outputs: the outputs measured (e.g. 'Pos x,Pos y': "
                        "a camera that sees the tip's position, not its angle); the one state they share is fitted "
                        "on them and every output predicted from it (default: every output)")
    p.add_argument("--interval", type=LEVEL, default=None, metavar="LEVEL",
                   help="also write the bounds of a LEVEL prediction interval (e.g. 0.9) as y_lo,y_hi and a column "
                        "'outside' (1 where the input leaves the training data); needs a model folder from "
                        "`hyst fit`, whose held-out runs calibrated them")
    # no defaults for the columns: a model folder (`hyst fit`) remembers the ones it was fitted on
    p.set_defaults(func=run, out_kind="file", out_suffixes=(".csv",), rate=None, time=None, input=None, output=None)


def _manifest(args, folder: bool) -> dict | None:
    """A model folder's manifest (``hyst fit``'s ``card.json``: its columns and warm-up), or None."""
    from pathlib import Path

    from hybrid.export._load import MODEL_DIR_MANIFEST
    from physics.data.io import read_json

    if not folder:
        return None
    info = read_json(Path(args.model) / MODEL_DIR_MANIFEST, "model-folder manifest (`hyst fit`)")
    return info if isinstance(info, dict) else {}


def _columns(args, manifest: dict | None) -> None:
    """``--time/--input/--output``: as given, else the columns a model folder was fitted on (its
    ``manifest``), else ``time,u,y``; says so when it takes a folder's."""
    remembered = (manifest.get("columns") or {}) if manifest is not None else {}
    taken = []
    for key, default in (("time", "time"), ("input", "u"), ("output", "y")):
        if getattr(args, key) is None:
            value = remembered.get(key)
            if isinstance(value, str) and value:
                taken.append(f"{key} '{value}'")
            setattr(args, key, value if isinstance(value, str) and value else default)
    if taken:
        print(f"columns from {args.model}: {', '.join(taken)}")


def _warmup(args, manifest: dict | None) -> str:
    """``--warmup``: as given, else a model folder's own (its ``manifest``: its card's protocol), else 0
    (from rest); returns the words that say where a default came from ("" when given)."""
    from hybrid.experiments._compare import WARMUP

    if args.warmup is not None:
        return ""
    if manifest is None:
        args.warmup = 0
        return " (the default for a model outside a folder)"
    args.warmup = int(manifest.get("warmup", WARMUP))
    return " (the model folder's, as its card scores each run; --warmup K for another)"


def run(args) -> int:
    import numpy as np

    from physics.data.io import atomic_path
    from hybrid.cli._main import CLIError
    from physics.data import rmse, warmup_split

    from pathlib import Path

    from hybrid.export._load import MODEL_DIR_MANIFEST
    from physics import Series

    folder = (Path(args.model) / MODEL_DIR_MANIFEST).is_file()
    if not folder and not str(args.model).endswith((".pt", ".json")):
        raise CLIError(f"No checkpoint at '{args.model}': predict reads a .pt written by `hyst train --out`, "
                       "a fit JSON or a folder written by `hyst fit`.")
    model = load_model(args, args.model)
    # a physics fit predicts by simulating from its initial state
    predict = (lambda t, warmup=None: model.simulate(t.u, warmup=warmup)
               ) if isinstance(model, Series) else getattr(model, "predict", None)
    if predict is None:
        raise CLIError(f"'{args.model}' is not a learned or hybrid checkpoint; predict reads a .pt written by "
                       "`hyst train --out`.")
    model_rate(args, args.model, model, "the CSV is then resampled to the model's rate")
    if model_outputs(model) > 1:
        return _several(args, model, folder)
    if args.measure_outputs is not None:
        raise CLIError(f"--measure-outputs picks the measured outputs of a model of several; '{args.model}' has one "
                       "output. Leave it out.")
    intervals = _intervals(args, folder)
    manifest = _manifest(args, folder)
    _columns(args, manifest)
    whose = _warmup(args, manifest)
    traj = load_csvs([args.data], args, refuse_copies=False)[0]  # a ramp input may equal its time stamps
    if getattr(model, "direction", "forward") == "inverse":
        traj = traj.swap()
    if args.warmup >= traj.n:
        fix = " (the model folder's; give a shorter --warmup, 0 from rest)" if whose else ""
        raise CLIError(f"--warmup {args.warmup}{fix} must leave samples to predict: '{args.data}' has "
                       f"{traj.n} samples at {args.rate:g} Hz.")
    band, start = None, None
    if args.measure_every is not None:
        if getattr(model, "direction", "forward") == "inverse":
            raise CLIError("--measure-every corrects a forward model's predicted output; this model is an inverse.")
        pred, measured = _with_measurements(model, traj, args.warmup, args.measure_every)
        if intervals is not None:  # the band of the free run, centred and sized online by the measurements
            from hybrid.intervals import AdaptiveIntervals

            window, rest = warmup_split(traj, args.warmup)
            free = np.asarray(predict(rest) if window is None else predict(rest, warmup=window), dtype=float).ravel()
            online = AdaptiveIntervals(every=args.measure_every, level=args.interval).fit(intervals)
            band = online.run(free, rest.u, rest.dt, rest.y, measured, window=window)
        traj = traj.segment(args.warmup, traj.n)
    else:
        window, traj = warmup_split(traj, args.warmup)
        pred = predict(traj) if window is None else predict(traj, warmup=window)
        measured = None
        start = window
    columns, header = [traj.time, traj.u, traj.y, pred], "time,u,y,y_pred"
    if measured is not None:
        columns, header = [*columns, measured.astype(int)], header + ",measured"
    if band is None and intervals is not None:
        band = intervals.interval(pred, traj.u, traj.dt, args.interval, window=start)
    if band is not None:
        columns, header = [*columns, band.lo, band.hi, band.outside.astype(int)], header + ",y_lo,y_hi,outside"
    if band is not None:  # what the training runs can promise of this run's band, said before it is scored
        _interval_caveats(intervals, traj, args.interval)
    with atomic_path(args.out) as tmp:
        np.savetxt(tmp, np.column_stack(columns), delimiter=",", fmt="%.17g", header=header, comments="")
    after = (f" after a warm-up of {args.warmup} measured samples{whose}" if args.warmup
             else f" from rest at the first input{whose}")
    fed = (f", each from the measurements before it (one every {args.measure_every} samples, "
           f"{int(measured.sum())} in all)" if measured is not None else "")
    print(f"wrote {traj.n} predictions{after}{fed} to {args.out}; RMSE {rmse(traj.y, pred):.4g}")
    if band is not None:
        from hybrid.intervals import coverage

        how = " (online: adapted at each measurement)" if measured is not None else ""
        print(f"{args.interval * 100:.4g}% interval{how}: mean width {np.mean(band.hi - band.lo):.4g}, covers "
              f"{coverage(traj.y, band.lo, band.hi):.1%} of the measured samples")
        if band.outside.any():
            first = int(np.argmax(band.outside))
            what = ("have inputs outside the training data or follow a measured error beyond the offline band"
                    if measured is not None else "have inputs outside the training data")
            print(f"warning: {int(band.outside.sum())} of {traj.n} samples ({band.outside.mean():.1%}) {what} "
                  f"(first at t = {traj.time[first]:.4g} s): the model extrapolates there "
                  "and its interval is a guess ('outside' column)")
    return 0


def _several(args, model, folder: bool) -> int:
    """A fit of several outputs (``hyst identify --output A,B,C``, a ``hyst fit --output A,B,C`` folder, or a network
    of ``hyst train --output A,B,C``): each output's prediction beside its measurement, named, after the fit's warm-up
    window (``--warmup K`` for another; 0 from rest); with ``--interval`` (a folder), each output's bounds and the
    joint coverage."""
    import numpy as np

    from identification._outputs import output_columns
    from physics import Series
    from physics.data import rmse
    from physics.data.io import atomic_path, read_json
    from hybrid.cli._main import CLIError
    from hybrid.cli._options import fit_outputs
    from hybrid.experiments._fit_outputs import predict_after

    physics = isinstance(model, Series)
    outputs = fit_outputs(args.model, model_outputs(model))
    if args.output not in (None, ",".join(outputs)):
        raise CLIError(f"--output {args.output!r}: '{args.model}' models the outputs {', '.join(outputs)}, read from "
                       "the CSV by those names; leave --output out.")
    seen = _measured_outputs(args, outputs)
    if args.measure_every is not None and args.interval is not None:
        raise CLIError("--interval with --measure-every takes a model of one output (its band adapts to the measured "
                       "errors); for a model of several outputs give one of them.")
    intervals = _intervals_per_output(args, outputs) if args.interval is not None else None
    manifest = _manifest(args, folder)
    whose = ""
    if args.warmup is None:
        info = manifest if folder else read_json(args.model, "model file") if physics else {}
        args.warmup, whose = int(info.get("warmup", 0)), " (the fit's)" if physics or folder else ""
    args.output = ",".join(outputs)
    _columns(args, manifest)
    traj = load_csvs([args.data], args, refuse_copies=False)[0]
    if args.warmup >= traj.n:
        raise CLIError(f"--warmup {args.warmup}{whose} must leave samples to predict: '{args.data}' has {traj.n} "
                       f"samples at {args.rate:g} Hz.")
    measured = output_columns(traj, outputs, refuse_copies=False)
    k = args.warmup
    if args.measure_every is None:  # a physics fit's state from the window's outputs, a network's from its inputs
        pred, fed = predict_after(model, traj, measured, k), None
    else:
        pred, fed = _with_measurements(model, traj, k, args.measure_every, (measured, seen))
    columns, names = [traj.time[k:], traj.u[k:]], ["time", "u"]
    inside = np.ones(traj.n - k, dtype=bool)
    covers = []
    for j, o in enumerate(outputs):
        columns += [measured[k:, j], pred[:, j]]
        names += [o, f"{o}_pred"]
        if intervals is not None:
            band = intervals[o].interval(pred[:, j], traj.u[k:], traj.dt, level=args.interval)
            columns += [band.lo, band.hi]
            names += [f"{o}_lo", f"{o}_hi"]
            hit = (measured[k:, j] >= band.lo) & (measured[k:, j] <= band.hi)
            inside &= hit
            covers.append(f"{o} {np.mean(hit):.1%}")
    if fed is not None:
        columns, names = [*columns, fed.astype(int)], [*names, "measured"]
    with atomic_path(args.out) as tmp:
        np.savetxt(tmp, np.column_stack(columns), delimiter=",", fmt="%.17g", header=",".join(names), comments="")
    scores = ", ".join(f"{o} {rmse(measured[k:, j], pred[:, j]):.4g}" for j, o in enumerate(outputs))
    after = f"after a warm-up of {k} measured samples{whose}" if k else f"from rest at the first input{whose}"
    if fed is not None:
        after += (f", each from the measurements of {', '.join(outputs[j] for j in seen)} before it (one every "
                  f"{args.measure_every} samples, {int(fed.sum())} in all)")
    print(f"wrote {traj.n - k} predictions of {len(outputs)} outputs {after} to {args.out}; RMSE {scores}")
    if intervals is not None:
        print(f"{args.interval:.0%} intervals per output cover {', '.join(covers)}; every output inside at once: "
              f"{np.mean(inside):.1%}")
    return 0


def _measured_outputs(args, outputs) -> list[int]:
    """``--measure-outputs``: the indices of the outputs measured (default: all), or a refusal in one line."""
    from hybrid.cli._main import CLIError

    if args.measure_outputs is None:
        return list(range(len(outputs)))
    if args.measure_every is None:
        raise CLIError("--measure-outputs names the outputs measured every --measure-every N samples; give "
                       "--measure-every too.")
    from hybrid.cli._options import measured_indices

    return measured_indices(args, outputs)


def _intervals_per_output(args, outputs) -> dict:
    """``--interval`` on a model of several outputs: the folder's calibrated interval of each, or a refusal."""
    from hybrid.cli._main import CLIError
    from hybrid.export._load import folder_intervals

    found = {}
    for o in outputs:
        found[o], why = folder_intervals(args.model, o)
        if found[o] is None:
            raise CLIError(f"--interval: '{args.model}' has no calibrated intervals: {why}.")
    return found


def _interval_caveats(intervals, traj, level: float) -> None:
    """Where no band from the training runs can promise ``level`` for this run: too few of them, or the
    run's amplitude or rate outside theirs (the band then widens with that distance)."""
    outside = intervals.run_outside(traj.u, traj.dt)
    if outside:
        print(f"warning: this run's {outside} lies outside the training runs: its band widens with that "
              f"distance, and no {level * 100:.4g}% coverage is promised")
    report = intervals.report(level)
    if not report.enough:
        print(f"note: the {level * 100:.4g}% band rests on {report.units} held-out {report.unit}, fewer or less "
              "varied than a guaranteed coverage needs (see the model card)")


def _intervals(args, folder: bool):
    """The model folder's calibrated intervals when --interval asks for them, or a clear refusal."""
    from hybrid.cli._main import CLIError
    from hybrid.export._load import folder_intervals

    if args.interval is None:
        return None
    intervals, why = folder_intervals(args.model)
    if intervals is None:
        raise CLIError(f"--interval: '{args.model}' has no calibrated intervals: {why}.")
    return intervals


def _with_measurements(model, traj, warmup: int, every: int, several=None):
    """Predictions of the samples after ``warmup`` through a moving-horizon estimator fed with the
    warm-up window's every sample and then every ``every``-th one; returns them and the mask of the
    measured samples among them. ``several``: a model of several outputs, ``(measured, seen)``: its outputs'
    columns (n, k), of which only those indexed by ``seen`` are fed (each output predicted)."""
    import numpy as np

    from hybrid.control import MovingHorizonEstimator, measurement_mask
    from hybrid.export import export_model
    from physics import Series

    exported = export_model(model, **({} if isinstance(model, Series) else {"symbolic": "MX"}))
    bounds = exported.input_range or (float(np.min(traj.u)), float(np.max(traj.u)))
    if not bounds[1] > bounds[0]:
        bounds = (bounds[0] - 1.0, bounds[0] + 1.0)
    mask = np.r_[np.ones(warmup, dtype=bool), measurement_mask(traj.n - warmup, every)]
    if several is None:
        y = np.where(mask, traj.y, np.nan)
    else:
        measured, seen = several
        y = np.full(measured.shape, np.nan)
        y[np.ix_(mask, seen)] = measured[np.ix_(mask, seen)]
    # a model that also reads measured inputs steps on [u, those columns], in the model's order (a hybrid's
    # extra_inputs_, a learned model's features); load_csvs keeps them in traj.extra
    names = model.extra_inputs_ if hasattr(type(model), "extra_inputs_") else tuple(getattr(model, "features", ()))
    u = traj.u if exported.n_u == 1 else np.column_stack([traj.u, *(traj.extra[k] for k in names)])
    pred = MovingHorizonEstimator(exported, u_bounds=bounds).filter(u, y)
    return pred[warmup:], mask[warmup:]
