"""The least-squares NLP behind :func:`identify`: single shooting, Gauss-Newton, IPOPT.

Decision variables ``w`` are the free parameters divided by their typical
magnitudes (so IPOPT sees O(1) numbers), then, with ``x0="estimate"``, each
trajectory's initial state divided by its magnitude. The objective is the mean
squared output error divided by the output variance, so it starts near 1 for a
poor model and ends near (noise / spread)^2 whatever the units and the amount
of data. IPOPT gets the Gauss-Newton Hessian ``2 J^T J`` (``hess_lag``) and the
gradient ``2 J^T r`` (``grad_f``) from forward sensitivities: ten times cheaper
per iteration than CasADi's exact Hessian through the rollout, and it converges
in as few iterations on these small-residual problems.
"""

from __future__ import annotations

import copy
import time
from dataclasses import dataclass
from typing import NamedTuple

import casadi as ca
import numpy as np

from physics import Series
from physics.data.io import stop_callback

from ._checks import Record
from ._sensitivity import sensitivity_rollouts

SUCCESS = ("Solve_Succeeded", "Solved_To_Acceptable_Level", "Objective_Stalled")
#: A solve ends ``Objective_Stalled`` (a success) once its best objective has dropped by no more than
#: ``STALL_RTOL`` of itself over ``STALL_WINDOW`` iterations: it is crawling through the rounding
#: noise of a long rollout's sums, where IPOPT's own tolerances may never be met (the Bouc-Wen
#: benchmark's oscillator fits spent 100 of their 150 iterations there, minutes each fit).
STALL_WINDOW, STALL_RTOL = 10, 1e-6


@dataclass
class Solve:
    """One IPOPT run."""

    w: np.ndarray
    cost: float
    status: str
    success: bool
    iterations: int
    wall_time_s: float


def _split(model: Series, vec, kind: str) -> list:
    sizes = [b.n_p if kind == "p" else b.n_x for b in model.blocks]
    offsets = np.cumsum([0] + sizes)
    return [vec[offsets[i]:offsets[i + 1]] for i in range(len(sizes))]


_NEEDS_NUMBER = (TypeError, RuntimeError, NotImplementedError, ValueError)


def steady_function(model: Series) -> ca.Function | None:
    """``steady(u0, p) -> x0`` built once, or None when a block needs a numeric input."""
    u0, p = ca.SX.sym("u0"), ca.SX.sym("p", model.n_p)
    parts, signal = [], u0
    try:
        for b, pb in zip(model.blocks, _split(model, p, "p")):
            xb = ca.SX(b.steady_state(signal, pb)) if b.n_x else ca.SX(0, 1)
            parts.append(xb)
            _, signal = b.step(xb, signal, pb, model.dt)
    except _NEEDS_NUMBER:
        return None
    return ca.Function("steady", [u0, p], [ca.vertcat(*parts) if parts else ca.SX(0, 1)])


def initial_state_exprs(model: Series, u0s, P, p_num: np.ndarray) -> list:
    """Steady states at each first input ``u0s`` as expressions of the parameters ``P``."""
    f = steady_function(model)
    if f is not None:
        return [f(float(u0), P) for u0 in u0s]
    return [steady_expr(model, u0, P, p_num) for u0 in u0s]


def steady_expr(model: Series, u0: float, P, p_num: np.ndarray):
    """Steady state at ``u0`` as an expression of the parameters ``P``.

    Blocks whose steady state needs a number (Preisach's relays) get the
    value at ``p_num``: their state then does not follow the parameters.
    """
    parts, signal = [], float(u0)
    for i, (b, pb) in enumerate(zip(model.blocks, _split(model, P, "p"))):
        try:
            xb = ca.MX(b.steady_state(signal, pb)) if b.n_x else ca.MX(0, 1)
        except _NEEDS_NUMBER:
            xb = ca.MX(ca.DM(_split(model, model.steady_state(u0, p_num), "x")[i]))
        parts.append(xb)
        _, signal = b.step(xb, signal, pb, model.dt)
    return ca.vertcat(*parts) if parts else ca.MX(0, 1)


#: Warm-up windows of at most this many samples are differentiated through the expanded window fit
#: (:func:`physics._warmup.init_function`, ``expanded=True``); longer ones through the function as written.
EXPANDED_WINDOW = 32


class WarmStart(NamedTuple):
    """Initial states from measured windows: per run ``(u_w, y_w, s_x, s_y)``, the window before the
    samples fitted and the scales of its state fit (:func:`physics._warmup.scales`). Each run's state
    is the window fit's (:meth:`Series.estimate_state`) as a function of the parameters, the rule every
    model is scored and predicted with."""

    windows: list


class LeastSquaresProblem:
    """Output-error least squares over one or many trajectories (single shooting)."""

    def __init__(self, model: Series, records: list[Record], free: np.ndarray,
                 p_base: np.ndarray, scale: np.ndarray, x0, jit: bool | None = None, bounds=None,
                 state_scale=None, shift: np.ndarray | None = None):
        self.model, self.records = model, records
        self.free = np.asarray(free, dtype=bool)
        self.p_base = np.asarray(p_base, dtype=float)
        # p = shift + scale * w: a location (an offset of 30 mm that moves by micrometres) is
        # solved for as its distance from ``shift`` in units of ``scale``
        self.scale = np.asarray(scale, dtype=float)
        self.shift = np.zeros(model.n_p) if shift is None else np.asarray(shift, dtype=float)
        self.lower, self.upper = bounds if bounds is not None else (model.lower_bounds, model.upper_bounds)
        self.state_scale = np.ones(model.n_x) if state_scale is None else np.asarray(state_scale, dtype=float)
        self.n_free = int(self.free.sum())
        self.estimate_x0 = isinstance(x0, str) and x0 == "estimate"
        nx = model.n_x
        self.n_w = self.n_free + (len(records) * nx if self.estimate_x0 else 0)
        self.n_samples = sum(r.n for r in records)
        spread = np.concatenate([r.y for r in records])
        self.output_scale = float(np.std(spread)) or 1.0
        self.weight = 1.0 / (self.n_samples * self.output_scale**2)

        w = ca.MX.sym("w", self.n_w)
        self.w = w
        free_idx = np.flatnonzero(self.free)
        entries = [ca.MX(float(v)) for v in self.p_base]
        for j, k in enumerate(free_idx):
            entries[k] = self.shift[k] + w[j] * self.scale[k]
        self.P = ca.vertcat(*entries) if entries else ca.MX(0, 1)
        self.x0_scale = np.ones((len(records), nx))
        self.x0_exprs = self._initial_states(x0, w)

        with_x0 = self.estimate_x0 or any(ca.depends_on(e, w) for e in self.x0_exprs if e.numel())
        self.kernels = sensitivity_rollouts(model, self.free, with_x0, jit)
        self._solvers: dict[tuple, ca.Function] = {}
        self._build(w)

    # -- construction ---------------------------------------------------------
    def _initial_states(self, x0, w) -> list:
        m, nx = self.model, self.model.n_x
        if isinstance(x0, np.ndarray):
            return [ca.MX(ca.DM(row)) for row in x0]
        if isinstance(x0, WarmStart):  # the state after each run's window, a function of the parameters
            from physics._warmup import init_function

            # expanded for short windows: the fit differentiates it at every iterate (its Jacobian in a
            # third of the time); its scalar graph grows about 3 MB a sample (200 samples: 0.7 GB)
            return [init_function(m, u_w.size, False, expanded=u_w.size <= EXPANDED_WINDOW)(
                        ca.DM(u_w[None, :]), ca.DM(y_w[None, :]), self.P, ca.DM(s_x), s_y)[0]
                    for u_w, y_w, s_x, s_y in x0.windows]
        if not self.estimate_x0:
            u0s = [r.u[0] for r in self.records]
            return self._constant_if_flat(initial_state_exprs(m, u0s, self.P, self.p_base), w)
        out = []
        for i, r in enumerate(self.records):
            guess = m.steady_state(r.u[0], self.p_base)
            self.x0_scale[i] = np.maximum(np.abs(guess), self.state_scale)
            start = self.n_free + i * nx
            out.append(w[start:start + nx] * ca.DM(self.x0_scale[i]))
        return out

    def _constant_if_flat(self, exprs, w) -> list:
        """Replace steady states that do not move with the parameters by numbers.

        A lag's steady output is its input whatever its time constant, but the
        expression still mentions the time constant; carrying it would double
        the sensitivity work for nothing.
        """
        if not exprs or self.n_w == 0:
            return [ca.MX(ca.evalf(ca.substitute(e, w, ca.DM.zeros(self.n_w)))) if e.numel()
                    else e for e in exprs]
        x = ca.vertcat(*exprs)
        jac = ca.Function("steady_jacobian", [w], [ca.jacobian(x, w), x])
        w0 = self.scaled(self.p_base)
        rng = np.random.default_rng(0)
        flat = True
        for trial in (w0, w0 * (1 + 0.3 * rng.standard_normal(w0.size))):
            J, _ = jac(trial)
            flat &= bool(np.all(np.abs(np.asarray(J)) < 1e-10))
        if not flat:
            return exprs
        _, values = jac(w0)
        values = np.asarray(values, dtype=float).ravel()
        nx = self.model.n_x
        return [ca.MX(ca.DM(values[i * nx:(i + 1) * nx])) for i in range(len(exprs))]

    def _build(self, w) -> None:
        nf, res, jacs, preds = self.n_free, [], [], []
        for r, x0 in zip(self.records, self.x0_exprs):
            y, dy = self.kernels(r.n)(x0, ca.DM(r.u[None, :]), self.P)
            ri = (y - ca.DM(r.y[None, :])).T
            Ji = ca.mtimes(dy[:nf, :].T, ca.diag(ca.DM(self.scale[self.free])))
            if self.n_w > nf:
                Ji = ca.horzcat(Ji, ca.MX(r.n, self.n_w - nf))
            if self.kernels.with_x0:
                Ji = Ji + ca.mtimes(dy[nf:, :].T, ca.jacobian(x0, w))
            res.append(ri)
            jacs.append(Ji)
            preds.append(y.T)
        r_all, J_all = ca.vertcat(*res), ca.vertcat(*jacs)
        c = self.weight
        cons = self.model.constraints(self.P)
        self.g = ca.vertcat(*[e for e, _, _ in cons]) if cons else ca.MX(0, 1)
        self.lbg = np.array([lo for _, lo, _ in cons], dtype=float)
        self.ubg = np.array([hi for _, _, hi in cons], dtype=float)
        self.f_plain = self._plain_cost(w)
        self.residuals = ca.Function("residuals", [w], [r_all, J_all], ["w"], ["r", "J"])
        point = _LastPoint(self.residuals)
        self.grad_f = _gradient(point, c, self.n_w)
        self.hess_lag = _gauss_newton_hessian(point, c, self.n_w, int(self.g.numel()))
        self.predict = ca.Function("predict", [w], preds)
        self.g_jac = ca.Function("g_jac", [w], [ca.jacobian(self.g, w)])
        self._cost = ca.Function("cost", [w], [self.f_plain])

    def _plain_cost(self, w):
        """The objective through plain rollouts: cheap, for IPOPT's line search."""
        total, cache = 0, {}
        for r, x0 in zip(self.records, self.x0_exprs):
            if r.n not in cache:
                cache[r.n] = self.kernels.plain(r.n)
            _, y = cache[r.n](x0, ca.DM(r.u[None, :]), self.P)
            total = total + ca.sumsqr(y - ca.DM(r.y[None, :]))
        return self.weight * total

    def fork(self) -> "LeastSquaresProblem":
        """This problem for another thread: its own Jacobian buffers and IPOPT instances, the compiled
        rollouts shared (CasADi releases the GIL while they run), so starts can be solved at once."""
        twin = copy.copy(self)
        point = _LastPoint(self.residuals)
        twin.grad_f = _gradient(point, self.weight, self.n_w)
        twin.hess_lag = _gauss_newton_hessian(point, self.weight, self.n_w, int(self.g.numel()))
        twin._solvers = {}
        return twin

    # -- conversion -------------------------------------------------------------
    def scaled(self, p: np.ndarray, x0s=None) -> np.ndarray:
        """Decision vector from full parameters (and initial states when estimated)."""
        w = (np.asarray(p, dtype=float)[self.free] - self.shift[self.free]) / self.scale[self.free]
        if self.estimate_x0:
            if x0s is None:
                x0s = [self.model.steady_state(r.u[0], p) for r in self.records]
            w = np.concatenate([w] + [np.asarray(x, float) / s for x, s in zip(x0s, self.x0_scale)])
        return w

    def params(self, w: np.ndarray) -> np.ndarray:
        p = self.p_base.copy()
        p[self.free] = self.shift[self.free] + np.asarray(w, dtype=float)[: self.n_free] * self.scale[self.free]
        return p

    def initial_states(self, w: np.ndarray) -> list[np.ndarray]:
        f = ca.Function("x0s", [self.w], self.x0_exprs) if self.x0_exprs else None
        outs = f(w) if f is not None else []
        outs = [outs] if isinstance(outs, ca.DM) else outs
        return [np.asarray(o, dtype=float).ravel() for o in outs]

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        lo = np.full(self.n_w, -np.inf)
        hi = np.full(self.n_w, np.inf)
        s, c = self.scale[self.free], self.shift[self.free]
        lo[: self.n_free] = (self.lower[self.free] - c) / s
        hi[: self.n_free] = (self.upper[self.free] - c) / s
        return lo, hi

    # -- solving ------------------------------------------------------------------
    def solver(self, max_wall_time: float | None, verbose: bool = False, options: dict | None = None):
        """IPOPT on this problem; built once per setting without a wall-time limit (a start and the
        multi-start's probes share it: building costs about a tenth of a solve)."""
        key = None if max_wall_time is not None else (bool(verbose), repr(sorted((options or {}).items())))
        if key is not None and key in self._solvers:
            return self._solvers[key]
        solver = self._new_solver(max_wall_time, verbose, options)
        if key is not None:
            self._solvers[key] = solver
        return solver

    def _new_solver(self, max_wall_time: float | None, verbose: bool, options: dict | None):
        opts = {
            "ipopt.print_level": 5 if verbose else 0,
            "ipopt.sb": "yes",
            "ipopt.mu_init": 1e-4,
            # stop when stalled at the optimum: smoothed |z| makes the last digits noisy
            "ipopt.acceptable_tol": 1e-5,
            "ipopt.acceptable_iter": 5,
            "ipopt.acceptable_obj_change_tol": 1e-10,
            "print_time": bool(verbose),
            "error_on_fail": False,
            "calc_lam_p": False,  # no NLP parameters; on a compiled rollout it took 3 of 4 s to build
            # nor their gradient (reverse mode through every rollout; half a fold fit's set-up): IPOPT
            # gets grad_f and the multipliers of the bounds itself
            "no_nlp_grad": True,
            "show_eval_warnings": bool(verbose),
            "grad_f": self.grad_f,
            "hess_lag": self.hess_lag,
        }
        if max_wall_time is not None:
            opts["ipopt.max_wall_time"] = float(max_wall_time)
        for key, value in (options or {}).items():
            opts[key if "." in key else f"ipopt.{key}"] = value
        stop = stop_callback(self.n_w, int(self.g.numel()), stall=(STALL_WINDOW, STALL_RTOL))
        opts["iteration_callback"] = stop
        nlp = {"x": self.w, "f": self.f_plain, "g": self.g}
        solver = ca.nlpsol("identify", "ipopt", nlp, opts)
        solver.stop = stop  # kept alive with the solver
        return solver

    def solve(self, solver, w0: np.ndarray) -> Solve:
        lo, hi = self.bounds()
        w0 = np.clip(np.asarray(w0, dtype=float), lo, hi)
        t0 = time.perf_counter()
        solver.stop.reset()
        out = solver(x0=w0, lbx=lo, ubx=hi, lbg=self.lbg, ubg=self.ubg)
        wall = time.perf_counter() - t0
        stats = solver.stats()
        status = str(stats.get("return_status", "unknown"))
        if status == "User_Requested_Stop" and solver.stop.stalled:
            status = "Objective_Stalled"
        w = np.asarray(out["x"], dtype=float).ravel()
        cost = float(out["f"])
        ok = status in SUCCESS and np.isfinite(cost)
        return Solve(w, cost, status, ok, int(stats.get("iter_count", -1)), wall)

    def cost(self, w: np.ndarray) -> float:
        return float(self._cost(w))


class _LastPoint:
    """``r`` and ``J`` at the last ``w`` asked for. IPOPT asks for the gradient and then the
    Hessian at each iterate; both are products of ``J``, whose rollout with sensitivities is most
    of a fit's time, so it runs once per iterate. It is evaluated into numpy arrays bound to the
    function once (``Function.buffer``): the same numbers as a call, without building a ``DM`` of
    ``J`` and converting it, which cost as much as the rollout of a short fold."""

    def __init__(self, residuals: ca.Function):
        dense = ca.Function("residuals_dense", [residuals.mx_in(0)],
                            [ca.densify(e) for e in residuals(residuals.mx_in(0))])
        self.shapes = [dense.size_out(i) for i in range(dense.n_out())]
        self._w = np.zeros(dense.nnz_in(0))
        self._out = [np.zeros(rows * cols) for rows, cols in self.shapes]
        self._buffer, self._run = dense.buffer()
        self._buffer.set_arg(0, memoryview(self._w))
        for i, out in enumerate(self._out):
            self._buffer.set_res(i, memoryview(out))
        self.w, self.rJ = None, None

    def __call__(self, w) -> tuple[np.ndarray, np.ndarray]:
        w = np.asarray(w, dtype=float).ravel()
        if self.w is None or not np.array_equal(w, self.w):
            self._w[:] = w
            self._run()
            if self._buffer.ret():
                raise RuntimeError(f"Evaluating the residuals and their Jacobian failed (code {self._buffer.ret()}).")
            # column-major nonzeros -> (rows, cols) arrays of their own
            self.rJ = tuple(out.reshape(cols, rows).T.copy() for out, (rows, cols) in zip(self._out, self.shapes))
            self.w = w.copy()
        return self.rJ


class _NumpyFunction(ca.Callback):
    """A CasADi function of dense inputs computed in numpy: ``fn(*inputs) -> outputs``."""

    def __init__(self, name: str, inputs: dict[str, int], outputs: dict[str, ca.Sparsity], fn):
        ca.Callback.__init__(self)
        self.inputs, self.outputs, self.fn = list(inputs.items()), list(outputs.items()), fn
        self.construct(name, {})

    def get_n_in(self):
        return len(self.inputs)

    def get_n_out(self):
        return len(self.outputs)

    def get_name_in(self, i):
        return self.inputs[i][0]

    def get_name_out(self, i):
        return self.outputs[i][0]

    def get_sparsity_in(self, i):
        return ca.Sparsity.dense(self.inputs[i][1], 1)

    def get_sparsity_out(self, i):
        return self.outputs[i][1]

    def eval(self, arg):
        return [ca.DM(v) for v in self.fn(*arg)]


def _gradient(point: _LastPoint, weight: float, n_w: int) -> ca.Function:
    """IPOPT's ``grad_f``: ``(f, 2 c J^T r)``."""

    def fn(x, p):
        r, J = point(x)
        r = r.ravel()
        with np.errstate(over="ignore", invalid="ignore"):  # a trial step gone far: inf, which IPOPT rejects
            return weight * float(r @ r), 2 * weight * (J.T @ r)

    return _NumpyFunction("grad_f", {"x": n_w, "p": 0},
                          {"f": ca.Sparsity.dense(1, 1), "grad_f_x": ca.Sparsity.dense(n_w, 1)}, fn)


def _gauss_newton_hessian(point: _LastPoint, weight: float, n_w: int, n_g: int) -> ca.Function:
    """IPOPT's ``hess_lag``: the upper triangle of ``lam_f 2 c J^T J``."""

    def fn(x, p, lam_f, lam_g):
        _, J = point(x)
        with np.errstate(over="ignore", invalid="ignore"):
            return (ca.triu(ca.DM(float(lam_f) * 2 * weight * (J.T @ J))),)

    return _NumpyFunction("hess_lag", {"x": n_w, "p": 0, "lam_f": 1, "lam_g": n_g},
                          {"hess_gamma_x_x": ca.Sparsity.upper(n_w)}, fn)
