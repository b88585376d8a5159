"""Data layer: trajectories, CSV and preset loading, resampling, scaling, windows, metrics.

Users import from here (``from hybrid.data import Trajectory``); the private
modules behind these names may move.
"""

from ._checks import is_constant
from ._errors import DataError, DataNotFoundError, NotFittedError
from ._estimator import BaseEstimator, Settings
from ._fetch import SOURCES, dataset_folder, user_cache
from ._io import load_csv, load_csvs
from ._metrics import nrmse, rmse
from ._presets import PRESETS, PROTOCOLS, data_names, data_root, load_preset, niti_tip_angle
from ._resample import raw_rate, resample
from ._scaling import MinMaxScaler
from ._trajectory import Dataset, DataSplit, Trajectory
from ._warmup import Warmup, as_warmup, check_warmup_length, join, warmup_split
from ._windows import history_windows, lstm_subsequences

__all__ = [
    "BaseEstimator",
    "Settings",
    "DataError",
    "DataNotFoundError",
    "NotFittedError",
    "Trajectory",
    "Dataset",
    "DataSplit",
    "resample",
    "raw_rate",
    "load_csv",
    "load_csvs",
    "load_preset",
    "data_root",
    "PRESETS",
    "PROTOCOLS",
    "data_names",
    "niti_tip_angle",
    "MinMaxScaler",
    "history_windows",
    "lstm_subsequences",
    "Warmup",
    "as_warmup",
    "check_warmup_length",
    "warmup_split",
    "rmse",
    "nrmse",
    "is_constant",
    "join",
    "SOURCES",
    "dataset_folder",
    "user_cache",
]
