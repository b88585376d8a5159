"""Rollouts that return the output and its derivatives with respect to parameters and x0.

Identification uses a Gauss-Newton Hessian ``J^T J``, so what it needs per
trajectory is the Jacobian ``J`` of the output path. For small models the
forward sensitivities are propagated with the state, one step at a time
(``S_{k+1} = f_x S_k + f_p``, ``dy_k = h_x S_k + h_p``): one SX function per
sample, compiled with the system C compiler when there is one (4-5 times faster
than CasADi's interpreter on lag+boucwen+linear). Larger models (Preisach's
relay grid) fall back to CasADi's forward mode over the MX rollout. The plain
rollouts of the line search are compiled too where the step is long (the
hysteretic oscillator's).
"""

from __future__ import annotations

import hashlib
import shutil
from functools import cached_property

import casadi as ca
import numpy as np

from physics import Series
from physics.data.io import compile_function

#: Above this many sensitivity entries (n_x * directions) use MX forward mode instead.
MAX_AUGMENTED = 300
#: A step of at least this many instructions is compiled for the plain rollouts too: the
#: hysteretic oscillator's (2347) took 62 ms per 6000 samples interpreted, 15 ms compiled after
#: a 0.6 s compile; the other blocks' steps (50-800) gain less than twice.
JIT_MIN_INSTRUCTIONS = 1000
#: The flags CasADi's own JIT used (``-O2 -fPIC`` to compile, ``-shared`` to link): the same code.
JIT_FLAGS = ("-O2", "-fPIC", "-shared")

_JIT_CACHE: dict[str, ca.Function] = {}


def _c_compiler() -> str | None:
    return next((c for c in ("gcc", "cc") if shutil.which(c)), None)


def jit_available() -> bool:
    """True when there is a system C compiler to compile generated C with."""
    return _c_compiler() is not None


def _compiled(name: str, inputs, outputs) -> ca.Function:
    """``casadi.Function(name, inputs, outputs)`` compiled (cached by content), or interpreted
    where no compiler works. The compiler runs as a child we can stop (a Ctrl-C or SIGTERM during
    a compile stops the command) and leaves no files behind (:mod:`physics.data._compiler`)."""
    plain = ca.Function(name, inputs, outputs)
    key = hashlib.sha1(plain.serialize().encode()).hexdigest()
    if key not in _JIT_CACHE:
        compiler = _c_compiler()
        try:
            if compiler is None:
                raise RuntimeError("no C compiler")
            # only evaluated compiled: the fits never call its derivatives
            _JIT_CACHE[key] = compile_function(plain, JIT_FLAGS, compiler)
        except RuntimeError:  # no working compiler after all: interpret
            _JIT_CACHE[key] = plain
    return _JIT_CACHE[key]


class SensitivityRollouts:
    """``(x0, u[1 x n], p) -> (y[1 x n], dy[d x n])`` Functions, one per length, cached.

    ``dy`` holds the derivatives of each output sample with respect to the
    free parameters (``free`` mask, in order) and then, when ``with_x0``, to
    the initial state.
    """

    def __init__(self, model: Series, free: np.ndarray, with_x0: bool, jit: bool | None = None):
        self.model = model
        self.idx = [int(i) for i in np.flatnonzero(free)]
        self.with_x0 = bool(with_x0) and model.n_x > 0
        self.d = len(self.idx) + (model.n_x if self.with_x0 else 0)
        self.jit = jit_available() if jit is None else bool(jit)
        self.augmented = 0 < model.n_x and model.n_x * self.d <= MAX_AUGMENTED
        self._cache: dict[int, ca.Function] = {}
        self._plain: dict[int, ca.Function] = {}
        if self.augmented:
            self._step = self._augmented_step()

    def _augmented_step(self) -> ca.Function:
        m = self.model
        x, u, p = ca.SX.sym("x", m.n_x), ca.SX.sym("u"), ca.SX.sym("p", m.n_p)
        S = ca.SX.sym("S", m.n_x, self.d)
        xn, y = m.step_expr(x, u, p)
        direct = [ca.jacobian(xn, p)[:, self.idx], ca.jacobian(y, p)[:, self.idx]]
        if self.with_x0:
            direct = [ca.horzcat(d, ca.SX.zeros(d.shape[0], m.n_x)) for d in direct]
        Sn = ca.mtimes(ca.jacobian(xn, x), S) + direct[0]
        dy = ca.mtimes(ca.jacobian(y, x), S) + direct[1]
        xa = ca.vertcat(x, ca.vec(S))
        inputs, outputs = [xa, u, p], [ca.vertcat(xn, ca.vec(Sn)), ca.vertcat(y, dy.T)]
        if self.jit:
            return _compiled("sensitivity_step", inputs, outputs)
        return ca.Function("sensitivity_step", inputs, outputs)

    def plain(self, n: int) -> ca.Function:
        """``(x0, u[1 x n], p) -> (x, y)``: the rollout alone, for the line search's costs."""
        if n not in self._plain:
            step = self._plain_step
            if step is None:
                self._plain[n] = self.model.rollout(n)
            else:
                m = self.model
                x0, u, p = ca.MX.sym("x0", m.n_x), ca.MX.sym("u", 1, n), ca.MX.sym("p", m.n_p)
                xs, ys = step.mapaccum("plain_rollout", int(n))(x0, u, ca.repmat(p, 1, n))
                self._plain[n] = ca.Function("rollout", [x0, u, p], [xs, ys], ["x0", "u", "p"], ["x", "y"])
        return self._plain[n]

    @cached_property
    def _plain_step(self) -> ca.Function | None:
        """The model's step compiled, where it has :data:`JIT_MIN_INSTRUCTIONS` or more (a fit
        runs it hundreds of times); None where the model's own interpreted rollout does."""
        if not self.jit:
            return None
        step = self.model.step_function()
        if step.n_instructions() < JIT_MIN_INSTRUCTIONS:
            return None
        return _compiled("step", step.sx_in(), list(step(*step.sx_in())))

    def __call__(self, n: int) -> ca.Function:
        if n not in self._cache:
            self._cache[n] = self._build(n)
        return self._cache[n]

    def _build(self, n: int) -> ca.Function:
        m = self.model
        x0, u, p = ca.MX.sym("x0", m.n_x), ca.MX.sym("u", 1, n), ca.MX.sym("p", m.n_p)
        if self.augmented:
            seed = ca.DM.zeros(m.n_x, self.d)
            if self.with_x0:
                seed[:, len(self.idx):] = ca.DM.eye(m.n_x)
            acc = self._step.mapaccum("sensitivity_rollout", n)
            _, out = acc(ca.vertcat(x0, ca.vec(seed)), u, ca.repmat(p, 1, n))
            y, dy = out[0, :], out[1:, :]
        else:
            _, y = m.rollout(n)(x0, u, p)
            parts = [ca.jacobian(y.T, p)[:, self.idx]]
            if self.with_x0:
                parts.append(ca.jacobian(y.T, x0))
            dy = ca.horzcat(*parts).T
        return ca.Function("sensitivity_rollout", [x0, u, p], [y, dy],
                           ["x0", "u", "p"], ["y", "dy"])
