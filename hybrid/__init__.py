"""hysteresis-hybrid: learned and hybrid kinematic models of hysteretic tendon robots.

Public names are re-exported here; the modules behind them are private and may move.
Every name loads on first use (torch-based ones such as :class:`LearnedModel` import torch
then), so ``import hybrid`` stays fast.

>>> from hybrid import LearnedModel, FNNHIBNet
>>> LearnedModel(network=FNNHIBNet(buffer=50), direction="inverse")
LearnedModel(FNNHIBNet(buffer=50, hidden=(64, 64), pad='edge'), direction='inverse', unfitted)
"""

from __future__ import annotations

import importlib
from typing import Any

from ._version import __version__

#: name -> module, imported on first attribute access: ``import hybrid`` imports nothing heavy (the
#: data layer imports scipy and casadi, the models torch), so ``hyst`` can stop cleanly on a Ctrl-C
#: that arrives while it starts.
_LAZY = {
    "data": None,  # subpackage
    **dict.fromkeys(("Dataset", "DataSplit", "Trajectory", "load_csv", "load_preset", "nrmse", "rmse"), ".data"),
    **dict.fromkeys(("NETWORKS", "AbstractNetwork", "FNNHIBNet", "FNNNet", "LSTMNet", "make_network"), ".networks"),
    "LearnedModel": ".learning._learned",
    "TrainingSettings": ".learning._settings",
    "TrainingHistory": ".learning._training",
    "train": ".learning._training",
    "save_checkpoint": ".learning._learned",
    "load_checkpoint": ".learning._learned",
    "reproduce": ".experiments._reproduce",
    "Score": ".experiments._scoring",
    "score_model": ".experiments._scoring",
    "HybridModel": ".models._hybrid",
    "FineTuneSettings": ".models._hybrid_tune",
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


__all__ = ["__version__", *_LAZY]
