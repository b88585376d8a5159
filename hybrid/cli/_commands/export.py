"""``hyst export``: a fitted model as a CasADi step function (and C code)."""

from __future__ import annotations

import argparse

from hybrid.cli._options import add_rate_option, dt_s, rate_hz

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
    p.add_argument("--mode", choices=("carried", "window"), default=None,
                   help="LSTM state: carried (h, c) or window (input buffer; the network's default)")
    add_rate_option(p, "model rate of a physics model")
    p.set_defaults(func=run, out_kind="file", out_suffixes=(".casadi",))


def run(args) -> int:
    from hybrid.cli._main import CLIError
    from hybrid.export import export_model
    from hybrid.export._codegen import has_compiler, write_c_demo
    from hybrid.export._model import sidecar
    from hybrid.export import load

    if not str(args.out).endswith(".casadi"):
        raise CLIError(f"--out must end in .casadi; got '{args.out}'.")
    model = load(args.model, rate_hz(args))
    symbolic = args.symbolic
    if symbolic == "auto":
        symbolic = "SX" if type(model).__name__ == "Series" else "MX"
    options = {"symbolic": symbolic}
    if args.mode is not None:
        options["mode"] = args.mode
    if type(model).__name__ == "Series" and args.mode is not None:
        raise CLIError("--mode applies to LSTM models only.")
    exported = export_model(model, **options)
    if exported.dt is None:
        exported.dt = dt_s(args)
    path = exported.save(args.out)
    print(f"wrote {path} ({exported.kind}, {exported.n_x} states) and {sidecar(path)}")
    if args.c_code:
        compiled = has_compiler()
        out = exported.codegen(args.c_code, compile=compiled)
        demo = write_c_demo(exported.step, args.c_code, exported.x0(0.0), 0.0)
        print(f"wrote {out}" + ("" if compiled else " (gcc not found: compile step.c yourself)")
              + f" and {demo}")
    return 0
