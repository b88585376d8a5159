"""Purely learned models: the estimator, its training loop and checkpoints (these import torch).

Names load on first use, so :class:`TrainingSettings` (and the experiments' budget table built
of them) is available without importing torch.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # the names, for readers and the API docs; loaded on first use below
    from ._learned import DIRECTIONS, LearnedModel, fit_together, load_checkpoint, save_checkpoint
    from ._settings import TrainingSettings
    from ._together import train_together
    from ._training import TrainingHistory, train

_LAZY = {
    **dict.fromkeys(("LearnedModel", "DIRECTIONS", "save_checkpoint", "load_checkpoint", "fit_together"), "._learned"),
    **dict.fromkeys(("TrainingHistory", "train"), "._training"),
    "train_together": "._together",
    "TrainingSettings": "._settings",
}


def __getattr__(name: str) -> Any:
    if name not in _LAZY:
        raise AttributeError(f"module 'hybrid.learning' has no attribute {name!r}")
    value = getattr(importlib.import_module(_LAZY[name], __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))


__all__ = ["LearnedModel", "DIRECTIONS", "TrainingSettings", "TrainingHistory", "train", "train_together",
           "fit_together", "save_checkpoint", "load_checkpoint"]
