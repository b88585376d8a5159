"""``hyst train``: fit a learned or hybrid model on CSV trajectories and save its checkpoint."""

from __future__ import annotations

import argparse

from hybrid.cli._options import (POSITIVE_FLOAT, POSITIVE_INT, input_columns, add_csv_options, add_device_option, add_seed_option, load_csvs, network_names, nonempty,
                                output_names, validation_fraction)

EPILOG = """\
examples:
  hyst train run1.csv run2.csv --model fnn-hib --out models/fnn_hib.pt
  hyst train results/demo/train/*.csv --model lstm --physics "backlash+boucwen+linear" \\
      --epochs 40 --out models/hybrid_lstm.pt          # physics + LSTM residual
  hyst train run1.csv --model fnn-hib --direction inverse --out models/inv.pt
  hyst train data_1_*.txt --time Time --input "Tendon Disp.,Motor Curr." --output "Angle x" \
      --model fnn-hib --physics "lag+backlash+linear" --out models/current.pt   # the residual also reads the current
  hyst train data_1_*.txt --time Time --input "Tendon Disp." --output "Angle x,Pos x,Pos y" \
      --model fnn-hib --physics "lag+gpi+linear" --out models/pose.pt   # one chain, a map per output, one residual

--model names the network ({networks}); with --physics SPEC it is the
residual of a hybrid model whose physics is identified first (CasADi + IPOPT).
The checkpoint (.pt plus a .json sidecar) is what `hyst predict` and
`hyst export` read.
"""


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "train", help="train a learned or hybrid model on CSV trajectories",
        description="Train a network (the seed paper's FNN, FNN-HIB or LSTM, or any registered one; Adam, MSE, "
                    "batch 16), alone or as the residual of a physics model, and save a checkpoint.",
        epilog=EPILOG.format(networks=network_names()), formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("data", nargs="+", metavar="DATA.csv", help="training trajectories")
    p.add_argument("--model", default="lstm", help=f"network: {network_names()} (default: %(default)s)")
    p.add_argument("--physics", default=None, metavar="SPEC", type=nonempty("a spec such as 'backlash+linear', or leave "
                                                                            "--physics out to train the network alone"),
                   help="physics spec for a hybrid model, e.g. 'backlash+boucwen+linear'")
    p.add_argument("--residual-domain", type=POSITIVE_FLOAT, default=None, metavar="S",
                   help="with --physics: weigh the residual by exp(-(d/r)^2), d the distance of an input row to "
                        "the training rows, r = S x their 99th percentile, so off the training data the physics "
                        "speaks alone (e.g. 0.5; default: off)")
    p.add_argument("--direction", choices=("forward", "inverse"), default="forward")
    p.add_argument("--epochs", type=POSITIVE_INT, default=100, help="training epochs (default: 100)")
    p.add_argument("--validation", type=validation_fraction, default=0.1,
                   help="validation fraction; the best epoch is kept (default: 0.1)")
    p.add_argument("--patience", type=POSITIVE_INT, default=10, help="early-stopping patience (default: 10)")
    add_seed_option(p, "seed")
    add_device_option(p)
    add_csv_options(p, several_outputs=True)
    p.add_argument("--out", required=True, metavar="MODEL.pt", help="checkpoint to write")
    p.set_defaults(func=run, out_kind="file", out_suffixes=(".pt",))


def run(args) -> int:
    from hybrid.cli._main import CLIError
    from hybrid.networks import make_network

    if not str(args.out).endswith(".pt"):
        raise CLIError(f"--out must end in .pt; got '{args.out}'.")
    if args.residual_domain is not None and not args.physics:
        raise CLIError("--residual-domain weighs a hybrid's residual; give --physics SPEC too, or leave it out.")
    network = make_network(args.model)  # unknown name: a clear DataError
    outputs = output_names(args)
    if len(outputs) > 1 and args.direction != "forward":
        raise CLIError(f"--output {args.output!r}: a model of several outputs is forward; an inverse predicts the one "
                       "input: give one --output.")
    data = load_csvs(args.data, args)
    from hybrid.learning import TrainingSettings

    training = TrainingSettings(epochs=args.epochs, validation=args.validation,
                                patience=args.patience if args.validation > 0 else None, seed=args.seed,
                                threads=1, progress=True, device=args.device)  # a bar on a terminal, a line per tenth of the epochs in a log
    measured = input_columns(args)[1]  # --input 'command,measured,...': the network reads them too
    if args.physics:
        from hybrid.models import HybridModel

        model = HybridModel(physics=args.physics, residual=network, direction=args.direction,
                            features=("u", "physics", *measured), residual_domain=args.residual_domain,
                            training=training, outputs=outputs if len(outputs) > 1 else ())
    else:
        from hybrid.learning import LearnedModel

        model = LearnedModel(network=network, direction=args.direction, features=measured, training=training,
                             outputs=outputs if len(outputs) > 1 else ())
    model.fit(data)
    path = model.save(args.out)
    print(f"trained {model!r} on {len(data)} trajectories; wrote {path}")
    return 0
