"""``hyst compare``: physics, learned and hybrid models side by side, forward and inverse."""

from __future__ import annotations

import argparse

from hybrid.cli._options import (
    LEVEL, NONNEGATIVE_INT, add_experiment_options, check_data, network_names, nonempty, parse_networks,
)
from hybrid.experiments._presets import PAPER_NETWORKS

EPILOG = """\
examples:
  hyst compare --out results/compare                        # virtual catheter, quick preset (about 10 min)
  hyst compare --data catheter_2023 --out results/cath-cmp  # real catheter: train set 1, test set 2
  hyst compare --data catheter_2023:reverse --physics auto --out results/cath-rev  # physics chosen on held-out runs
  hyst compare --preset paper --out results/compare-paper   # 500 epochs (hours)
  hyst compare --networks fnn-hib --out results/cmp-hib      # one network, alone and as a residual

every model is scored after each test run's first --warmup samples (default 10), which set its state.
writes OUT/compare.csv (direction,model,kind,test,rmse,nrmse; kind physics|learned|hybrid|peer;
test '<category>:<run>' or '<category>:all' with category id, ood_freq, ood_amp, ood_baseline,
ood_steps, data_1, data_3, data_all), OUT/compare.md, OUT/figures/*.png and OUT/run.json.
"""


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "compare", help="physics, FNN/FNN-HIB/LSTM and hybrids side by side, in and out of distribution",
        description="Train the physics model, the paper's three networks and each network as a residual on "
                    "the physics (plus a neural-ODE hybrid and a model-based inverse), forward and inverse, "
                    "and score them in distribution, out of distribution and for data efficiency.",
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_experiment_options(
        p, data="'virtual' (default: every test category), a measured data set: 'catheter_2023' (set 1 -> "
                "set 2), 'catheter_2023:reverse' (set 2 -> set 1), 'catheter_2023:interp' (held-out "
                "frequencies), 'niti_frequency_trials' (tension -> tip angle; random excitation as "
                "ood_random), 'boucwen_benchmark' (force -> displacement at 750 Hz), or a folder with "
                "train/*.csv and test/*.csv",
        preset="quick (default): short training, bounded time; paper: 500 epochs")
    p.add_argument("--networks", default=None, metavar="NAMES",
                   help=f"comma-separated networks to train alone and as residuals, from: {network_names()} "
                        f"(default: the paper's {','.join(PAPER_NETWORKS)})")
    p.add_argument("--physics", default=None, metavar="SPECS|auto", type=nonempty("comma-separated specs or auto, "
                                                                                  "or leave --physics out for auto"),
                   help="auto (default): the hybrids' physics is chosen on each training set by leaving whole "
                        "runs out of the fit (or thirds of a single run; the candidates' held-out errors go to "
                        "run.json's physics_selection). Or comma-separated specs tried in order: the first that "
                        "fits is used and the failures are listed in run.json")
    p.add_argument("--warmup", type=NONNEGATIVE_INT, default=None, metavar="K",
                   help="the protocol: every model (and peer) sets its state from each test run's first K measured "
                        "samples and is scored on the rest (default 10; 0: every model from rest, scored on all)")
    p.add_argument("--peers", default=None, metavar="NAMES|none",
                   help="comma-separated peers fitted and scored beside ours, from: arx (linear ARX), narx "
                        "(SysIdentPy polynomial NARX), subnet (deepSI SUBNET); default all (those whose package is "
                        "missing are skipped with a note: pip install 'hysteresis-hybrid[peers]'); none: no peers")
    p.add_argument("--interval", type=LEVEL, default=None, metavar="LEVEL",
                   help="also calibrate every forward model's LEVEL (e.g. 0.9) conformal interval on training runs "
                        "held out of its fit (each model fitted again on up to 5 folds: several times the time) "
                        "and report coverage and width per test category (OUT/intervals.csv, compare.md)")
    p.set_defaults(func=run, out_kind="dir")


def run(args) -> int:
    from hybrid.experiments._compare import PRESETS, compare
    from hybrid.experiments._datasets import compare_data
    from hybrid.experiments._presets import check_preset

    check_preset(args.preset, PRESETS)
    networks = parse_networks(args.networks, PAPER_NETWORKS)
    check_data(args)
    data = compare_data(args.data, seed=args.seed, preset=args.preset)
    physics = {} if args.physics is None else {"physics": tuple(s.strip() for s in args.physics.split(",") if s.strip())}
    if args.warmup is not None:
        physics["warmup"] = args.warmup
    if args.interval is not None:
        physics["interval"] = args.interval
    if args.peers is not None:
        physics["peers"] = () if args.peers.strip() == "none" else tuple(p.strip() for p in args.peers.split(",")
                                                                        if p.strip())
    result = compare(data, args.out, preset=args.preset, seed=args.seed, networks=networks, **physics,
                     progress=False if args.no_progress else None, figures=not args.no_figures)
    print(f"compared {len({r.model for r in result.rows})} models on {len(data.train)} training runs "
          f"in {result.seconds:.0f} s")
    print((result.out / "compare.md").read_text())
    print(f"results in {result.out}: compare.csv, compare.md, run.json, figures/")
    return 0
