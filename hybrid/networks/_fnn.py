"""Feedforward networks: the plain FNN and the FNN with a history input buffer (FNN-HIB).

Both run one torch module, :class:`BufferMLP` (a ReLU MLP on the flattened buffer
of the last ``buffer`` inputs; the FNN is ``buffer = 1``), and one CasADi step
(:func:`buffer_mlp_step`: the buffer is a shift register of inputs).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import ClassVar

import casadi as ca
import numpy as np
from numpy.typing import NDArray

from physics.data import DataError, history_windows
from ._base import AbstractNetwork, CasadiStep, check_int, in_chunks, padded_windows
from ._casadi import mlp_expr

__all__ = ["FNNNet", "FNNHIBNet", "BufferMLP", "buffer_mlp_step"]


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
    label: ClassVar[str] = "FNN"

    def __post_init__(self) -> None:
        object.__setattr__(self, "hidden", tuple(self.hidden))
        _check_hidden("FNNNet", self.hidden)

    @property
    def history(self) -> int:
        return 1

    def windows(self, features: NDArray[np.float64]) -> NDArray[np.float32]:
        arr = self.check_features(features)
        return arr[:, None, :].astype(np.float32)

    @classmethod
    def module_class(cls) -> type:
        return _buffer_mlp()

    def build(self, n_features: int, n_outputs: int = 1):
        return _buffer_mlp()(n_features, buffer=1, hidden=self.hidden, n_outputs=n_outputs, pad="edge")

    @classmethod
    def casadi_step(cls, module, inputs, outputs, mode=None, sym=ca.SX) -> CasadiStep:
        return _module_step(module, inputs, outputs, sym)


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
    label: ClassVar[str] = "FNN-HIB"
    auto_residual: ClassVar[bool] = True

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

    @classmethod
    def module_class(cls) -> type:
        return _buffer_mlp()

    def build(self, n_features: int, n_outputs: int = 1):
        return _buffer_mlp()(n_features, buffer=self.buffer, hidden=self.hidden, n_outputs=n_outputs, pad=self.pad)

    @classmethod
    def casadi_step(cls, module, inputs, outputs, mode=None, sym=ca.SX) -> CasadiStep:
        return _module_step(module, inputs, outputs, sym)


# ------------------------------------------------------------------ torch module
@functools.cache
def _buffer_mlp() -> type:
    """Define :class:`BufferMLP` (on first use: importing the specs needs no torch)."""
    import torch
    from torch import Tensor, nn

    class BufferMLP(nn.Module):
        """ReLU MLP on the flattened buffer of the last ``buffer`` inputs (FNN when buffer = 1)."""

        def __init__(self, n_features: int, buffer: int, hidden: tuple[int, ...], n_outputs: int,
                     pad: str | float):
            super().__init__()
            self.n_features, self.n_outputs, self.buffer, self.pad = n_features, n_outputs, buffer, pad
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
            return in_chunks(self, padded_windows(features, self.buffer, self.pad))

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

    BufferMLP.__qualname__ = "BufferMLP"
    return BufferMLP


def __getattr__(name: str):
    if name == "BufferMLP":  # the torch class, defined when first asked for
        return _buffer_mlp()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


# ------------------------------------------------------------------ CasADi step
def _module_step(module, inputs, outputs, sym) -> CasadiStep:
    return buffer_mlp_step(module.net, int(module.buffer), int(module.n_features), module.pad, inputs, outputs, sym)


def buffer_mlp_step(net, buffer: int, n_features: int, pad: str | float, inputs, outputs, sym=ca.SX) -> CasadiStep:
    """An MLP ``net`` on the last ``buffer`` inputs as a CasADi step (FNN-HIB; ``buffer=1``: FNN).

    The network sees the window ``[v_{k-buffer+1}, ..., v_k]`` (oldest first,
    flattened row by row as ``windows.reshape(B, -1)``). The state is the
    previous ``buffer - 1`` input rows in physical units, oldest first (a shift
    register): ``x = torch_state[1:]`` of :class:`BufferMLP`. ``pad`` is what fills the
    buffer before the start (``"edge"``: the first input; a number: that value in
    scaled units), as in training.
    """
    n_f = n_features
    x, u = sym.sym("x", (buffer - 1) * n_f), sym.sym("u", n_f)
    rows = [x[i * n_f:(i + 1) * n_f] for i in range(buffer - 1)] + [u]
    window = ca.vertcat(*[inputs.to_scaled(r) for r in rows])
    y = outputs.to_physical(mlp_expr(net, window))
    x_next = ca.vertcat(*rows[1:]) if buffer > 1 else sym.zeros(0, 1)
    step = ca.Function("step", [x, u], [x_next, y], ["x", "u"], ["x_next", "y"])
    u0 = ca.SX.sym("u0", n_f)
    # the buffer before the first sample, as in training and prediction (padded_windows)
    if pad == "edge":
        base = ca.repmat(u0, buffer - 1, 1)
    else:
        base = ca.repmat(ca.DM(inputs.value_to_physical(float(pad))), buffer - 1, 1)
    names = tuple(f"buffer.v{j}[k-{buffer - 1 - i}]" if n_f > 1 else f"buffer.u[k-{buffer - 1 - i}]"
                  for i in range(buffer - 1) for j in range(n_f))
    kind = FNNNet.name if buffer == 1 else FNNHIBNet.name
    x0 = ca.Function("x0", [u0], [ca.SX(base)], ["u0"], ["x0"])
    return CasadiStep(step, names, x0, kind=kind, meta={"buffer": int(buffer), "pad": pad})
