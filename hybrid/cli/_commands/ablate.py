"""``hyst ablate``: sweep model settings from a TOML grid on Dask; resumable, one result per run."""

from __future__ import annotations

import argparse
import textwrap

from hybrid.cli._options import POSITIVE_INT, add_device_option, check_scheduler, network_names
from hybrid.experiments.ablation._config import DATA_SOURCES, METRICS, SETTINGS, bundled_configs

EPILOG = """\
examples:
  hyst ablate buffer_length --out results/buffer          # a bundled config; local pool, one process per core
  hyst ablate tiny --out /tmp/tiny --workers 2
  hyst ablate my_grid.toml --out results/mine --scheduler tcp://10.0.0.5:8786

{config}

Writes DIR/runs/<run_id>.json per finished run (settings, metrics per test trajectory and pooled,
timings, provenance) and DIR/runs/<run_id>.error.json per failed one (with its traceback),
DIR/results.csv (one row per run), DIR/ablation.json and DIR/figures/*.png. Rerunning the same
command skips finished runs and retries failed ones. Exit status 1 when any run failed.
"""


def _config_help() -> str:
    sources = " | ".join(f'"{s}"' for s in DATA_SOURCES)
    return textwrap.fill(
        f"CONFIG.toml declares [data] (source = {sources}), [grid] (a list is an axis of the sweep, a single "
        f"value is fixed: {', '.join(SETTINGS)}; model is one of {network_names()}) and metrics "
        f"({', '.join(METRICS)}). Bundled configs, by name: {', '.join(bundled_configs())}.", width=98)


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "ablate", help="sweep model settings (buffer, hidden size, data fraction, ...) on Dask",
        description="Train and score one model per grid point of CONFIG.toml on a local Dask process pool "
                    "or a Dask cluster; finished runs are skipped on a rerun, failed runs are recorded and retried.",
        epilog=EPILOG.format(config=_config_help()), formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("config", metavar="CONFIG", help="ablation config (data, grid, metrics): a .toml file, or the name "
                   f"of a bundled one ({', '.join(bundled_configs())})")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (reuse it to resume)")
    p.add_argument("--workers", type=POSITIVE_INT, default=None, metavar="N",
                   help="processes of the local cluster (default: number of CPU cores)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="use a running Dask scheduler, e.g. tcp://host:8786, instead of a local cluster")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--no-figures", action="store_true", help="write results.csv only")
    add_device_option(p)
    p.set_defaults(func=run, out_kind="dir")


def run(args) -> int:
    import os
    import sys

    from hybrid.cli._main import CLIError
    from hybrid.experiments.ablation import AblationConfig, run_ablation
    from physics.data.io import read_text

    cores = os.cpu_count() or 1
    if args.workers is not None and args.workers > 4 * cores:
        raise CLIError(f"--workers {args.workers} is more than 4 processes per CPU core ({cores} cores here); "
                       f"use at most --workers {4 * cores}, or a Dask cluster (--scheduler).")
    if args.workers is not None and args.scheduler:
        raise CLIError("--workers sets the size of the local cluster; with --scheduler the cluster's own "
                       "workers run the sweep. Give one of them.")
    check_scheduler(args.scheduler)
    from hybrid.experiments.ablation import ConfigError, config_path

    try:
        path = config_path(args.config)
    except ConfigError as exc:
        raise CLIError(str(exc)) from None
    read_text(path, "config file")  # a folder, another encoding: one line naming it
    config = AblationConfig.from_toml(path)
    result = run_ablation(config, args.out, workers=args.workers, scheduler=args.scheduler,
                          progress=False if args.no_progress else None, figures=not args.no_figures,
                          device=args.device)
    n_failed = sum(r["status"] != "ok" for r in result.table)
    print(f"{result.n_runs} runs: {len(result.ran)} ran, {len(result.skipped)} already done, "
          f"{n_failed} failed ({result.seconds:.0f} s)")
    print(f"wrote {result.out / 'results.csv'}" + (f" and {len(result.figures)} figures in "
                                                   f"{result.out / 'figures'}" if result.figures else ""))
    if n_failed:
        print(f"hyst ablate: {n_failed} of {result.n_runs} runs failed; errors in "
              f"{result.out / 'runs'}/*.error.json. Run the same command again to retry them.", file=sys.stderr)
        return 1
    return 0
