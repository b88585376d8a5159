"""Torch modules written as CasADi expressions, their weights folded in as float64 constants.

The expressions work on SX and MX alike. Each torch layer becomes the same
arithmetic on ``casadi.DM`` constants, so the result equals torch's float64
forward pass to rounding (tests check 1e-12 on values and Jacobians).
"""

from __future__ import annotations

import casadi as ca
import numpy as np

__all__ = ["mlp_expr", "lstm_step_expr", "lstm_state_names", "as_dm", "matvec"]

#: Columns per multiply-accumulate node of an MX matrix-vector product (see :func:`matvec`).
MAC_BLOCK = 8


def as_dm(tensor) -> ca.DM:
    """A torch tensor (any dtype) as a float64 ``casadi.DM`` (vectors become columns)."""
    arr = np.asarray(tensor.detach().cpu().double().numpy(), dtype=np.float64)
    return ca.DM(arr.reshape(-1, 1) if arr.ndim == 1 else arr)


def matvec(weight: ca.DM, v, acc=None):
    """``acc + weight @ v`` with a float64 constant ``weight``, shaped for fast generated C.

    On SX this is ``mtimes``. On MX it is a chain of multiply-accumulate nodes over
    blocks of :data:`MAC_BLOCK` columns, ``z += W[:, k:k+8] @ v[k:k+8]``: CasADi writes
    each as a short loop whose long dimension runs over contiguous rows, which gcc
    ``-O3`` vectorises. One ``mtimes`` node instead becomes a strided dot product per
    row, three times slower in C (an LSTM 2 x 64 step: 15 us against 45 us for a
    whole-matrix node, measured by ``benchmarks/export_mpc.py``). Same value up to
    rounding of the summation order. ``acc`` (default zero) starts the sum.
    """
    if not isinstance(v, ca.MX) or weight.shape[1] <= MAC_BLOCK:
        return ca.mtimes(weight, v) if acc is None else acc + ca.mtimes(weight, v)
    w = np.asarray(weight.full())
    z = ca.MX.zeros(w.shape[0], 1) if acc is None else ca.MX(acc)
    for k in range(0, w.shape[1], MAC_BLOCK):
        end = min(k + MAC_BLOCK, w.shape[1])
        z = ca.mac(ca.DM(w[:, k:end]), v[k:end], z)
    return z


def _activation(module, x):
    import torch.nn as nn

    if isinstance(module, nn.ReLU):
        return ca.fmax(x, 0)
    if isinstance(module, nn.Tanh):
        return ca.tanh(x)
    if isinstance(module, nn.Sigmoid):
        return 1 / (1 + ca.exp(-x))
    if isinstance(module, (nn.Identity, nn.Dropout)):
        return x  # dropout is the identity at inference
    raise TypeError(
        f"mlp_expr supports Linear, ReLU, Tanh, Sigmoid, Identity and Dropout layers; "
        f"got {type(module).__name__}. Write an exporter for it or use those layers."
    )


def mlp_expr(sequential, x):
    """Output of ``sequential`` (``nn.Sequential`` or a single ``nn.Linear``) at ``x``.

    Parameters
    ----------
    sequential : torch.nn.Module
        ``nn.Sequential`` of ``Linear``/``ReLU``/``Tanh``/``Sigmoid``/``Identity`` (nested
        ``Sequential`` allowed), or one ``Linear``.
    x : casadi.SX or casadi.MX
        Column vector of length ``in_features`` of the first ``Linear``.

    Examples
    --------
    >>> import casadi as ca, torch
    >>> net = torch.nn.Sequential(torch.nn.Linear(1, 4), torch.nn.ReLU(), torch.nn.Linear(4, 1))
    >>> x = ca.SX.sym("x")
    >>> ca.Function("f", [x], [mlp_expr(net, x)]).size1_out(0)
    1
    """
    import torch.nn as nn

    layers = [sequential] if isinstance(sequential, nn.Linear) else list(_flatten(sequential))
    for layer in layers:
        if isinstance(layer, nn.Linear):
            if x.shape[0] != layer.in_features:
                raise ValueError(f"A Linear layer expects {layer.in_features} inputs; "
                                 f"the expression has {x.shape[0]}.")
            x = matvec(as_dm(layer.weight), x, None if layer.bias is None else as_dm(layer.bias))
        else:
            x = _activation(layer, x)
    return x


def _flatten(module):
    import torch.nn as nn

    for child in module.children() if isinstance(module, nn.Sequential) else [module]:
        if isinstance(child, nn.Sequential):
            yield from _flatten(child)
        else:
            yield child


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
        i, f = _sigmoid(z[0:n]), _sigmoid(z[n:2 * n])
        g, o = ca.tanh(z[2 * n:3 * n]), _sigmoid(z[3 * n:4 * n])
        c_new = f * ck + i * g
        h_new = o * ca.tanh(c_new)
        hs.append(h_new)
        cs.append(c_new)
        inp = h_new
    y = inp if head is None else mlp_expr(head, inp)
    return y, ca.vertcat(*hs), ca.vertcat(*cs)


def _sigmoid(z):
    return 1 / (1 + ca.exp(-z))


def lstm_state_names(lstm, prefix: str = "lstm") -> list[str]:
    """Names of the stacked state ``[h_l0, ..., h_l{L-1}, c_l0, ..., c_l{L-1}]``."""
    n, L = lstm.hidden_size, lstm.num_layers
    return ([f"{prefix}.h_l{k}[{j}]" for k in range(L) for j in range(n)]
            + [f"{prefix}.c_l{k}[{j}]" for k in range(L) for j in range(n)])
