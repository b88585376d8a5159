"""Rollouts that return the output and its derivatives with respect to parameters and x0.

Identification uses a Gauss-Newton Hessian ``J^T J``, so what it needs per
trajectory is the Jacobian ``J`` of the output path. For small models the
forward sensitivities are propagated with the state, one step at a time
(``S_{k+1} = f_x S_k + f_p``, ``dy_k = h_x S_k + h_p``): one SX function per
sample, compiled with the system C compiler when there is one (4-5 times faster
than CasADi's interpreter on lag+boucwen+linear). Larger models (Preisach's
relay grid) fall back to CasADi's forward mode over the MX rollout. The plain
rollouts of the line search and of the starting grid are compiled too
(:func:`plain_rollout`: the same numbers, bit for bit, about twice as fast).
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import os
import shutil
import subprocess
from pathlib import Path

import casadi as ca
import numpy as np

from physics import Series
from physics._cache import built
from physics.data.io import compile_function, load_function

#: Above this many sensitivity entries that can be nonzero (:func:`_reachable`) use MX forward mode
#: instead. Counted on the pattern, not on ``n_x * directions``: a creep's relaxed start makes x0 a
#: function of the parameters, which adds ``n_x`` directions, and resonance+gpi+poly+creep+linear's
#: dense 336 entries (212 reachable) fell back to forward mode, 20 times as slow per fit.
MAX_AUGMENTED = 300
#: Plain rollouts built (:func:`plain_rollout`), by the model's structure and length; the oldest go first.
_ROLLOUTS: dict[tuple, ca.Function] = {}
_ROLLOUT_CACHE_SIZE = 512
#: ``-O1``: the same numbers as CasADi's own JIT's ``-O2`` (bit for bit: no flag here reorders floating
#: point) and rollouts as fast, compiled in two thirds of the CPU time (0.6-0.9 s against 0.8-1.3 s
#: for the selection's larger steps), which a selection pays once per spec and worker.
JIT_FLAGS = ("-O1", "-fPIC", "-shared")

_JIT_CACHE: dict[str, ca.Function] = {}
#: A folder the pool's worker processes share compiled libraries through where :func:`jit_cache` is off.
_SHARED: list[Path] = []


def _c_compiler() -> str | None:
    return next((c for c in ("gcc", "cc") if shutil.which(c)), None)


def jit_available() -> bool:
    """True when there is a system C compiler to compile generated C with."""
    return _c_compiler() is not None


def _compiled(name: str, inputs, outputs) -> ca.Function:
    """``casadi.Function(name, inputs, outputs)`` compiled (cached by content), or interpreted
    where no compiler works. The compiler runs as a child we can stop (a Ctrl-C or SIGTERM during
    a compile stops the command) and leaves no files behind (:mod:`physics.data._compiler`)."""
    return _JIT_CACHE[_compiled_key(ca.Function(name, inputs, outputs))]


def _compiled_key(plain: ca.Function) -> str:
    """The content key of ``plain`` in ``_JIT_CACHE``, compiled there first if it is new: loaded from the
    library kept for it (:func:`jit_cache`, or the pool's folder, :func:`shared_compiles`) when there is
    one, else compiled and kept there for the next process."""
    key = hashlib.sha1(plain.serialize().encode()).hexdigest()
    if key not in _JIT_CACHE:
        compiler = _c_compiler()
        try:
            if compiler is None:
                raise RuntimeError("no C compiler")
            # only evaluated compiled: the fits never call its derivatives
            _JIT_CACHE[key] = _kept(plain, key, compiler)
        except RuntimeError:  # no working compiler after all: interpret
            _JIT_CACHE[key] = plain
    return key


def _kept(plain: ca.Function, key: str, compiler: str) -> ca.Function:
    """``plain`` compiled: the kept library of the same C, flags and compiler, or a new one (kept)."""
    folder = jit_cache() or (_SHARED[-1] if _SHARED else None)
    if folder is None:
        return compile_function(plain, JIT_FLAGS, compiler)
    library = folder / (hashlib.sha1(" ".join([key, *JIT_FLAGS, *_compiler_identity(compiler)]).encode()).hexdigest()
                        + ".so")
    if library.is_file():
        try:
            return load_function(plain.name(), library)
        except RuntimeError:  # not a library of this function after all: compile it again
            pass
    return compile_function(plain, JIT_FLAGS, compiler, keep=library)  # kept where the folder can be written


def jit_cache() -> Path | None:
    """The folder compiled steps are kept in between runs, by the content of their C, the flags and the
    compiler (so a kept library is the one a compile would give): ``$HYST_JIT_CACHE``, else
    ``$XDG_CACHE_HOME/hysteresis-hybrid/jit`` (``~/.cache/...``); ``HYST_JIT_CACHE=off`` keeps none."""
    value = os.environ.get("HYST_JIT_CACHE")
    if value is not None and value.strip().lower() in ("", "0", "off", "no", "false"):
        return None
    if value:
        return Path(value)
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "hysteresis-hybrid" / "jit"


@functools.cache
def _compiler_identity(compiler: str) -> tuple[str, ...]:
    """The compiler's path, version and target: a kept library is used only with the same."""
    path = shutil.which(compiler) or compiler
    try:
        out = subprocess.run([path, "-dumpfullversion", "-dumpmachine"], capture_output=True, text=True, timeout=30)
        return (path, *out.stdout.split())
    except (OSError, subprocess.SubprocessError):
        return (path,)


@contextlib.contextmanager
def shared_compiles(folder):
    """Inside, compiled libraries are shared through ``folder`` (None: not shared): one worker process
    compiles a step and the others load it (the selection's fold fits of one spec run in several)."""
    if folder is None:
        yield
        return
    _SHARED.append(Path(folder))
    try:
        yield
    finally:
        _SHARED.pop()


#: Steps per call of a compiled chunk (:func:`_chunked`): a rollout calls its step through CasADi's
#: ``mapaccum`` about 0.15-0.2 us a step; a chunk runs this many in one compiled loop (plain rollouts
#: 1.4-1.7 times as fast, with sensitivities up to 1.3 times; the same numbers bit for bit).
CHUNK = 64


def _chunked(step: ca.Function, n: int, x0, u, p, states: bool = True) -> tuple:
    """``(xs, outs)``: ``step`` (``(x, u, p) -> (x_next, out)``, SX) run over the ``n`` columns of ``u``
    from ``x0``, :data:`CHUNK` steps per call of one compiled loop (cached by content); ``xs`` None
    without ``states``. The input is padded with its last value to whole chunks, and what the padded
    steps give is dropped (a step only looks back)."""
    X, U, P = ca.MX.sym("x", step.size1_in(0)), ca.MX.sym("u", 1, CHUNK), ca.MX.sym("p", step.size1_in(2))
    xs, outs = step.mapaccum("steps", CHUNK)(X, U, ca.repmat(P, 1, CHUNK))
    chunk = _compiled(f"{step.name()}_chunk", [X, U, P], [xs[:, CHUNK - 1], outs] + ([xs] if states else []))
    q = -(-n // CHUNK)
    padded = ca.horzcat(u, ca.repmat(u[:, n - 1], 1, q * CHUNK - n)) if q * CHUNK > n else u
    _, outs, *xs = chunk.mapaccum("chunks", q)(x0, padded, ca.repmat(p, 1, q))
    return (xs[0][:, :n] if states else None), outs[:, :n]


def _shared(outputs: list) -> list:
    """SX ``outputs`` with each subexpression they repeat computed once (``casadi.cse``: the same operations
    on the same operands, so the same numbers bit for bit; a sensitivity step has 15-28 % fewer)."""
    sizes = np.cumsum([0] + [o.numel() for o in outputs])
    joint = ca.cse(ca.vertcat(*[ca.vec(o) for o in outputs]))
    return [ca.reshape(joint[a:b], o.shape) for a, b, o in zip(sizes[:-1], sizes[1:], outputs)]


def plain_rollout(model: Series, n: int, jit: bool | None = None) -> ca.Function:
    """``(x0, u[1 x n], p) -> (x, y)``: :meth:`Series.rollout` over the model's step compiled (bit for bit
    the same numbers: the same operations in the same order, no flag that reorders them; the steps of
    the selection's specs ran 1.8-2.5 times as fast over 1,700 samples). A fit's line search and its
    starting grid run it hundreds of times. The model's own rollout where there is no compiler (or
    ``jit=False``) or no state."""
    if not (jit_available() if jit is None else jit) or model.n_x == 0:
        return model.rollout(n)
    def build() -> ca.Function:
        x0, u, p = ca.MX.sym("x0", model.n_x), ca.MX.sym("u", 1, n), ca.MX.sym("p", model.n_p)
        step = model.step_function()
        step = ca.Function(step.name(), step.sx_in(), _shared(step.call(step.sx_in())))
        xs, ys = _chunked(step, int(n), x0, u, p)
        return ca.Function("rollout", [x0, u, p], [xs, ys], ["x0", "u", "p"], ["x", "y"])

    # by structure: the same step as its content's key, without serializing it
    return built(_ROLLOUTS, (model._structure(), int(n)), _ROLLOUT_CACHE_SIZE, build)


#: Sensitivity rollouts built (:func:`sensitivity_rollouts`), by structure, directions and compiler use;
#: each keeps its rollouts over every length it was asked (0.1-0.15 MB each), so fewer of them are kept.
_KERNELS: dict[tuple, "SensitivityRollouts"] = {}
_KERNEL_CACHE_SIZE = 64


def sensitivity_rollouts(model: Series, free: np.ndarray, with_x0: bool, jit: bool | None = None):
    """:class:`SensitivityRollouts` of ``model``, built once per structure, free parameters, ``with_x0``
    and ``jit`` (the oldest go first): each of a selection's fold fits would otherwise build the step
    with its sensitivities and the rollouts over each run's length again, about a tenth of its time."""
    jit = jit_available() if jit is None else bool(jit)
    key = (model._structure(), tuple(np.flatnonzero(free).tolist()), bool(with_x0) and model.n_x > 0, jit)
    return built(_KERNELS, key, _KERNEL_CACHE_SIZE, lambda: SensitivityRollouts(model, free, with_x0, jit))


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
        self._cache: dict[int, ca.Function] = {}
        self._step, self._pattern = self._augmented_step() if model.n_x > 0 else (None, None)
        self.augmented = self._step is not None

    def _augmented_step(self) -> tuple[ca.Function | None, ca.Sparsity]:
        """The step with the sensitivities on their pattern (:func:`_reachable`), and that pattern; the
        step is None when the pattern holds more than :data:`MAX_AUGMENTED` entries."""
        m = self.model
        x, u, p = ca.SX.sym("x", m.n_x), ca.SX.sym("u"), ca.SX.sym("p", m.n_p)
        xn, y = m.step_expr(x, u, p)
        direct = [ca.jacobian(xn, p)[:, self.idx], ca.jacobian(y, p)[:, self.idx]]
        if self.with_x0:
            direct = [ca.horzcat(d, ca.SX.zeros(d.shape[0], m.n_x)) for d in direct]
        f_x = ca.jacobian(xn, x)
        pattern = _reachable(f_x, direct[0], m.n_x if self.with_x0 else 0)
        if pattern.nnz() > MAX_AUGMENTED:
            return None, pattern
        S = ca.SX.sym("S", pattern)
        Sn = ca.project(ca.mtimes(f_x, S) + direct[0], S.sparsity())  # no entry outside the pattern moves
        dy = ca.mtimes(ca.jacobian(y, x), S) + direct[1]
        inputs, outputs = [ca.vertcat(x, *S.nonzeros()), u, p], [ca.vertcat(xn, *Sn.nonzeros()), ca.vertcat(y, dy.T)]
        return ca.Function("sensitivity_step", inputs, _shared(outputs)), pattern  # compiled by chunks (_chunked)

    def plain(self, n: int) -> ca.Function:
        """``(x0, u[1 x n], p) -> (x, y)``: the rollout alone, for the line search's costs."""
        return plain_rollout(self.model, n, self.jit)  # cached there, by structure and length

    def __call__(self, n: int) -> ca.Function:
        if n not in self._cache:
            self._cache[n] = self._build(n)
        return self._cache[n]

    def _build(self, n: int) -> ca.Function:
        m = self.model
        x0, u, p = ca.MX.sym("x0", m.n_x), ca.MX.sym("u", 1, n), ca.MX.sym("p", m.n_p)
        if self.augmented:
            seed = ca.DM(self._pattern, 0)  # the sensitivities at the start, on their pattern
            if self.with_x0:
                for i in range(m.n_x):
                    seed[i, len(self.idx) + i] = 1.0
            start = ca.vertcat(x0, *seed.nonzeros())
            if self.jit:
                _, out = _chunked(self._step, n, start, u, p, states=False)
            else:
                _, out = self._step.mapaccum("sensitivity_rollout", n)(start, u, ca.repmat(p, 1, n))
            y, dy = out[0, :], out[1:, :]
        else:
            _, y = m.rollout(n)(x0, u, p)
            parts = [ca.jacobian(y.T, p)[:, self.idx]]
            if self.with_x0:
                parts.append(ca.jacobian(y.T, x0))
            dy = ca.horzcat(*parts).T
        return ca.Function("sensitivity_rollout", [x0, u, p], [y, dy],
                           ["x0", "u", "p"], ["y", "dy"])


def _reachable(f_x, f_p, seeded: int = 0) -> ca.Sparsity:
    """The entries of the state's sensitivities that can be nonzero: those of ``f_p`` and of the initial
    seed (the identity over the last ``seeded`` columns: x0's), spread through ``f_x`` until nothing new
    is reached. Only these are propagated: a play's state does not move with the weights that read it,
    and the others stay exactly zero, so the same numbers come out with a half to a fifth of the work
    (lag+gpi+poly+linear: 16 of 84 entries, its rollout with sensitivities 1.5 times as fast)."""
    reach = np.array(ca.DM(f_p.sparsity(), 1), dtype=bool)
    if seeded:
        reach[:, reach.shape[1] - seeded:] |= np.eye(seeded, dtype=bool)
    moves = np.array(ca.DM(f_x.sparsity(), 1), dtype=int)
    while True:
        grown = reach | (moves @ reach > 0)
        if np.array_equal(grown, reach):
            break
        reach = grown
    rows, cols = np.nonzero(reach)
    return ca.Sparsity.triplet(*reach.shape, rows.tolist(), cols.tolist())
