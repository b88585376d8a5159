"""``hyst export``: a fitted model as a CasADi step function (and C code)."""

from __future__ import annotations

import argparse

from hybrid.cli._options import (HORIZON, OUTPUT_LO_HI, POSITIVE_INT, WINDOW, add_model_options, add_model_rate_option,
                                bound_index, dt_s, export_options, load_model, model_outputs, model_rate)

EPILOG = """\
examples:
  hyst export fit.json --out step.casadi                    # physics fit from `hyst identify`
  hyst export results/table1/models/forward_lstm.pt --mode carried --out lstm.casadi --c-code lstm_c
  hyst export "lag+boucwen+linear" --out default.casadi

MODEL is a fit JSON (keys 'model', 'parameters'), a learned checkpoint (.pt), a
folder holding one of them, or a physics spec. Writes OUT (load it with
casadi.Function.load, no torch needed) and OUT with suffix .json (state names,
initial-state rule); --c-code DIR also writes step.c/step.h and, when gcc is
present, libstep.so (casadi.external) and a C demo program.
"""


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "export", help="export a fitted model as a CasADi function (.casadi) and C code",
        description="Write a fitted model as Function('step', [x, u], [x_next, y]) in physical units, "
                    "with its parameters, weights and scaling folded in.",
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("model", metavar="MODEL", help="fit JSON, .pt checkpoint, folder, or physics spec")
    p.add_argument("--out", required=True, metavar="STEP.casadi", help="where to write the function")
    p.add_argument("--c-code", metavar="DIR", help="also write (and compile, if gcc is present) C code")
    p.add_argument("--symbolic", choices=("auto", "SX", "MX"), default="auto",
                   help="auto (default): SX for physics (flat scalar graph), MX for models with networks "
                        "(compact graph of dense loops: 3x faster C that compiles in a second)")
    p.add_argument("--warmup", type=WINDOW, default=None, metavar="K",
                   help="also export init(u_w, y_w) -> x: the state after K measured samples, so a controller "
                        "starts from the measured state (stored in the sidecar); at most 10000")
    p.add_argument("--measure-outputs", default=None, metavar="A,B",
                   help="with --warmup, a physics model of several outputs: init fits the state on these outputs' "
                        "windows (e.g. 'Pos x,Pos y': the tip's position, not its angle); default: the output its "
                        "predictions fit it on")
    p.add_argument("--estimator", type=WINDOW, default=None, metavar="WINDOW",
                   help="also export the moving-horizon estimator over WINDOW samples, mhe(x_start, d, U, Y, mask) "
                        "-> (x_start_new, d_new, x_now), to OUT with suffix .mhe.casadi (and into the C library); at most "
                        "10000")
    p.add_argument("--controller", metavar="DIR",
                   help="also write a C controller: the fixed-iteration SQP tracking MPC (qrqp) with the model's "
                        "step (and the estimator with --estimator) as controller.c/.h, an example main.c that "
                        "closes the loop, and a Makefile; no Python, torch or CasADi runtime needed")
    p.add_argument("--track", default=None, metavar="OUTPUT",
                   help="a model of several outputs (hyst identify --output A,B,C): export the step of this output "
                        "alone, by its column name (and the C controller that tracks it)")
    p.add_argument("--horizon", type=HORIZON, default=25,
                   help="the C controller's prediction horizon, samples, at most 1000 (default: 25)")
    p.add_argument("--iterations", type=POSITIVE_INT, default=1,
                   help="the C controller's SQP iterations per control step (default 1: real-time iteration)")
    p.add_argument("--y-bounds", type=OUTPUT_LO_HI, default=None, metavar="[OUTPUT:]LO,HI",
                   help="the C controller keeps the model's output inside LO,HI over the horizon (a soft "
                        "constraint); its control call then also takes h[0..N-1], the interval's half-widths "
                        "(an online band's, each sample). main.c feeds the model folder's offline half-width "
                        "(0 without intervals). With --track, OUTPUT:LO,HI bounds another output of the model "
                        "(e.g. 'Angle x:20,60' while 'Pos y' is tracked; h then 0)")
    p.add_argument("--measure-every", type=POSITIVE_INT, default=None, metavar="N",
                   help="with --controller and --y-bounds: main.c runs the model folder's online band "
                        "(hybrid.intervals.AdaptiveIntervals, as `hyst mpc --tighten --measure-every N`), measuring "
                        "the tip every N samples and feeding the control call its half-widths; the library also "
                        "holds online_band and online_update")
    add_model_options(p)
    add_model_rate_option(p)
    p.set_defaults(func=run, out_kind="file", out_suffixes=(".casadi",))


def run(args) -> int:
    from hybrid.export import export_model
    from hybrid.export._codegen import has_compiler, write_c_demo
    from hybrid.export._model import sidecar

    from hybrid.cli._main import CLIError
    from hybrid.cli._outputs import check_model_folder_out, check_out_folder

    for option, value, what in (("--c-code", args.c_code, "step.c"), ("--controller", args.controller, "controller.c")):
        check_model_folder_out(args, value, option, CLIError)  # a model folder read is one unit: not written
        if value is not None:  # before any work: nothing is written when a folder cannot be
            check_out_folder(option, value, what, CLIError)
    model = load_model(args, args.model)
    model_rate(args, args.model, model, "the step runs at the model's rate")
    index = _tracked(args, model)
    bound = bound_index(args, model_outputs(model), index)
    other = bound is not None and bound != index  # the C controller bounds another output than the tracked one
    symbolic = args.symbolic
    if symbolic == "auto":
        symbolic = "SX" if type(model).__name__ == "Series" else "MX"
    init_outputs = _init_outputs(args, model)
    exported = export_model(model, warmup=args.warmup, init_outputs=init_outputs,
                            **export_options(args, model, symbolic=symbolic))
    whole = exported
    if index is not None:
        reads = exported.meta.get("init_outputs", [exported.meta.get("init_output")])
        exported = exported.output(index)
        if args.warmup is not None and exported.init is None:
            from hybrid.cli._options import fit_outputs

            names = fit_outputs(args.model, model_outputs(model))
            raise CLIError(f"--warmup with --track {args.track!r}: the window's init fits the state on "
                           f"{', '.join(repr(names[j]) for j in reads)}'s window; track that output with --warmup "
                           "(or name it alone with --measure-outputs), or leave --warmup out.")
    if exported.dt is None:
        exported.dt = dt_s(args)
    if args.controller is not None and exported.input_range is None:
        from hybrid.cli._main import CLIError

        raise CLIError(f"'{args.model}' records no input range it was fitted on, which bounds the controller's "
                       "input; export a fitted model (fit JSON, checkpoint or folder) with --controller.")
    if args.y_bounds is not None and args.controller is None:
        from hybrid.cli._main import CLIError

        raise CLIError("--y-bounds bounds the C controller's output; give --controller DIR too.")
    if args.measure_every is not None and (args.controller is None or args.y_bounds is None):
        from hybrid.cli._main import CLIError

        raise CLIError("--measure-every runs the online band the C controller keeps inside its output bounds; "
                       "give --controller DIR and --y-bounds LO,HI too.")
    if args.measure_every is not None and other:
        from hybrid.cli._main import CLIError

        raise CLIError(f"--measure-every runs the tracked output's online band inside --y-bounds; with the bounds on "
                       f"another output than {args.track!r} leave it out.")
    if args.controller is not None and exported.n_u > 1:
        from hybrid.cli._main import CLIError

        raise CLIError(f"'{args.model}' also reads measured inputs; the C controller steps a model with one input.")
    if args.estimator is not None and exported.input_range is None:
        from hybrid.cli._main import CLIError

        raise CLIError(f"'{args.model}' records no input range it was fitted on, which the estimator's scales "
                       "need; export a fitted model (fit JSON, checkpoint or folder) with --estimator.")
    from hybrid.export._load import folder_intervals

    intervals, why = folder_intervals(args.model, args.track)
    if args.measure_every is not None and intervals is None:
        from hybrid.cli._main import CLIError

        raise CLIError(f"--measure-every runs the model's online interval, calibrated by `hyst fit`, and {why}.")
    if intervals is not None:  # a model folder's calibrated interval rides along (C symbol half_width)
        exported.half_width = intervals.function(dt=exported.dt)
        exported.meta["interval_level"] = intervals.level
    path = exported.save(args.out)
    print(f"wrote {path} ({exported.kind}, {exported.n_x} states) and {sidecar(path)}"
          + ("" if intervals is None else f", with its {intervals.level:.0%} interval's half-width"))
    functions = [exported.step] + [f for f in (exported.init, exported.half_width) if f is not None]
    if args.estimator is not None:
        from hybrid.control import MovingHorizonEstimator

        # a model of several outputs: the estimator of every output (one state; its mask says which are measured),
        # whose state the tracked output's step and controller take as they are
        estimated = whole if whole.n_y > 1 else exported
        estimated.dt = estimated.dt or exported.dt
        mhe = MovingHorizonEstimator(estimated, window=args.estimator, compile=False)
        functions.append(mhe.function)
        where = mhe.save(path.with_suffix(".mhe.casadi"))
        fitted = ("the output offset" if whole.n_y == 1 else
                  f"an offset per output, of all {whole.n_y} outputs (Y and mask: {whole.n_y} rows, NaN-free; mask 0 "
                  "where an output is not measured)")
        print(f"wrote {where} (moving-horizon estimator over {args.estimator} samples, "
              f"{len(mhe.states)} state(s) and {fitted} fitted)")
    if args.controller:
        from hybrid.control import TrackingMPC, write_controller

        settings = None
        if other:  # the tracked output's step, bounds on another output of the same state
            from hybrid.control import MPCSettings

            whole.dt = whole.dt or exported.dt
            settings = MPCSettings(track=index)
        mpc = TrackingMPC(whole if other else exported, settings, horizon=args.horizon, solver="fixed-sqp",
                          y_bounds={bound: args.y_bounds} if other else args.y_bounds,
                          solver_options={"iterations": args.iterations, "compile": False})
        online, half = None, 0.0 if args.y_bounds is None or intervals is None or other else intervals.quantile()
        if other and args.y_bounds is not None:  # main.c keeps the bounded output's own band inside its bounds
            banded, _ = folder_intervals(args.model, _bound_name(args, model, bound))
            half = 0.0 if banded is None else banded.quantile()
        if args.measure_every is not None:  # the band hyst mpc --tighten --measure-every runs
            from hybrid.intervals import AdaptiveIntervals

            online, half = AdaptiveIntervals(every=args.measure_every).fit(intervals), 0.0
        where = write_controller(mpc, args.controller, estimator=mhe if args.estimator is not None else None,
                                 half_width=half, online=online, measure_every=args.measure_every)
        feeds = (f"{half:.4g}" if online is None else
                 f"the online band's, measured every {args.measure_every} samples, {online.offline_:.4g} before")
        bounded = ("" if args.y_bounds is None else
                   f", {_bound_name(args, model, bound)!r} kept within {args.y_bounds[0]:g} to {args.y_bounds[1]:g} "
                   f"less the half-widths h its control call takes (main.c feeds {half:.4g}, that output's interval)"
                   if other else
                   f", outputs {args.y_bounds[0]:g} to {args.y_bounds[1]:g} less the "
                   f"half-widths h its control call takes (main.c feeds {feeds})")
        print(f"wrote the C controller to {where} (controller.c/.h, main.c, Makefile: run make there; horizon "
              f"{args.horizon}, {args.iterations} SQP iteration(s) per step, inputs {mpc.u_bounds[0]:g} to "
              f"{mpc.u_bounds[1]:g}{bounded})")
    if args.c_code:
        from hybrid.export._codegen import codegen

        compiled = has_compiler()
        out = codegen(functions, args.c_code, name="step", compile=compiled)
        demo = write_c_demo(exported.step, args.c_code, exported.x0(0.0), 0.0)
        print(f"wrote {out}" + ("" if compiled else " (gcc not found: compile step.c yourself)")
              + f" and {demo}")
    return 0


def _bound_name(args, model, bound: int) -> str:
    from hybrid.cli._options import fit_outputs

    return fit_outputs(args.model, model_outputs(model))[bound]


def _init_outputs(args, model) -> list[int] | None:
    """``--measure-outputs``: the indices of the outputs the window's init reads, or a refusal in one line."""
    from hybrid.cli._main import CLIError

    if args.measure_outputs is None:
        return None
    if args.warmup is None:
        raise CLIError("--measure-outputs names the outputs the --warmup K window's init reads; give --warmup too.")
    if type(model).__name__ != "Series" or model.n_y == 1:
        raise CLIError(f"--measure-outputs picks the measured outputs of a physics model of several; '{args.model}' "
                       "is not one. Leave it out.")
    from hybrid.cli._options import fit_outputs, measured_indices

    return measured_indices(args, fit_outputs(args.model, model.n_y))


def _tracked(args, model) -> int | None:
    """``--track``: the index of the exported output of a model of several; what needs one output refused."""
    from hybrid.cli._main import CLIError
    from hybrid.cli._options import track_index

    n_y = model_outputs(model)
    if n_y > 1 and args.controller is not None and args.track is None:
        raise CLIError(f"--controller (without --track) takes a model of one output; '{args.model}' has {n_y}. Its "
                       "step, rest state, init (--warmup K: the state fitted on its first output's window) and "
                       "estimator of every output (--estimator W) export without --track; --track OUTPUT exports one "
                       "output's step and controller.")
    return track_index(args, n_y, f"'{args.model}'")
