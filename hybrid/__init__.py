"""hysteresis-hybrid: learned and hybrid kinematic models of hysteretic tendon robots.

Public names are re-exported here; the modules behind them are private and may move.
Torch-based names (:class:`LearnedModel`, checkpoints, training) load on first use,
so ``import hybrid`` and the data layer stay fast.

>>> from hybrid import LearnedModel, FNNHIBNet
>>> LearnedModel(network=FNNHIBNet(buffer=50), direction="inverse")
LearnedModel(FNNHIBNet(buffer=50, hidden=(64, 64), pad='edge'), direction='inverse', unfitted)
"""

from __future__ import annotations

import importlib
from typing import Any

from ._version import __version__
from . import data
from .data import Dataset, DataSplit, Trajectory, load_csv, load_preset, nrmse, rmse
from .networks import NETWORKS, AbstractNetwork, FNNHIBNet, FNNNet, LSTMNet, make_network

#: name -> private module, imported on first attribute access (these import torch).
_LAZY = {
    "LearnedModel": ".learning._learned",
    "TrainingSettings": ".learning._training",
    "TrainingHistory": ".learning._training",
    "train": ".learning._training",
    "save_checkpoint": ".learning._learned",
    "load_checkpoint": ".learning._learned",
    "reproduce": ".experiments._reproduce",
    "Score": ".experiments._scoring",
    "score_model": ".experiments._scoring",
    "HybridModel": ".models._hybrid",
    "NeuralODEHybrid": ".models._neural_ode",
    "ModelInverse": ".control._inverse",
    "ConformalModel": ".intervals._model",
    "ConformalIntervals": ".intervals._conformal",
    "compare": ".experiments._compare",
    "virtual": None,  # subpackage: imports casadi
}


def __getattr__(name: str) -> Any:
    if name not in _LAZY:
        raise AttributeError(f"module 'hybrid' has no attribute {name!r}")
    module = _LAZY[name]
    value = importlib.import_module(f".{name}" if module is None else module, __name__)
    if module is not None:
        value = getattr(value, name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))


__all__ = [
    "data", "Trajectory", "Dataset", "DataSplit", "load_csv", "load_preset", "rmse", "nrmse",
    "AbstractNetwork", "FNNNet", "FNNHIBNet", "LSTMNet", "NETWORKS", "make_network",
    *_LAZY,
]
