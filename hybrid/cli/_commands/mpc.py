"""``hyst mpc``: closed-loop tracking with an MPC built on an exported model, against the model folder's
own model, the virtual catheter or another fitted model of the same actuator (``--plant``)."""

from __future__ import annotations

import argparse

from hybrid.cli._options import (DURATION, LO_HI, OUTPUT_LO_HI, POSITIVE_FLOAT, POSITIVE_INT, add_model_options,
                                add_model_rate_option, add_seed_option, bounded_float, dt_s, export_options, load_model,
                                model_rate, rate_hz)

EPILOG = """\
examples:
  hyst mpc --model fit.json --reference sine --out results/mpc
  hyst mpc --model "lag+boucwen+linear" --reference steps --solver ipopt --out results/mpc_steps
  hyst mpc --model lstm.pt --mode carried --reference ref.csv --horizon 15 --out results/mpc_lstm
  hyst mpc --model fit/ --plant lstm_fit/ --reference steps --out results/mpc_measured
  hyst mpc --model fit/ --y-bounds 30,55 --tighten --measure-every 25 --out results/mpc_band
  hyst mpc --model pose.json --track "Pos y" --out results/mpc_pose
  hyst mpc --model pose.json --track "Pos y" --y-bounds "Angle x:20,60" --out results/mpc_pose_bounded

The plant of a model folder from hyst fit is its own model, with its card's training
RMSE as Gaussian sensor noise (--plant auto, the default); of any other model the
virtual catheter's true physics (--effects) stepped at the model rate with sensor
noise (--noise; --plant virtual asks for it), or with --plant another fitted model of
the actuator (e.g. an LSTM trained on its measurements). Off the virtual catheter, in
the model's units: the input bounds are the range the model was fitted on (--u-bounds),
the rate limit a twelfth of it per sample (--du-max), the run starts at rest mid-range,
and the sine/steps references span the outputs the model reaches from there when swept
across those bounds. The MPC's model state is advanced by
running the model on the applied inputs (open-loop observer) and the filtered
output error is removed from the reference (--correction offset). A reference FILE
holds one output value (deg for the catheter) per line, or a CSV column named 'reference', one per sample.
With --y-bounds the model's output is kept inside LO,HI over the horizon (with --track,
OUTPUT:LO,HI keeps another output of the model inside them while the tracked one follows
the reference: the tip's angle within limits while its position is steered); --tighten
(a model folder from hyst fit) keeps its 90 % interval inside them instead, and with
--measure-every N that interval is the online one: re-centred and resized at each
measurement (hybrid.intervals.AdaptiveIntervals), so the output backs off from the
bounds by what the measurements say the model misses. With --solver fixed-sqp (the
C controller's) the bounds are a soft constraint (the output may pass them by about
a thousandth of the reference's excess) and the band reaches its control function
as the input h, as the C controller takes it each sample.
Writes OUT/closed_loop.csv, OUT/summary.json and OUT/closed_loop.png.
"""


def register(subparsers) -> None:
    from hybrid.control import SOLVERS  # the registered solvers are the choices

    p = subparsers.add_parser(
        "mpc", help="closed-loop MPC tracking of a tip-angle reference on the virtual catheter",
        description="Track a tip-angle reference with a model-predictive controller built on an "
                    "exported model; report tracking RMSE and solve times.",
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--model", required=True, help="fit JSON, .pt checkpoint, .casadi, folder, or physics spec")
    p.add_argument("--reference", default="sine", help="sine, steps, or a FILE (default: sine)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.add_argument("--horizon", type=POSITIVE_INT, default=25, help="prediction horizon, samples (default: 25)")
    p.add_argument("--solver", choices=("auto", *SOLVERS), default="auto",
                   help="auto (default): adjoint-sqp for hybrids (exact gradient, physics Hessian, compiled), "
                        "sqp (full NLP, qrqp) otherwise; fixed-sqp: a fixed number of SQP iterations per step "
                        "(the same cost every step, the controller hyst export --controller writes in C)")
    p.add_argument("--max-iter", type=POSITIVE_INT, default=None,
                   help="adjoint-sqp iterations per control step (default 3; 1 = real-time iteration), or "
                        "fixed-sqp's iterations (default 1)")
    p.add_argument("--plant", default="auto", metavar="MODEL",
                   help="'virtual' (the virtual catheter), another fitted model of the actuator (fit JSON, .pt, "
                        "folder, .casadi) to close the loop on, or 'auto' (default): a `hyst fit` folder's own model "
                        "with its card's training RMSE as sensor noise, else the virtual catheter")
    p.add_argument("--u-bounds", type=LO_HI, default=None, metavar="LO,HI",
                   help="input bounds (default: 0,6 mm for the virtual catheter; else the range the model "
                        "was fitted on); a negative low bound needs '=': --u-bounds=-1e-3,2e-3")
    p.add_argument("--du-max", type=POSITIVE_FLOAT, default=None,
                   help="largest input change per sample (default: a twelfth of the bounds, 0.5 mm on 0-6 mm)")
    p.add_argument("--duration", type=DURATION, default=20.0, help="length of sine/steps references, s (default: 20)")
    p.add_argument("--effects", default="lag,hysteresis,backlash",
                   help="the virtual catheter's effects (default: %(default)s)")
    p.add_argument("--noise", type=bounded_float(0, 1e150, strict=False), default=None,
                   help="sensor noise, output units (default: 0.15 deg on the virtual catheter, a folder's training "
                        "RMSE on its own model, 0 on another --plant model)")
    p.add_argument("--correction", choices=("offset", "none"), default="offset",
                   help="output-error correction (default: offset)")
    add_model_options(p)
    add_model_rate_option(p, "control rate")
    p.add_argument("--measure-every", type=POSITIVE_INT, default=None, metavar="N",
                   help="measure the plant's output only every N samples and feed it to a moving-horizon "
                        "estimator of the model's state and offset (default: every sample, offset filter)")
    p.add_argument("--y-bounds", type=OUTPUT_LO_HI, default=None, metavar="[OUTPUT:]LO,HI",
                   help="keep the model's output inside LO,HI over the horizon (a hard constraint with sqp; with ipopt, "
                        "auto's choice, an exact-penalty soft one, kept where it can be; a soft constraint with "
                        "fixed-sqp, the C controller's); "
                        "with --track, OUTPUT:LO,HI bounds that output of the model instead, e.g. 'Angle x:20,60'")
    p.add_argument("--track", default=None, metavar="OUTPUT",
                   help="a model of several outputs (hyst identify --output A,B,C): the output to track, by its "
                        "column name, e.g. 'Pos y'; its plant is the model itself (--plant auto) or, for an angle and "
                        "position on an arc, the virtual catheter with a tip (--plant virtual)")
    p.add_argument("--measure-outputs", default=None, metavar="A,B",
                   help="with --track and --measure-every: the outputs the tracker measures (e.g. 'Angle x,Pos x,Pos "
                        "y'), read by an estimator of every output's one state (default: the tracked output alone)")
    p.add_argument("--tighten", action="store_true",
                   help="with --y-bounds and a model folder from hyst fit: keep its prediction interval inside "
                        "the bounds (online with --measure-every)")
    add_seed_option(p, "seed of the noise and the steps")
    p.add_argument("--no-figures", action="store_true", help="skip the figure")
    p.set_defaults(func=run, out_kind="dir")


def _reference(args, model, u_bounds, start=None):
    from pathlib import Path

    import numpy as np

    from hybrid.cli._main import CLIError
    from hybrid.control import reference_signal, rest_output
    from hybrid.control._closed_loop import SINE_HZ

    if args.reference in ("sine", "steps"):
        margin = (u_bounds[1] - u_bounds[0]) / 12  # 0.5 mm of the catheter's 0-6 mm
        lo, hi = u_bounds[0] + margin, u_bounds[1] - margin
        if start is None:
            return reference_signal(args.reference, rest_output(model, lo), rest_output(model, hi),
                                    duration_s=args.duration, dt=dt_s(args), seed=args.seed)
        reached = _reached(model, lo, hi, start)
        if args.reference == "steps":
            return reference_signal("steps", *reached, duration_s=args.duration, dt=dt_s(args), seed=args.seed)
        # from rest at start, the sine joins the run where it passes the output there, within its first period
        # (a jump from rest to the sine's low end would be scored as tracking error)
        full = reference_signal("sine", *reached, duration_s=args.duration + 1 / SINE_HZ, dt=dt_s(args))
        n = int(round(args.duration / dt_s(args)))
        k = int(np.argmin(np.abs(full[:full.size - n] - rest_output(model, start))))
        return full[k:k + n]
    path = Path(args.reference)
    if not path.exists():
        raise CLIError(f"--reference must be sine, steps or a file; '{path}' does not exist.")
    ref = read_reference(path)
    if ref.size < 2:
        raise CLIError(f"{path}: the reference needs at least 2 angles (deg); it has {ref.size}.")
    return ref


def _reached(model, lo: float, hi: float, start: float, cycles: int = 2, samples: int = 200) -> tuple[float, float]:
    """The lowest and highest outputs ``model`` reaches over ``cycles`` slow sweeps between ``lo`` and ``hi``
    from rest at ``start``, after the first reversal (what a run from there can be steered to)."""
    import numpy as np

    leg = np.linspace(0.0, 1.0, samples)
    path = np.r_[start + (hi - start) * leg, *([hi + (lo - hi) * leg, lo + (hi - lo) * leg] * cycles)]
    x, ys = model.x0(start), []
    for u in path:
        x, y = (np.asarray(v, dtype=float).ravel() for v in model.step(x, u))
        ys.append(float(y[0]))
    settled = np.asarray(ys[samples:])
    return float(settled.min()), float(settled.max())


def _reference_length(args) -> int:
    """Samples of the reference: the file's, or --duration at --rate."""
    from pathlib import Path

    if args.reference in ("sine", "steps"):
        return int(args.duration * rate_hz(args)) + 1
    if not Path(args.reference).exists():
        return 10**9  # _reference says what is wrong
    return read_reference(Path(args.reference)).size


def read_reference(path) -> "np.ndarray":
    """The angles of a reference file: one per line, or a CSV column named 'reference' (comma,
    semicolon or tab separated; a semicolon file may use decimal commas; a BOM is ignored)."""
    import numpy as np

    from hybrid.cli._main import CLIError
    from physics.data.io import read_text

    rows = [(n, line) for n, line in enumerate(read_text(path, "reference file").splitlines(), start=1) if line.strip()]
    if not rows:
        raise CLIError(f"{path} is empty; write one angle (deg) per line, or a CSV column named 'reference'.")
    first = rows[0][1]
    sep = ";" if ";" in first else "," if "," in first else "\t" if "\t" in first else None
    column = 0
    if any(c.isalpha() for c in first):
        header = [h.strip().strip('"') for h in first.split(sep)]
        if "reference" not in header:
            raise CLIError(f"{path}: a CSV reference needs a column named 'reference'; its columns are {header}.")
        column, rows = header.index("reference"), rows[1:]
    ref = []
    for n, line in rows:
        cells = line.split(sep)
        cell = cells[column].strip().strip('"') if column < len(cells) else ""
        try:
            value = float(cell.replace(",", ".") if sep == ";" else cell)
        except ValueError:
            raise CLIError(f"{path}, line {n}: {cell!r} is not an angle (a number in deg).") from None
        if not np.isfinite(value):
            raise CLIError(f"{path}, line {n}: {cell!r} is not a finite angle.")
        ref.append(value)
    return np.asarray(ref, dtype=float)


def run(args) -> int:
    import numpy as np

    from physics.data.io import atomic_path, write_json
    from hybrid.cli._main import CLIError
    from hybrid.cli._options import bound_index, fit_outputs
    from hybrid.control import SOLVERS, Feedback, MPCSettings, TrackingMPC, run_closed_loop
    from hybrid.control._mpc_problem import choose_solver
    from physics.virtual import VirtualCatheter

    if args.correction == "none" and args.measure_every is not None:  # was: the estimator's correction, unsaid
        raise CLIError("--correction none contradicts --measure-every: the moving-horizon estimator corrects the "
                       "output with its offset; leave one of them out.")
    model = load_model(args, args.model)
    model_rate(args, args.model, model, "the controller runs at the model's rate, and --duration is in seconds of "
               "its clock")
    exported = _exported(args, model)
    exported.dt = exported.dt or dt_s(args)
    index = _tracked(args, exported)
    bound = bound_index(args, exported.n_y, index)
    other = bound is not None and bound != index  # the bounds on another output than the tracked one
    if other and args.tighten and args.measure_every is not None:
        raise CLIError("--tighten with --measure-every moves the tracked output's online band; with the bounds on "
                       f"another output than {args.track!r} leave --measure-every out (the bounded output's interval "
                       "is then the folder's, offline).")
    whole = exported
    seen = _measured_outputs(args, whole, index)
    exported = exported if index is None else exported.output(index)
    n_ref = _reference_length(args)
    if n_ref < 2 and args.reference in ("sine", "steps"):
        raise CLIError(f"--duration {args.duration:g} s at --rate {rate_hz(args):g} Hz is a single sample; "
                       f"use --duration >= {1 / rate_hz(args):g}.")
    if args.horizon > n_ref:
        raise CLIError(f"--horizon {args.horizon} is longer than the reference ({n_ref} samples); use at most "
                       f"--horizon {n_ref}, or a longer reference (--duration).")
    if exported.n_u > 1:
        measured = ", ".join(exported.meta.get("inputs", [])[1:])
        raise CLIError(f"--model {args.model} also reads measured inputs ({measured}), which the virtual catheter "
                       "plant of hyst mpc does not produce; run it in Python with "
                       "hybrid.control.run_closed_loop(..., measured=...).")
    own_noise = _own_plant(args) if index is None else 0.0
    if index is not None and args.plant == "auto":  # a model of several outputs closes the loop on itself
        args.plant = "itself"
    virtual = args.plant == "virtual" and index is None
    if virtual:  # the virtual catheter: its tendon's 0-6 mm, whatever range the model was fitted on
        plant, bounds = VirtualCatheter(effects=args.effects, rate_hz=rate_hz(args)).truth_model(), (0.0, 6.0)
    elif args.plant == "virtual":  # the tracked output of the virtual catheter's tip, by its role on the arc
        (plant, own_noise), bounds = _virtual_tip(args, model, index, every=seen is not None), (0.0, 6.0)
    elif args.plant == "itself":
        plant, bounds = (exported if seen is None else whole), exported.input_range
    else:
        plant = _plant(args, exported)
        bounds = exported.input_range or plant.input_range
        if bounds is None and args.u_bounds is None:
            raise CLIError(f"Neither --model {args.model} nor --plant {args.plant} records the input range it was "
                           "fitted on; give --u-bounds LO,HI.")
    # the interval the bounds keep inside: the tracked output's, or the bounded one's set on the model of them all
    online = _interval(args, exported) if not other else _interval(args, whole, bound)
    # "auto" resolved here as TrackingMPC resolves it, so --max-iter names the chosen solver's option
    solver = args.solver if args.solver != "auto" else choose_solver(exported, exported.step.numel_in(1) - 1,
                                                                     args.y_bounds)
    mpc = TrackingMPC(whole if other or seen is not None else exported,
                      MPCSettings(track=index, y_bounds={bound: args.y_bounds} if other else None)
                      if other or seen is not None else None,
                      horizon=args.horizon, u_bounds=args.u_bounds or bounds, du_max=args.du_max,
                      solver=solver, solver_options=None if args.max_iter is None else
                      {SOLVERS[solver].iterations_option: args.max_iter},
                      **({} if args.y_bounds is None else {"tighten": args.tighten} if other
                         else {"y_bounds": args.y_bounds, "tighten": args.tighten}))
    # on a fitted plant, its run starts at rest mid-range and the reference spans what the model reaches from
    # there (a hysteretic model's rest output far from where its runs started is a state no run showed)
    start = None if virtual else 0.5 * (mpc.u_bounds[0] + mpc.u_bounds[1])
    ref = _reference(args, exported, mpc.u_bounds, start)
    if not other:  # bounds on another output say nothing of the reference's reach
        _warn_unreachable(args, ref)
    noise = args.noise if args.noise is not None else 0.15 if virtual else own_noise
    estimator = None
    if seen is not None:  # the estimator of every output's one state, fed the outputs the tracker measures
        from hybrid.control import MovingHorizonEstimator

        estimator = MovingHorizonEstimator(whole, u_bounds=mpc.u_bounds)
    result = run_closed_loop(mpc, plant, ref, u0=start, noise_std_deg=noise, seed=args.seed, feedback=Feedback(
        correction=args.correction, measure_every=args.measure_every, online=online, estimator=estimator,
        outputs=seen))
    _warn_apart(args, result)
    from pathlib import Path

    out = Path(args.out)
    with atomic_path(out / "closed_loop.csv") as tmp:
        np.savetxt(tmp, result.table(), delimiter=",", fmt="%.10g", comments="",
                   header="time_s,reference_deg,u_mm,y_measured_deg,y_true_deg,y_model_deg,solve_time_s" if virtual
                   else "time_s,reference,u,y_measured,y_true,y_model,solve_time_s")
    summary = {"model": args.model, "plant": args.plant, "kind": exported.kind, "n_x": exported.n_x,
               **({} if index is None else {"track": args.track}),
               "reference": args.reference, "solver": mpc.solver_name, "horizon": args.horizon,
               "correction": "estimator" if args.measure_every else args.correction,
               "measure_every": args.measure_every,
               **({} if seen is None else {"measure_outputs": [fit_outputs(args.model, whole.n_y)[j] for j in seen]}),
               "rate_hz": rate_hz(args), "u_bounds": list(mpc.u_bounds), "du_max": mpc.du_max,
               **({"effects": args.effects, "noise_std_deg": noise, "rmse_deg": result.rmse_deg} if virtual
                  else {"noise_std": noise, "rmse": result.rmse_deg}),
               "y_bounds": None if args.y_bounds is None else list(args.y_bounds),
               **({} if not other else _bounded(args, whole, model, bound, result.u, start)),
               "interval": ("online" if online is not None else "offline") if args.tighten else None,
               **({} if result.half_width is None else {"mean_half_width": float(np.mean(result.half_width))}),
               "build_time_s": mpc.build_time, **mpc.stats.summary()}
    write_json(out / "summary.json", summary)
    unit = " deg" if virtual else ""
    share = 100 * summary["success_rate"]
    converged = (f"{mpc.solver.iterations} SQP iteration(s) on every step, the last one within tolerance on {share:.1f} %"
                 if mpc.solver_name == "fixed-sqp" else f"{share:.1f} % of solves converged")
    if not args.no_figures:
        _plot(result, out / "closed_loop.png", f"{exported.kind} MPC, RMSE {result.rmse_deg:.4g}{unit}", virtual)
    else:  # a figure left by an earlier run into this folder would pass for this run's
        (out / "closed_loop.png").unlink(missing_ok=True)
    print(f"tracking RMSE {result.rmse_deg:.4g}{unit} over {result.time.size} samples at {rate_hz(args):g} Hz; "
          f"solve time median {summary['median_ms']:.2f} ms, p99 {summary['p99_ms']:.2f} ms, worst "
          f"{summary['max_ms']:.2f} ms; {converged}; wrote {out}")
    if "bounded_range" in summary:
        lo, hi = summary["bounded_range"]
        print(f"{summary['bound']} (bounded to {args.y_bounds[0]:g},{args.y_bounds[1]:g}) ran from {lo:.4g} to {hi:.4g} "
              "on the plant")
    if result.half_width is not None:
        print(f"the output bounds kept the online interval inside them: mean half-width "
              f"{summary['mean_half_width']:.4g}{unit}, moved at each of the {int(np.ceil(result.time.size / args.measure_every))} measurements")
    return 0


def _bounded(args, whole, model, bound: int, u, start: float) -> dict:
    """The summary's entries of a bounded output other than the tracked one: its name and, where the plant is
    the model itself or the virtual catheter's tip, the range it ran over on the plant (noise-free)."""
    import numpy as np

    from hybrid.cli._options import fit_outputs

    entry = {"bound": fit_outputs(args.model, whole.n_y)[bound]}
    if args.plant == "itself":
        view = whole.output(bound)
    elif args.plant == "virtual":
        view = _virtual_tip(args, model, bound)[0]
    else:
        return entry
    y = view.simulate(np.asarray(u, dtype=float), x0=view.x0(start))
    return {**entry, "bounded_range": [float(np.min(y)), float(np.max(y))]}


def _warn_unreachable(args, ref) -> None:
    """A warning (stderr) when every sample of the reference lies outside --y-bounds: the output can only be
    held at a bound (a typo, or bounds in other units), and the solves report that they fail."""
    import sys

    import numpy as np

    if args.y_bounds is None:
        return
    lo, hi = args.y_bounds
    ref = np.asarray(ref, dtype=float)
    if ref.size and np.all((ref < lo) | (ref > hi)):
        print(f"hyst mpc: warning: the reference ({np.min(ref):.4g} to {np.max(ref):.4g}) lies outside --y-bounds "
              f"{lo:g},{hi:g} on every sample: the output is held at a bound, off the reference; check the bounds' "
              "units.", file=sys.stderr)


def _warn_apart(args, result) -> None:
    """A warning (stderr) when the plant's output never enters the reference's range: a plant or a reference
    in other units than the model (micro-strain against degrees), or an actuator the model is not of."""
    import sys

    import numpy as np

    y, ref = np.asarray(result.y_true, dtype=float), np.asarray(result.reference, dtype=float)
    if y.size and ref.size and np.all(np.isfinite(y)) and (y.max() < ref.min() or y.min() > ref.max()):
        print(f"hyst mpc: warning: the plant's output ({y.min():.4g} to {y.max():.4g}) never enters the reference's "
              f"range ({ref.min():.4g} to {ref.max():.4g}); are the plant (--plant), the reference and --model in "
              "the same units, of the same actuator?", file=sys.stderr)


def _interval(args, exported, bound: int | None = None):
    """With --tighten: the model folder's interval set on ``exported`` (``half_width``), and the online
    band that --measure-every moves (None without it). ``bound``: the index of the bounded output of a model of
    several (another than the tracked one), whose interval is set on the model of them all
    (``meta["interval_output"]``: :meth:`ExportedModel.output` of it keeps it)."""
    from hybrid.cli._main import CLIError

    if not args.tighten:
        return None
    if args.y_bounds is None:
        raise CLIError("--tighten keeps the model's interval inside the output bounds; give them with "
                       "--y-bounds LO,HI.")
    from hybrid.export._load import folder_intervals

    from hybrid.cli._options import fit_outputs

    name = args.track if bound is None else fit_outputs(args.model, exported.n_y)[bound]
    intervals, why = folder_intervals(args.model, name)
    if intervals is None:
        raise CLIError(f"--tighten needs the model's calibrated interval, and {why}.")
    exported.half_width = intervals.function(dt=exported.dt)
    if bound is not None:
        exported.meta["interval_output"] = bound
    if args.measure_every is None:
        return None
    from hybrid.intervals import AdaptiveIntervals

    return AdaptiveIntervals(every=args.measure_every).fit(intervals)


def _exported(args, model):
    """``model`` (from :func:`load_model`) exported for stepping (carried state where its network has one;
    MX for networks)."""
    from hybrid.export import export_model

    plain = type(model).__name__ in ("Series", "ExportedModel")
    return export_model(model, **export_options(args, model, "carried", **({} if plain else {"symbolic": "MX"})))


def _tracked(args, exported) -> int | None:
    """``--track``: the index of the tracked output of a model of several, None for a model of one; a model of
    several needs it."""
    from hybrid.cli._main import CLIError
    from hybrid.cli._options import fit_outputs, track_index

    index = track_index(args, exported.n_y, f"--model {args.model}")
    if index is None and exported.n_y > 1:
        raise CLIError(f"--model {args.model} has {exported.n_y} outputs "
                       f"({', '.join(fit_outputs(args.model, exported.n_y))}); name the one to track with --track.")
    return index


def _measured_outputs(args, whole, index: int | None) -> tuple[int, ...] | None:
    """``--measure-outputs``: the indices of the outputs the estimator reads (None: the tracked one alone, by the
    estimator of the tracked output), or a refusal in one line."""
    from hybrid.cli._main import CLIError
    from hybrid.cli._options import fit_outputs, measured_indices

    if args.measure_outputs is None:
        return None
    if index is None or args.measure_every is None:
        raise CLIError("--measure-outputs names the outputs measured every --measure-every N samples of a model of "
                       "several outputs; give --track and --measure-every too.")
    if args.tighten:
        raise CLIError("--tighten with --measure-every runs the tracked output's online band; with --measure-outputs "
                       "leave --tighten out.")
    return tuple(measured_indices(args, fit_outputs(args.model, whole.n_y)))


def _virtual_tip(args, model, index: int, every: bool = False):
    """The virtual catheter with a tip (``TipArc``'s defaults), seen through the output the model's arc gives
    at ``index`` (the angle, or a coordinate of the position), and its sensor's noise there; ``every``: the plant
    of every output the model's arc gives, in its order, and each one's noise."""
    from hybrid.cli._main import CLIError
    from hybrid.export import export_model
    from physics import Arc, Series
    from physics.virtual import VirtualCatheter, TipArc

    last = model.blocks[-1] if hasattr(model, "blocks") else None
    if not isinstance(last, Arc):
        raise CLIError(f"--plant virtual with --track: the virtual catheter's tip is an arc's angle and position, "
                       f"and --model {args.model} does not end in one; close the loop on the model itself "
                       "(--plant auto).")
    catheter = VirtualCatheter(effects=args.effects, rate_hz=rate_hz(args), tip=TipArc())
    truth = catheter.truth_model(pose=True)
    roles = last.outputs if every else (last.outputs[index],)
    noise = [catheter.noise_std_deg if role == "angle" else catheter.tip.noise_std_mm for role in roles]
    if not every:
        return export_model(truth).output(("angle", "x", "y").index(roles[0])), noise[0]
    arc = truth.blocks[-1].with_settings(outputs=tuple(roles))
    return export_model(Series(*truth.blocks[:-1], arc, dt=truth.dt, input_range=truth.input_range)), noise


def _own_plant(args) -> float:
    """Resolve ``--plant auto`` in ``args``: a `hyst fit` folder closes the loop on its own model, with its
    card's pooled training RMSE as the sensor noise (returned); anything else on the virtual catheter (0)."""
    from pathlib import Path

    from hybrid.experiments._card import pooled
    from hybrid.export._load import MODEL_DIR_MANIFEST
    from physics.data.io import read_json

    if args.plant != "auto":
        return 0.0
    manifest = Path(args.model) / MODEL_DIR_MANIFEST
    if not manifest.is_file():
        args.plant = "virtual"
        return 0.0
    args.plant = str(args.model)
    rows = [r for r in read_json(manifest, "model-folder manifest (`hyst fit`)").get("rows", []) if r.get("set") == "train"]
    return pooled(rows, "model_rmse") if rows else 0.0


def _plant(args, model):
    """The fitted model ``--plant`` as an exported step at the controller's sample time."""
    from hybrid.cli._main import CLIError

    own = argparse.Namespace(**{**vars(args), "mode": None})  # --mode is the controller model's
    plant = _exported(own, load_model(own, args.plant))
    if plant.n_u > 1:
        raise CLIError(f"--plant {args.plant} also reads measured inputs, which hyst mpc cannot give it; "
                       "run it in Python with hybrid.control.run_closed_loop(..., measured=...).")
    plant.dt = plant.dt or model.dt
    if abs(plant.dt - model.dt) > 1e-9 * model.dt:
        raise CLIError(f"--plant {args.plant} runs at {1 / plant.dt:.6g} Hz but --model {args.model} at "
                       f"{1 / model.dt:.6g} Hz; fit both at one rate.")
    return plant


def _plot(result, path, title, virtual=True):
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    from physics.data.io import atomic_path

    fig, ax = plt.subplots(3, 1, figsize=(8, 7), sharex=True)
    ax[0].plot(result.time, result.reference, "k--", label="reference")
    ax[0].plot(result.time, result.y, ".", ms=2, color="0.6", label="measured")
    ax[0].plot(result.time, result.y_true, label="tip angle")
    ax[0].set_ylabel("angle (deg)" if virtual else "output")
    ax[0].legend(loc="best", fontsize=8)
    ax[0].set_title(title)
    ax[1].plot(result.time, result.u)
    ax[1].set_ylabel("tendon (mm)" if virtual else "input")
    ax[2].plot(result.time, result.solve_times * 1e3)
    ax[2].set_ylabel("solve (ms)")
    ax[2].set_xlabel("time (s)")
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=110)
    plt.close(fig)
