"""The seed paper's two-layer LSTM fed subsequences with flag values before the start."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from physics.data import DataError, lstm_subsequences
from ._base import AbstractNetwork, check_int

__all__ = ["LSTMNet"]


@dataclass(frozen=True)
class LSTMNet(AbstractNetwork):
    """LSTM layers then a linear layer, trained on windows of ``seq_len`` samples.

    Each training sample is the window of the last ``seq_len`` inputs ending at
    that sample, with ``flag`` values standing in for samples before the start
    of the trajectory (the paper: 50 samples, flag -1, inputs scaled to [0, 1]);
    the loss is on the output at the window's last step.

    Parameters
    ----------
    hidden : int, default 64
    layers : int, default 2
    seq_len : int, default 50
    flag : float, default -1.0
        Value (in scaled units) marking "no history here".
    mode : {"window", "carried"}, default "window"
        How a trained network predicts a whole trajectory. ``"window"`` (the
        paper's scheme): each output from its own window of the last
        ``seq_len`` inputs, run from a zero state, so the prediction state is
        the buffer of the last ``seq_len`` inputs (a causal filter of finite
        memory, exactly what the network was trained on). ``"carried"``: one
        LSTM run over the whole trajectory (after ``seq_len - 1`` flags), the
        state (h, c) carried from sample to sample; cheaper per step but the
        network never saw memories longer than ``seq_len`` in training.

    Examples
    --------
    >>> LSTMNet(seq_len=3).windows(np.array([1.0, 2.0]))[:, :, 0]
    array([[-1., -1.,  1.],
           [-1.,  1.,  2.]], dtype=float32)
    """

    hidden: int = 64
    layers: int = 2
    seq_len: int = 50
    flag: float = -1.0
    mode: str = "window"
    name: ClassVar[str] = "lstm"
    modes: ClassVar[tuple[str, ...]] = ("window", "carried")

    def __post_init__(self) -> None:
        check_int("LSTMNet", "hidden", self.hidden)
        check_int("LSTMNet", "layers", self.layers)
        check_int("LSTMNet", "seq_len", self.seq_len)
        if isinstance(self.flag, bool) or not isinstance(self.flag, (int, float)) or not np.isfinite(self.flag):
            raise DataError(f"The 'flag' parameter of LSTMNet must be a finite number. Got {self.flag!r} instead.")
        if self.mode not in self.modes:
            raise DataError(f"The 'mode' parameter of LSTMNet must be one of {list(self.modes)}. Got {self.mode!r}.")

    @property
    def history(self) -> int:
        return self.seq_len

    def windows(self, features: NDArray[np.float64]) -> NDArray[np.float32]:
        arr = self.check_features(features)
        return lstm_subsequences(arr, self.seq_len, flag=float(self.flag)).astype(np.float32)

    def build(self, n_features: int, n_outputs: int = 1):
        from ._modules import FlaggedLSTM

        return FlaggedLSTM(n_features, hidden=self.hidden, layers=self.layers, seq_len=self.seq_len,
                           flag=float(self.flag), n_outputs=n_outputs)
