"""Ablation studies: sweep model settings on Dask, one resumable result file per run.

A TOML file declares the data, the grid of settings and the metrics; :func:`run_ablation`
runs every grid point not yet finished (on a local process pool, or on a Dask cluster given
its scheduler address), records failures without stopping, and writes ``results.csv`` and
summary figures. ``hyst ablate CONFIG.toml --out DIR`` is the command line.

Examples
--------
>>> from hybrid.experiments.ablation import AblationConfig
>>> cfg = AblationConfig.from_dict({"grid": {"model": "lstm", "seq_len": [10, 50], "seed": [0, 1, 2]}})
>>> [(r.settings["seq_len"], r.settings["seed"]) for r in cfg.runs()][:3]
[(10, 0), (10, 1), (10, 2)]
"""

from ._config import (CONFIGS, DATA_SOURCES, METRICS, SETTINGS, AblationConfig, ConfigError, DataConfig, RunSpec,
                      bundled_configs, config_path)
from ._run import execute_run, select_training
from ._runner import AblationResult, run_ablation

__all__ = [
    "CONFIGS", "bundled_configs", "config_path",
    "AblationConfig", "DataConfig", "RunSpec", "ConfigError", "SETTINGS", "METRICS", "DATA_SOURCES",
    "run_ablation", "AblationResult", "execute_run", "select_training",
]
