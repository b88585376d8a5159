"""Feedforward networks: the plain FNN and the FNN with a history input buffer (FNN-HIB)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from physics.data import DataError, history_windows
from ._base import AbstractNetwork, check_int

__all__ = ["FNNNet", "FNNHIBNet"]


def _check_hidden(owner: str, hidden: tuple[int, ...]) -> None:
    if not isinstance(hidden, tuple) or not hidden:
        raise DataError(f"The 'hidden' parameter of {owner} must be a non-empty tuple of layer widths. Got {hidden!r}.")
    for width in hidden:
        check_int(owner, "hidden", width)


@dataclass(frozen=True)
class FNNNet(AbstractNetwork):
    """The seed paper's FNN: current input only, layers [n_features, 64, 64, 1], ReLU.

    It has no memory, so it cannot represent hysteresis: it is the baseline.

    Examples
    --------
    >>> FNNNet().windows(np.array([[0.1], [0.2]])).shape
    (2, 1, 1)
    """

    hidden: tuple[int, ...] = (64, 64)
    name: ClassVar[str] = "fnn"

    def __post_init__(self) -> None:
        object.__setattr__(self, "hidden", tuple(self.hidden))
        _check_hidden("FNNNet", self.hidden)

    @property
    def history(self) -> int:
        return 1

    def windows(self, features: NDArray[np.float64]) -> NDArray[np.float32]:
        arr = self.check_features(features)
        return arr[:, None, :].astype(np.float32)

    def build(self, n_features: int, n_outputs: int = 1):
        from ._modules import BufferMLP

        return BufferMLP(n_features, buffer=1, hidden=self.hidden, n_outputs=n_outputs, pad="edge")


@dataclass(frozen=True)
class FNNHIBNet(AbstractNetwork):
    """FNN with a history input buffer: the last ``buffer`` inputs, oldest first.

    Parameters
    ----------
    buffer : int, default 50
        Number of samples in the buffer (the paper's l = 50, i.e. 2 s at 25 Hz).
    hidden : tuple of int, default (64, 64)
        Hidden layer widths (ReLU).
    pad : "edge" or float, default "edge"
        What fills the buffer before the first sample: ``"edge"`` repeats the
        first input (the robot rested there), a number fills it with that
        value (in scaled units). Used in training and in prediction alike.

    Examples
    --------
    >>> FNNHIBNet(buffer=3).windows(np.array([1.0, 2.0, 3.0, 4.0]))[:, :, 0]
    array([[1., 1., 1.],
           [1., 1., 2.],
           [1., 2., 3.],
           [2., 3., 4.]], dtype=float32)
    """

    buffer: int = 50
    hidden: tuple[int, ...] = (64, 64)
    pad: str | float = "edge"
    name: ClassVar[str] = "fnn-hib"

    def __post_init__(self) -> None:
        object.__setattr__(self, "hidden", tuple(self.hidden))
        check_int("FNNHIBNet", "buffer", self.buffer)
        _check_hidden("FNNHIBNet", self.hidden)
        if not (self.pad == "edge" or (isinstance(self.pad, (int, float)) and not isinstance(self.pad, bool)
                                       and np.isfinite(self.pad))):
            raise DataError(f"The 'pad' parameter of FNNHIBNet must be 'edge' or a finite number. Got {self.pad!r}.")

    @property
    def history(self) -> int:
        return self.buffer

    def windows(self, features: NDArray[np.float64]) -> NDArray[np.float32]:
        arr = self.check_features(features)
        pad = self.pad if self.pad == "edge" else float(self.pad)
        return history_windows(arr, self.buffer, pad=pad).astype(np.float32)

    def build(self, n_features: int, n_outputs: int = 1):
        from ._modules import BufferMLP

        return BufferMLP(n_features, buffer=self.buffer, hidden=self.hidden, n_outputs=n_outputs, pad=self.pad)
