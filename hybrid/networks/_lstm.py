"""The seed paper's two-layer LSTM fed subsequences with flag values before the start.

The spec (:class:`LSTMNet`), its torch module (:class:`FlaggedLSTM`: a stacked
``nn.LSTM`` plus a linear head) and its CasADi step (:func:`lstm_step_expr`, one
step of the stack; :func:`flagged_lstm_step`, the whole step in either mode).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, replace
from typing import ClassVar

import casadi as ca
import numpy as np
from numpy.typing import NDArray

from physics.data import DataError, lstm_subsequences
from ._base import AbstractNetwork, CasadiStep, check_int, in_chunks, padded_windows
from ._casadi import as_dm, matvec, mlp_expr, sigmoid

__all__ = ["LSTMNet", "FlaggedLSTM", "flagged_lstm_step", "lstm_step_expr", "lstm_state_names"]


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
    label: ClassVar[str] = "LSTM"
    modes: ClassVar[tuple[str, ...]] = ("window", "carried")
    auto_residual: ClassVar[bool] = True

    def for_control(self) -> "LSTMNet":
        """The same LSTM carrying its state from sample to sample (one cell step per sample)."""
        return replace(self, mode="carried")

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

    @classmethod
    def module_class(cls) -> type:
        return _flagged_lstm()

    def build(self, n_features: int, n_outputs: int = 1):
        return _flagged_lstm()(n_features, hidden=self.hidden, layers=self.layers, seq_len=self.seq_len,
                               flag=float(self.flag), n_outputs=n_outputs)

    @classmethod
    def casadi_step(cls, module, inputs, outputs, mode=None, sym=ca.SX) -> CasadiStep:
        """Default mode ``"carried"``: the cheap recurrent step a controller wants."""
        return flagged_lstm_step(module.lstm, module.head, inputs, outputs, mode=mode or "carried",
                                 seq_len=int(module.seq_len), flag=float(module.flag), sym=sym)


# ------------------------------------------------------------------ torch module
@functools.cache
def _flagged_lstm() -> type:
    """Define :class:`FlaggedLSTM` (on first use: importing the specs needs no torch)."""
    import torch
    from torch import Tensor, nn

    class FlaggedLSTM(nn.Module):
        """Stacked LSTM plus a linear head; ``flag`` rows stand for samples before the start."""

        def __init__(self, n_features: int, hidden: int, layers: int, seq_len: int, flag: float, n_outputs: int):
            super().__init__()
            self.n_features, self.n_outputs, self.seq_len, self.flag = n_features, n_outputs, seq_len, flag
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
                return in_chunks(self, padded_windows(features, self.seq_len, self.flag))
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

    FlaggedLSTM.__qualname__ = "FlaggedLSTM"
    return FlaggedLSTM


def __getattr__(name: str):
    if name == "FlaggedLSTM":  # the torch class, defined when first asked for
        return _flagged_lstm()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


# ------------------------------------------------------------------ CasADi step
def _check_lstm(lstm) -> None:
    if getattr(lstm, "bidirectional", False):
        raise ValueError("A bidirectional LSTM is not causal and cannot be stepped; use bidirectional=False.")
    if getattr(lstm, "proj_size", 0):
        raise ValueError("LSTM with proj_size > 0 is not supported; use proj_size=0.")
    if not getattr(lstm, "bias", True):
        raise ValueError("LSTM without biases is not supported; use bias=True.")


def lstm_step_expr(lstm, head, x_t, h, c):
    """One step of a multi-layer ``nn.LSTM`` followed by a ``head`` (e.g. ``nn.Linear``).

    Parameters
    ----------
    lstm : torch.nn.LSTM
        Unidirectional, with biases, no projection. ``batch_first`` does not matter here.
    head : torch.nn.Module or None
        Maps the last layer's hidden state to the output (``mlp_expr`` rules); ``None``
        returns the last hidden state itself.
    x_t : casadi.SX or casadi.MX
        Input at this step, length ``input_size``.
    h, c : casadi.SX or casadi.MX
        Hidden and cell states of all layers stacked, layer 0 first, each
        ``num_layers * hidden_size`` long (see :func:`lstm_state_names`).

    Returns
    -------
    y, h_next, c_next
        The output and the stacked next states. Gates follow torch's order
        ``i, f, g, o`` and each layer's bias is ``b_ih + b_hh``.
    """
    _check_lstm(lstm)
    n, L = lstm.hidden_size, lstm.num_layers
    if h.shape[0] != n * L or c.shape[0] != n * L:
        raise ValueError(f"h and c must each have num_layers * hidden_size = {n * L} entries; "
                         f"got {h.shape[0]} and {c.shape[0]}.")
    inp, hs, cs = x_t, [], []
    for k in range(L):
        w_ih, w_hh = as_dm(getattr(lstm, f"weight_ih_l{k}")), as_dm(getattr(lstm, f"weight_hh_l{k}"))
        b = as_dm(getattr(lstm, f"bias_ih_l{k}")) + as_dm(getattr(lstm, f"bias_hh_l{k}"))
        hk, ck = h[k * n:(k + 1) * n], c[k * n:(k + 1) * n]
        z = matvec(w_hh, hk, matvec(w_ih, inp, b))
        i, f = sigmoid(z[0:n]), sigmoid(z[n:2 * n])
        g, o = ca.tanh(z[2 * n:3 * n]), sigmoid(z[3 * n:4 * n])
        c_new = f * ck + i * g
        h_new = o * ca.tanh(c_new)
        hs.append(h_new)
        cs.append(c_new)
        inp = h_new
    y = inp if head is None else mlp_expr(head, inp)
    return y, ca.vertcat(*hs), ca.vertcat(*cs)


def lstm_state_names(lstm, prefix: str = "lstm") -> list[str]:
    """Names of the stacked state ``[h_l0, ..., h_l{L-1}, c_l0, ..., c_l{L-1}]``."""
    n, L = lstm.hidden_size, lstm.num_layers
    return ([f"{prefix}.h_l{k}[{j}]" for k in range(L) for j in range(n)]
            + [f"{prefix}.c_l{k}[{j}]" for k in range(L) for j in range(n)])


def flagged_lstm_step(lstm, head, inputs, outputs, mode: str = "carried", seq_len: int = 50,
                      flag: float = -1.0, sym=ca.SX) -> CasadiStep:
    """A stacked ``nn.LSTM`` with a ``head`` as a CasADi step (:class:`FlaggedLSTM`'s maths).

    ``mode="carried"``: the state is ``(h, c)`` of every layer (:func:`lstm_state_names`),
    carried from sample to sample; the base state is the one after ``seq_len - 1``
    flag inputs from zero (as ``FlaggedLSTM.initial_state``): the state at the start of every
    run, in training, prediction and export alike. ``mode="window"`` (the paper's
    scheme): the state is the buffer of the previous ``seq_len - 1`` inputs
    (physical units, oldest first) and every step runs the LSTM over the window
    from a zero state: exact but ``seq_len`` times dearer; built in MX around an
    SX cell whatever ``sym`` says.
    """
    n_f, n_h, L = lstm.input_size, lstm.hidden_size, lstm.num_layers
    meta = {"mode": mode, "seq_len": int(seq_len), "flag": float(flag), "hidden": n_h, "layers": L}
    flag_phys = ca.DM(inputs.value_to_physical(float(flag)))
    if mode == "carried":
        x, u = sym.sym("x", 2 * n_h * L), sym.sym("u", n_f)
        y, h, c = lstm_step_expr(lstm, head, inputs.to_scaled(u), x[:n_h * L], x[n_h * L:])
        step = ca.Function("step", [x, u], [ca.vertcat(h, c), outputs.to_physical(y)],
                           ["x", "u"], ["x_next", "y"])
        base = ca.DM.zeros(2 * n_h * L, 1)
        if seq_len > 1:
            xs, _ = step.mapaccum("flags", seq_len - 1)(base, ca.repmat(flag_phys, 1, seq_len - 1))
            base = ca.DM(xs[:, -1])
        x0 = ca.Function("x0", [ca.SX.sym("u0", n_f)], [ca.SX(base)], ["u0"], ["x0"])
        return CasadiStep(step, tuple(lstm_state_names(lstm)), x0, kind=LSTMNet.name, meta=meta)
    if mode != "window":
        raise DataError(f"The LSTM export mode must be 'carried' or 'window'. Got {mode!r} instead.")
    xc, hc, cc = ca.SX.sym("v", n_f), ca.SX.sym("h", n_h * L), ca.SX.sym("c", n_h * L)
    _, h1, c1 = lstm_step_expr(lstm, None, xc, hc, cc)
    cell = ca.Function("lstm_cell", [ca.vertcat(hc, cc), xc], [ca.vertcat(h1, c1)])
    x, u = ca.MX.sym("x", (seq_len - 1) * n_f), ca.MX.sym("u", n_f)
    window = ca.horzcat(ca.reshape(x, n_f, seq_len - 1), u)
    scaled = (window - ca.repmat(ca.DM(inputs.lo), 1, seq_len)) / ca.repmat(ca.DM(inputs.span), 1, seq_len)
    hc_all = cell.mapaccum("window", seq_len)(ca.DM.zeros(2 * n_h * L, 1), scaled)
    h_last = hc_all[(L - 1) * n_h:L * n_h, -1]
    y = outputs.to_physical(mlp_expr(head, h_last))
    x_next = ca.vec(window[:, 1:]) if seq_len > 1 else ca.MX.zeros(0, 1)
    step = ca.Function("step", [x, u], [x_next, y], ["x", "u"], ["x_next", "y"])
    names = tuple(f"buffer.u[k-{seq_len - 1 - i}]" for i in range(seq_len - 1) for _ in range(n_f))
    x0 = ca.Function("x0", [ca.SX.sym("u0", n_f)], [ca.SX(ca.repmat(flag_phys, seq_len - 1, 1))],
                     ["u0"], ["x0"])
    return CasadiStep(step, names, x0, kind=LSTMNet.name, meta=meta)
