"""Torch layers written as CasADi expressions, their weights folded in as float64 constants.

The building blocks each network's ``casadi_step`` writes itself with. They work
on SX and MX alike: each torch layer becomes the same arithmetic on
``casadi.DM`` constants, so the result equals torch's float64 forward pass to
rounding (tests check 1e-12 on values and Jacobians).
"""

from __future__ import annotations

import casadi as ca
import numpy as np

__all__ = ["mlp_expr", "as_dm", "matvec", "sigmoid", "MAC_BLOCK"]

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


def sigmoid(z):
    return 1 / (1 + ca.exp(-z))
