"""``hyst compare``: physics, learned and hybrid models side by side, forward and inverse."""

from __future__ import annotations

import argparse

from hybrid.cli._options import (
    LEVEL, NONNEGATIVE_INT, RATE_OR_AUTO, add_experiment_options, add_selection_pool_options, check_data, check_scheduler,
    network_names, nonempty,
    parse_networks,
)
from hybrid.experiments._presets import PAPER_NETWORKS

EPILOG = """\
examples:
  hyst compare --out results/compare                        # virtual catheter, quick preset (about 10 min)
  hyst compare --data catheter_2023 --out results/cath-cmp  # real catheter: train set 1, test set 2
  hyst compare --data catheter_2023:reverse --physics auto --out results/cath-rev  # physics chosen on held-out runs
  hyst compare --preset paper --out results/compare-paper   # 500 epochs (hours)
  hyst compare --networks fnn-hib --out results/cmp-hib      # one network, alone and as a residual
  hyst compare --data DIR --rate 50 --jobs 2 --out results/mine  # a ~500 Hz folder compared at 50 Hz
  hyst compare --data catheter_2023 --output "Angle x,Pos x,Pos y" --out results/pose  # the tip's pose, forward

every model is scored after each test run's first --warmup samples (default 10), which set its state.
writes OUT/compare.csv (direction,model,kind,test,rmse,nrmse; kind physics|learned|hybrid|peer;
test '<category>:<run>' or '<category>:all' with category id, ood_freq, ood_amp, ood_baseline,
ood_steps, data_1, data_3, data_all), OUT/compare.md, OUT/figures/*.png and OUT/run.json (with the
rate every model ran at, rate_hz). With --output A,B,C (columns every run carries): forward only,
each model one of every output (the physics one chain read by a map per output, each network one unit
per output, the hybrids one residual of every output, the peers a linear ARX of all outputs, a NARX
per output and SUBNET of every output), scored per output (compare.csv's output column;
figures/rmse_per_output.png).
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
    p.add_argument("--rate", type=RATE_OR_AUTO, default="auto", metavar="HZ|auto",
                   help="rate the measured runs are resampled to and every model runs at, Hz; auto (default): a "
                        "folder's own rate (its manifest's rate_hz, else the rate its files were recorded at), a "
                        "named data set's default (25 Hz for catheter_2023 and niti_frequency_trials, read from its "
                        "raw files at --rate otherwise). The virtual data is simulated at 25 Hz: no --rate")
    p.add_argument("--output", default=None, metavar="A,B,C",
                   help="several output columns every run carries (e.g. 'Angle x,Pos x,Pos y' of catheter_2023): "
                        "each model of every output, forward only, scored per output (default: the data set's one "
                        "output)")
    add_selection_pool_options(p)
    p.set_defaults(func=run, out_kind="dir")


def run(args) -> int:
    from hybrid.experiments._compare import compare, compare_policy
    from identification.discovery import AUTO, Workers
    from hybrid.experiments._presets import check_preset

    check_preset(args.preset)
    check_scheduler(args.scheduler)
    networks = parse_networks(args.networks, PAPER_NETWORKS)
    check_data(args)
    outputs = _outputs(args)
    data = _data_at_rate(args)
    if outputs:
        return _several(args, data, outputs, networks)
    specs = AUTO if args.physics is None else tuple(s.strip() for s in args.physics.split(",") if s.strip())
    # the policy: auto or the specs, the selection's fold fits on --jobs processes or the --scheduler's cluster
    physics = {"physics": compare_policy(specs, Workers(args.jobs, args.scheduler, args.device))}
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
          f"at {1.0 / data.train[0].dt:.6g} Hz in {result.seconds:.0f} s")
    print((result.out / "compare.md").read_text())
    print(f"results in {result.out}: compare.csv, compare.md, run.json, figures/")
    return 0


def _outputs(args) -> tuple[str, ...]:
    """``--output A,B,C``: the output columns (two or more), or () for the data set's one output; what the comparison
    of several outputs does not offer refused in one line before any work."""
    from hybrid.cli._main import CLIError

    if args.output is None:
        return ()
    names = tuple(n.strip() for n in args.output.split(","))
    if len(names) < 2 or not all(names) or len(set(names)) != len(names):
        raise CLIError(f"--output {args.output!r}: name two or more distinct output columns ('Angle x,Pos x,Pos y'), "
                       "or leave --output out for the data set's one output.")
    if args.interval is not None:
        raise CLIError("--interval with --output A,B,C: the comparison of several outputs calibrates no intervals; "
                       "`hyst fit --output A,B,C` calibrates one per output. Leave --interval out.")
    return names


def _several(args, data, outputs, networks) -> int:
    """``hyst compare --output A,B,C``: every model of every output, forward (:func:`compare_outputs`)."""
    from hybrid.experiments._compare_outputs import OUTPUT_PEERS, compare_outputs
    from identification.discovery import Workers

    peers = OUTPUT_PEERS if args.peers is None else () if args.peers.strip() == "none" else tuple(
        p.strip() for p in args.peers.split(",") if p.strip())
    specs = "auto" if args.physics is None else tuple(s.strip() for s in args.physics.split(",") if s.strip())
    options = {} if args.warmup is None else {"warmup": args.warmup}
    result = compare_outputs(data, args.out, outputs, preset=args.preset, seed=args.seed, networks=networks,
                             physics=specs, peers=peers, workers=Workers(args.jobs, args.scheduler, args.device),
                             progress=False if args.no_progress else None, figures=not args.no_figures, **options)
    print(f"compared {len({r.model for r in result.rows})} models of {', '.join(outputs)} on {len(data.train)} "
          f"training runs at {1.0 / data.train[0].dt:.6g} Hz in {result.seconds:.0f} s (forward)")
    print((result.out / "compare.md").read_text())
    print(f"results in {result.out}: compare.csv, compare.md, run.json, figures/")
    return 0


def _data_at_rate(args):
    """The comparison's data (``compare_data``) at ``--rate``: as loaded for ``auto``; else a named data
    set read again from its raw files at the rate, a folder's runs resampled to it (anti-aliased when
    down-sampling: the runs were loaded on a uniform grid at the files' own rate). The virtual data
    is simulated at its own rate, so a number is refused there."""
    from dataclasses import replace

    from hybrid.cli._main import CLIError
    from hybrid.cli._options import MAX_SAMPLES
    from hybrid.experiments._datasets import compare_data
    from physics.data import Dataset, data_names, load_preset

    if args.rate != "auto" and args.data == "virtual":
        raise CLIError(f"--rate {args.rate:g}: the virtual data is simulated at 25 Hz; leave --rate out, or give "
                       "--data a folder (`hyst simulate --paper-dataset --rate HZ --out DIR`) or a measured data set.")
    data = compare_data(args.data, seed=args.seed, preset=args.preset)
    if args.rate == "auto":
        return data
    rate = float(args.rate)
    longest = max(t.duration for t in (*data.train, *(t for ts in data.tests.values() for t in ts)))
    if longest * rate > MAX_SAMPLES:
        raise CLIError(f"--rate {rate:g} Hz makes the longest run ({longest:g} s) {longest * rate:.3g} samples; the "
                       f"limit is {MAX_SAMPLES:.0e} (what fits in memory): lower --rate.")
    if str(args.data) in data_names():
        split = load_preset(str(args.data), rate_hz=rate)
        new = {_key(t): t for t in (*split.train, *split.test)}
        if len(new) != len(split.train) + len(split.test):  # runs not told apart: resample what was loaded
            new = {}
    else:
        new = {}  # a folder: its runs as loaded, on a uniform grid at the files' own rate

    def at_rate(runs):
        return Dataset(new.get(_key(t)) or t.resample(rate) for t in runs)

    return replace(data, train=at_rate(data.train), tests={k: at_rate(v) for k, v in data.tests.items()},
                   subsets={k: at_rate(v) for k, v in data.subsets.items()},
                   baseline=None if data.baseline is None else tuple(at_rate(d) for d in data.baseline))


def _key(traj) -> tuple:
    """What tells a data set's runs apart across two loads: the file and the part of it."""
    return traj.source, traj.meta.get("file"), traj.meta.get("part")
