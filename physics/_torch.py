"""CasADi functions called from torch with exact gradients.

The physics stays written once, in CasADi; torch code (residual training with
the physics parameters fine-tuned jointly, neural-ODE hybrids) calls the same
graph through :func:`torch_function`. The backward pass is CasADi's reverse mode
(``Function.reverse``), so the gradients are those of the CasADi graph itself.
"""

from __future__ import annotations

import casadi as ca
import numpy as np


def torch_function(f: ca.Function):
    """Wrap a CasADi ``Function`` as a differentiable torch function.

    The wrapper takes one tensor per CasADi input, each of the input's shape
    (column vectors may be given 1-D), and returns one float64 tensor per
    output, of the output's shape. Gradients flow to every input that requires
    them.

    Examples
    --------
    >>> import torch, casadi as ca
    >>> x = ca.SX.sym("x", 2)
    >>> f = torch_function(ca.Function("f", [x], [ca.sumsqr(x)]))
    >>> t = torch.tensor([1.0, 2.0], dtype=torch.float64, requires_grad=True)
    >>> f(t)[0].backward(); t.grad.tolist()
    [2.0, 4.0]
    """
    import torch

    rev = f.reverse(1)
    n_in, n_out = f.n_in(), f.n_out()
    in_shapes = [(f.size1_in(i), f.size2_in(i)) for i in range(n_in)]
    out_shapes = [(f.size1_out(i), f.size2_out(i)) for i in range(n_out)]

    def to_np(t, shape):
        return np.asarray(t.detach().cpu().to(torch.float64).numpy(), dtype=float).reshape(shape, order="F")

    def to_torch(dm, like_shape):
        arr = np.asarray(ca.DM(dm).full(), dtype=float)
        return torch.from_numpy(arr.reshape(like_shape, order="F").copy())

    class _CasadiFunction(torch.autograd.Function):
        @staticmethod
        def forward(ctx, *args):
            shapes = [tuple(a.shape) for a in args]
            np_args = [to_np(a, s) for a, s in zip(args, in_shapes)]
            outs = f.call(np_args)
            ctx.np_args, ctx.outs, ctx.shapes = np_args, outs, shapes
            return tuple(to_torch(o, s) for o, s in zip(outs, out_shapes))

        @staticmethod
        def backward(ctx, *grads):
            seeds = [to_np(g, s) if g is not None else np.zeros(s)
                     for g, s in zip(grads, out_shapes)]
            sens = rev.call(ctx.np_args + list(ctx.outs) + seeds)
            return tuple(to_torch(s, shape) if need else None
                         for s, shape, need in zip(sens, ctx.shapes, ctx.needs_input_grad))

    def call(*args):
        if len(args) != n_in:
            raise TypeError(f"{f.name()} takes {n_in} inputs ({', '.join(f.name_in())}); got {len(args)}.")
        return _CasadiFunction.apply(*args)

    return call
