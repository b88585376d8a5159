"""How a network is trained, as one frozen settings object (torch-free: the budget tables import it)."""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from physics.data import DataError, Settings
from physics.data._checks import check_device

__all__ = ["TrainingSettings", "DEFAULT_TRAINING", "check_training", "training_from_dict"]


@dataclass(frozen=True)
class TrainingSettings(Settings):
    """How to train a network (the seed paper's defaults: Adam, lr 1e-3, MSE, batch 16, 500 epochs).

    One object, checked when built and never changed, that :class:`LearnedModel` and
    :class:`~hybrid.models.HybridModel` take as ``training=``. scikit-learn sees its fields as
    ``training__epochs`` etc. (``get_params(deep=True)``, ``GridSearchCV(model, {"training__lr":
    [...]})``); ``set_params(training__lr=...)`` swaps in a changed copy. The experiments' budgets
    are a table of these (:data:`hybrid.experiments.BUDGETS`).

    Parameters
    ----------
    epochs : int
        Maximum number of passes over the training windows.
    batch_size : int
    lr : float
        Adam learning rate.
    validation : float in [0, 1)
        Fraction of the windows held out (chosen at random with the seed) to
        measure a validation loss; the weights of the epoch with the lowest
        validation loss are kept. 0: no validation, the last epoch's weights.
    patience : int or None
        Stop after this many epochs without a better validation loss (needs
        ``validation > 0``); None: run all epochs.
    stride : int
        Train on every ``stride``-th window of each trajectory (a faster, coarser fit).
    seed : int
        Seeds torch (initial weights) and the numpy Generator that shuffles.
    progress : bool or None
        True: a tqdm bar with the running loss on a terminal, and one line per tenth of the epochs
        when stderr is not one (a log file, CI); None: the bar only when stderr is a terminal.
    threads : int or None
        torch CPU threads while training (None: leave torch's setting).
    device : {"cpu", "auto", "cuda", "cuda:N"}
        Where the windows are trained: ``"auto"`` uses CUDA where torch sees a GPU, else the CPU. The
        trained module comes back to the CPU, so predictions, exports and saved models are the same
        objects whichever trained it (on the CPU the numbers are unchanged; on a GPU they differ by
        float rounding). The joint fine-tuning and the neural-ODE hybrid train on the CPU.

    Examples
    --------
    >>> TrainingSettings(epochs=40, validation=0.1, patience=8).replace(lr=1e-2).lr
    0.01
    >>> TrainingSettings(patience=5)
    Traceback (most recent call last):
    ...
    physics.data._errors.DataError: patience (early stopping) needs a validation split: set validation=0.1 or so.
    """

    epochs: int = 500
    batch_size: int = 16
    lr: float = 1e-3
    validation: float = 0.0
    patience: int | None = None
    stride: int = 1
    seed: int = 0
    progress: bool | None = None
    threads: int | None = None
    device: str = "cpu"

    def __post_init__(self) -> None:
        for name in ("epochs", "batch_size", "stride", "seed"):
            value = getattr(self, name)
            low = 0 if name == "seed" else 1
            if not _is_int(value) or value < low:
                raise DataError(f"The {name!r} training setting must be an integer >= {low}. Got {value!r} instead.")
        if not (isinstance(self.lr, (int, float)) and 0 < self.lr < 1):
            raise DataError(f"The 'lr' training setting must be a number in (0, 1). Got {self.lr!r} instead.")
        if not (isinstance(self.validation, (int, float)) and 0 <= self.validation < 1):
            raise DataError(f"The 'validation' fraction must be in [0, 1). Got {self.validation!r} instead.")
        if self.patience is not None:
            if not _is_int(self.patience) or self.patience < 1:
                raise DataError(f"The 'patience' setting must be None or an integer >= 1. Got {self.patience!r}.")
            if self.validation == 0:
                raise DataError("patience (early stopping) needs a validation split: set validation=0.1 or so.")
        if self.threads is not None and (not _is_int(self.threads) or self.threads < 1):
            raise DataError(f"The 'threads' training setting must be None or an integer >= 1. Got {self.threads!r}.")
        check_device(self.device)


def _is_int(value) -> bool:
    return not isinstance(value, bool) and isinstance(value, (int, np.integer))


def check_training(training, owner: str) -> TrainingSettings:
    """``training`` if it is a :class:`TrainingSettings`, else a clear error naming ``owner``."""
    if not isinstance(training, TrainingSettings):
        raise DataError(f"The 'training' parameter of {owner} must be a TrainingSettings, e.g. "
                        f"TrainingSettings(epochs=40, lr=1e-3). Got {training!r} instead.")
    return training


def training_from_dict(settings: dict) -> TrainingSettings:
    """The training settings of a saved model's ``settings``, taken out of it: under ``"training"``,
    or (models saved before the settings were one object) the flat names of its fields."""
    if "training" in settings:
        return TrainingSettings.from_dict(settings.pop("training"))
    return TrainingSettings.from_dict({f.name: settings.pop(f.name) for f in fields(TrainingSettings)
                                       if f.name in settings})


#: The training a LearnedModel or HybridModel gets when given none (the seed paper's; frozen, so shared).
DEFAULT_TRAINING = TrainingSettings()
