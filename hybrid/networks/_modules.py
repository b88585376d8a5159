"""Torch modules behind the network specs (imported only when a network is built).

Each module runs three ways that agree to float rounding:

``forward(windows)``
    training batches, shape (B, history, n_features) -> (B, n_outputs);
``sequence(features, mode)``
    a whole trajectory at once, shape (n, n_features) -> (n, n_outputs);
``initial_state(x0, mode)`` and ``step(state, x) -> (state, y)``
    one sample at a time with the state passed in and out (a controller's view).
"""

from __future__ import annotations

import torch
from torch import Tensor, nn

__all__ = ["BufferMLP", "FlaggedLSTM"]

_CHUNK = 4096  # windows per batch in sequence(); bounds memory on long trajectories


def _padded_windows(features: Tensor, length: int, pad: str | float) -> Tensor:
    """(n, f) -> (n, length, f): the window ending at each sample, oldest first."""
    if length > 1:
        head = features[:1].expand(length - 1, -1) if pad == "edge" else features.new_full(
            (length - 1, features.shape[1]), float(pad))
        features = torch.cat([head, features], dim=0)
    return features.unfold(0, length, 1).transpose(1, 2)


class BufferMLP(nn.Module):
    """ReLU MLP on the flattened buffer of the last ``buffer`` inputs (FNN when buffer = 1)."""

    def __init__(self, n_features: int, buffer: int, hidden: tuple[int, ...], n_outputs: int, pad: str | float):
        super().__init__()
        self.n_features, self.buffer, self.pad = n_features, buffer, pad
        widths = [buffer * n_features, *hidden]
        layers: list[nn.Module] = []
        for a, b in zip(widths[:-1], widths[1:]):
            layers += [nn.Linear(a, b), nn.ReLU()]
        layers.append(nn.Linear(widths[-1], n_outputs))
        self.net = nn.Sequential(*layers)

    def forward(self, windows: Tensor) -> Tensor:
        return self.net(windows.reshape(windows.shape[0], -1))

    @torch.no_grad()
    def sequence(self, features: Tensor, mode: str = "window") -> Tensor:
        windows = _padded_windows(features, self.buffer, self.pad)
        return torch.cat([self(windows[i:i + _CHUNK]) for i in range(0, windows.shape[0], _CHUNK)])

    @torch.no_grad()
    def initial_state(self, x0: Tensor, mode: str = "window") -> Tensor:
        """The buffer before the first sample: ``x0`` repeated ("edge") or the pad value."""
        if self.pad == "edge":
            return x0.reshape(1, -1).repeat(self.buffer, 1)
        return x0.new_full((self.buffer, self.n_features), float(self.pad))

    @torch.no_grad()
    def step(self, state: Tensor, x: Tensor) -> tuple[Tensor, Tensor]:
        buf = torch.cat([state[1:], x.reshape(1, -1)])
        return buf, self(buf[None])[0]


class FlaggedLSTM(nn.Module):
    """Stacked LSTM plus a linear head; ``flag`` rows stand for samples before the start."""

    def __init__(self, n_features: int, hidden: int, layers: int, seq_len: int, flag: float, n_outputs: int):
        super().__init__()
        self.n_features, self.seq_len, self.flag = n_features, seq_len, flag
        self.lstm = nn.LSTM(n_features, hidden, num_layers=layers, batch_first=True)
        self.head = nn.Linear(hidden, n_outputs)

    def forward(self, windows: Tensor) -> Tensor:
        out, _ = self.lstm(windows)
        return self.head(out[:, -1])

    def _flags(self, like: Tensor, count: int) -> Tensor:
        return like.new_full((count, self.n_features), self.flag)

    @torch.no_grad()
    def sequence(self, features: Tensor, mode: str = "window") -> Tensor:
        if mode == "window":
            windows = _padded_windows(features, self.seq_len, self.flag)
            return torch.cat([self(windows[i:i + _CHUNK]) for i in range(0, windows.shape[0], _CHUNK)])
        x = torch.cat([self._flags(features, self.seq_len - 1), features])[None]
        out, _ = self.lstm(x)
        return self.head(out[0, self.seq_len - 1:])

    @torch.no_grad()
    def initial_state(self, x0: Tensor, mode: str = "window"):
        """"window": the buffer of the last ``seq_len`` inputs, all flags. "carried": (h, c)
        after the ``seq_len - 1`` leading flags (x0 only sets dtype)."""
        if mode == "window":
            return self._flags(x0, self.seq_len)
        zeros = x0.new_zeros(self.lstm.num_layers, 1, self.lstm.hidden_size)
        if self.seq_len == 1:
            return (zeros, zeros.clone())
        _, hc = self.lstm(self._flags(x0, self.seq_len - 1)[None])
        return hc

    @torch.no_grad()
    def step(self, state, x: Tensor):
        if isinstance(state, Tensor):  # window mode: state is the input buffer
            buf = torch.cat([state[1:], x.reshape(1, -1)])
            return buf, self(buf[None])[0]
        out, hc = self.lstm(x.reshape(1, 1, -1), state)
        return hc, self.head(out[0, 0])
