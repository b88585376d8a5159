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


def _op_tables(torch):
    unary = {
        ca.OP_ASSIGN: lambda a: a, ca.OP_NEG: torch.neg, ca.OP_EXP: torch.exp,
        ca.OP_LOG: torch.log, ca.OP_SQRT: torch.sqrt, ca.OP_SQ: lambda a: a * a,
        ca.OP_TWICE: lambda a: 2 * a, ca.OP_INV: torch.reciprocal, ca.OP_FABS: torch.abs,
        ca.OP_SIN: torch.sin, ca.OP_COS: torch.cos, ca.OP_TAN: torch.tan,
        ca.OP_TANH: torch.tanh, ca.OP_ATAN: torch.atan, ca.OP_SIGN: torch.sign,
        ca.OP_NOT: lambda a: (a == 0).to(a.dtype), ca.OP_FLOOR: torch.floor,
        ca.OP_CEIL: torch.ceil, ca.OP_LOG1P: torch.log1p, ca.OP_EXPM1: torch.expm1,
        ca.OP_ERF: torch.erf, ca.OP_SINH: torch.sinh, ca.OP_COSH: torch.cosh,
    }
    binary = {
        ca.OP_ADD: torch.add, ca.OP_SUB: torch.sub, ca.OP_MUL: torch.mul, ca.OP_DIV: torch.div,
        ca.OP_POW: torch.pow, ca.OP_CONSTPOW: torch.pow, ca.OP_FMIN: torch.minimum,
        ca.OP_FMAX: torch.maximum, ca.OP_ATAN2: torch.atan2, ca.OP_COPYSIGN: torch.copysign,
        ca.OP_LT: lambda a, b: (a < b).to(a.dtype), ca.OP_LE: lambda a, b: (a <= b).to(a.dtype),
        ca.OP_EQ: lambda a, b: (a == b).to(a.dtype), ca.OP_NE: lambda a, b: (a != b).to(a.dtype),
        ca.OP_AND: lambda a, b: ((a != 0) & (b != 0)).to(a.dtype),
        ca.OP_OR: lambda a, b: ((a != 0) | (b != 0)).to(a.dtype),
        ca.OP_IF_ELSE_ZERO: lambda c, b: torch.where(c != 0, b, torch.zeros_like(b)),
    }
    return unary, binary


def torch_expression(f: ca.Function):
    """A pure-torch function evaluating the SX graph of ``f`` instruction by instruction.

    Unlike :func:`torch_function`, which calls CasADi, this is derived once from
    the CasADi graph and then runs in torch alone: batched (every input may
    carry leading batch dimensions, ``(..., numel)``), on any device, with torch
    autograd. Each input is given flattened column-major as ``(..., numel)``;
    each output is returned the same way (structural zeros filled in).
    Raises ``ValueError`` for an MX function or an operation it does not know.
    """
    import torch

    if not f.is_a("SXFunction"):
        f = f.expand()
    unary, binary = _op_tables(torch)
    program = []
    for k in range(f.n_instructions()):
        op = f.instruction_id(k)
        ins, outs = f.instruction_input(k), f.instruction_output(k)
        if op == ca.OP_CONST:
            program.append((op, float(f.instruction_constant(k)), outs))
        elif op in (ca.OP_INPUT, ca.OP_OUTPUT) or op in unary or op in binary:
            program.append((op, ins, outs))
        else:
            raise ValueError(f"torch_expression: CasADi operation {op} in '{f.name()}' is not "
                             "supported; use torch_function (calls CasADi) instead.")
    in_nz = [np.array(f.sparsity_in(i).find(), dtype=int) for i in range(f.n_in())]
    out_nz = [np.array(f.sparsity_out(i).find(), dtype=int) for i in range(f.n_out())]
    out_numel = [f.numel_out(i) for i in range(f.n_out())]

    def evaluate(*args):
        if len(args) != f.n_in():
            raise TypeError(f"{f.name()} takes {f.n_in()} inputs; got {len(args)}.")
        ref = next((a for a in args if torch.is_tensor(a)), torch.zeros(()))
        args = [torch.as_tensor(a, dtype=ref.dtype if ref.is_floating_point() else torch.float64)
                for a in args]
        batch = torch.broadcast_shapes(*[a.shape[:-1] for a in args if a.dim() > 0])
        w: dict[int, object] = {}
        parts = [dict() for _ in range(f.n_out())]
        for op, ins, outs in program:
            if op == ca.OP_CONST:
                w[outs[0]] = torch.tensor(ins, dtype=args[0].dtype)
            elif op == ca.OP_INPUT:
                w[outs[0]] = args[ins[0]][..., in_nz[ins[0]][ins[1]]]
            elif op == ca.OP_OUTPUT:
                parts[outs[0]][out_nz[outs[0]][outs[1]]] = w[ins[0]]
            elif op in unary:
                w[outs[0]] = unary[op](w[ins[0]])
            else:
                w[outs[0]] = binary[op](w[ins[0]], w[ins[1]])
        results = []
        for i in range(f.n_out()):
            zero = torch.zeros(batch, dtype=args[0].dtype)
            cols = [torch.broadcast_to(parts[i].get(j, zero), batch) for j in range(out_numel[i])]
            results.append(torch.stack(cols, dim=-1) if cols else torch.zeros(*batch, 0))
        return results

    return evaluate
