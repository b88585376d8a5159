"""Adjoint-based SQP for the tracking MPC: the exact cost gradient, a Hessian from a cheap model.

The MPC's problem, condensed onto the inputs ``U`` of the horizon (single shooting)::

    min_U  f(U) = w_track |Y(U) - r|^2 + w_du |dU|^2 + w_u |U - u_ref|^2,   dU_k = U_k - U_{k-1}
    s.t.   lo <= U_k <= hi,  |dU_k| <= du_max                               (U_{-1} = u_prev)

Each iteration solves the dense QP ``min_d 1/2 d'Hd + g'd`` (same bounds on ``U + d``)
with ``g = grad f(U)`` from one reverse sweep through the full model (exact, about
three model rollouts) and the Gauss-Newton Hessian ``H = 2 (w_track J'J + w_du D'D
+ w_u I)``, where ``J = dY/dU`` comes from an *approximate* model: for a hybrid its
physics part, whose Jacobian costs microseconds where an LSTM's costs a rollout per
input. A backtracking line search on ``f`` keeps every step a descent step, and
since ``g`` is exact a fixed point is a KKT point of the full model's problem; the
approximation only sets how fast the iterates get there (the adjoint-based SQP
with inexact Jacobians of Bock, Diehl et al.). Cost, gradient and Jacobian are
generated as C and compiled with gcc when it is there.
"""

from __future__ import annotations

import hashlib

import casadi as ca
import numpy as np

from hybrid.export._codegen import cached_build, codegen, has_compiler, load_compiled
from hybrid.export import ExportError

from ._mpc_problem import MPCProblem
from ._mpc_solver import MPCSolution, MPCSolver, register_solver

__all__ = ["AdjointSQP", "AdjointSQPSolver", "ADJOINT_TOL"]

#: The adjoint SQP's default step tolerance, as a share of the input bounds' span
#: (1 um on the catheter's 6 mm would be 1/6000; this is 1e-3 mm on 6 mm).
ADJOINT_TOL = 1e-3 / 6

#: The dense QP solver and its options: DAQP (dual active set) solves the 25-input QP in
#: about 0.25 ms, as fast as qpOASES and 15 times faster than ``qrqp``, which also
#: fails on degenerate active sets (bound and rate limit active at once).
QP_SOLVER, QP_OPTIONS = "daqp", {"error_on_fail": False}

#: gcc flags of the solver's own library, built and used on this machine: native vector
#: instructions, and re-association so the adjoint's dot products vectorise (the
#: gradient changes in the last bits only). 2-3 times faster than plain ``-O3``.
JIT_FLAGS = ("-O3", "-march=native", "-fno-math-errno", "-fassociative-math", "-fno-signed-zeros",
             "-fno-trapping-math", "-fno-semantic-interposition", "-fPIC", "-shared")


def _compiled(functions: list[ca.Function]) -> list[ca.Function]:
    """The functions compiled into one library, cached by content in the temp folder
    (a second MPC on the same model loads it instead of calling gcc again)."""
    key = hashlib.sha1("".join(f.serialize() for f in functions).encode()).hexdigest()[:16]
    folder = cached_build(key, lambda scratch: codegen(functions, scratch, name="mpc", flags=JIT_FLAGS))
    return [load_compiled(folder / "libmpc.so", f.name()) for f in functions]


class AdjointSQP:
    """Solver of the condensed tracking problem (see the module docstring).

    Parameters
    ----------
    step, approximation : casadi.Function
        ``(x, u) -> (x_next, y)`` of the model and of its approximation, on the same state.
    horizon, u_bounds, du_max, w_track, w_du, w_u, u_ref
        As :class:`TrackingMPC`.
    max_iter : int
        SQP iterations per call (each one gradient, one Jacobian, one QP). Warm-started
        from the last solution, 1 is the real-time iteration scheme (about half the
        time, same tracking on the virtual catheter); 3 converges most solves.
    tol : float
        Stop when the step changes no input by more than this, in the step's input units
        (:class:`TrackingMPC` gives it the scaled problem: a share of the input bounds' span).
    compile : bool or None
        Compile cost, gradient and Jacobian with gcc (default: when gcc is on the PATH).
    """

    def __init__(self, step: ca.Function, approximation: ca.Function, horizon: int,
                 u_bounds: tuple[float, float], du_max: float, w_track: float, w_du: float, w_u: float,
                 u_ref: float, max_iter: int = 3, tol: float = 1e-3, compile: bool | None = None):
        N, nx = horizon, step.size1_in(0)
        self.horizon, self.u_bounds, self.du_max = N, u_bounds, du_max
        self.max_iter, self.tol = int(max_iter), float(tol)
        x0, U = ca.MX.sym("x0", nx), ca.MX.sym("U", 1, N)
        ref, u_prev = ca.MX.sym("ref", 1, N), ca.MX.sym("u_prev")
        _, Y = step.mapaccum("horizon", N)(x0, U)
        du = U - ca.horzcat(u_prev, U[:, :N - 1])
        f = w_track * ca.sumsqr(Y - ref) + w_du * ca.sumsqr(du) + w_u * ca.sumsqr(U - u_ref)
        _, Ya = approximation.mapaccum("approx", N)(x0, U)
        functions = [
            ca.Function("mpc_cost", [x0, U, ref, u_prev], [f]),
            ca.Function("mpc_cost_grad", [x0, U, ref, u_prev], [f, ca.gradient(f, U).T, Y]),
            ca.Function("mpc_jac", [x0, U], [ca.jacobian(Ya, U)]),
        ]
        self.compiled = has_compiler() if compile is None else bool(compile)
        if self.compiled:
            functions = _compiled(functions)
        self.cost_function, self._cost_grad, self._jac = functions
        D = np.eye(N) - np.eye(N, k=-1)  # dU = D U - e0 u_prev
        self._D, self._w_track = D, w_track
        self._H0 = 2 * (w_du * D.T @ D + w_u * np.eye(N))
        self._qp = ca.conic("mpc_qp", QP_SOLVER, {"h": ca.Sparsity.dense(N, N), "a": ca.Sparsity.dense(N, N)},
                            QP_OPTIONS)

    def solve(self, x0: np.ndarray, ref: np.ndarray, u_prev: float, U: np.ndarray):
        """Improve the input path ``U`` (a feasible guess); returns ``(U, iterations, converged)``."""
        lo, hi = self.u_bounds
        U = np.asarray(U, dtype=float).copy()
        e0 = np.zeros(self.horizon)
        e0[0] = u_prev
        for it in range(1, self.max_iter + 1):
            f, g, _ = self._cost_grad(x0, U, ref, u_prev)
            f, g = float(f), np.asarray(g, dtype=float).ravel()
            if not (np.isfinite(f) and np.all(np.isfinite(g))):
                raise ExportError(f"The MPC cost or its gradient is not finite at the inputs {np.round(U, 4).tolist()}; "
                                  "check the state passed to solve() and the model's range of validity.")
            J = np.asarray(self._jac(x0, U), dtype=float)
            du = self._D @ U - e0
            sol = self._qp(h=2 * self._w_track * J.T @ J + self._H0, g=g, a=self._D, lbx=lo - U, ubx=hi - U,
                           lba=-self.du_max - du, uba=self.du_max - du)
            d = np.asarray(sol["x"], dtype=float).ravel()
            if not self._qp.stats()["success"]:
                return U, it, False
            slope = float(g @ d)
            if np.max(np.abs(d)) <= self.tol or not slope < 0:  # no descent left: stationary
                return U, it, bool(np.all(np.isfinite(d)))
            alpha = 1.0  # Armijo backtracking; the bounds are convex, so U + alpha d stays feasible
            while self.cost(x0, U + alpha * d, ref, u_prev) > f + 1e-4 * alpha * slope:
                alpha *= 0.5
                if alpha < 1e-3:
                    return U, it, False
            U = U + alpha * d
            if alpha * np.max(np.abs(d)) <= self.tol:
                return U, it, True
        return U, self.max_iter, False

    def cost(self, x0, U, ref, u_prev) -> float:
        """The objective ``f(U)`` from state ``x0`` (the module docstring), in the step's units."""
        return float(self.cost_function(x0, U, ref, u_prev))

    def predicted_output(self, x0, U, ref, u_prev) -> np.ndarray:
        return np.asarray(self._cost_grad(x0, U, ref, u_prev)[2], dtype=float).ravel()


@register_solver
class AdjointSQPSolver(MPCSolver):
    """``solver="adjoint-sqp"``: :class:`AdjointSQP` on the MPC's scaled problem, inputs only.

    SQP on the inputs with the exact gradient (one adjoint sweep of the model) and a Gauss-Newton
    Hessian from the model's ``approximation`` (a hybrid's physics; else the model itself),
    compiled with gcc: what makes MPC on an LSTM hybrid real-time. Warm-started from the last
    solution shifted by a sample. Options: ``max_iter``, ``tol`` (in input units, default
    :data:`ADJOINT_TOL` of the bounds' span) and ``compile`` (see :class:`AdjointSQP`).
    """

    name, title = "adjoint-sqp", "adjoint SQP"
    output_bounds = measured_inputs = False

    def __init__(self, problem: MPCProblem, options=None):
        super().__init__(problem, options)
        lo, hi = problem.settings.u_bounds
        options = dict(options or {})
        unknown = sorted(set(options) - {"max_iter", "tol", "compile"})
        if unknown:
            raise ExportError(f"Unknown adjoint-sqp option(s) {unknown}; it takes 'max_iter', 'tol' and 'compile'.")
        options["tol"] = options.get("tol", ADJOINT_TOL * (hi - lo)) / (hi - lo)
        w_track, w_du, w_u, u_ref, du_max = problem.scaled
        self.sqp = AdjointSQP(problem.step_n, problem.approximation_n(), problem.horizon, (0.0, 1.0), du_max,
                              w_track, w_du, w_u, u_ref, **options)

    def solve(self, x, ref, u_prev, D, last, half_widths=None) -> MPCSolution:
        sc = self.problem.scale  # the solver sees the scaled problem
        x, ref, u_phys, u_prev = sc.x(x), sc.y(ref), float(u_prev), float(sc.u(u_prev))
        p = np.r_[x, u_prev, ref, D.ravel(order="F")]
        best = self._solve_from(x, ref, u_prev, self._start(u_prev, last))
        best = self._from_rest(best, x, ref, u_phys, u_prev, D, lambda U: self._solve_from(x, ref, u_prev, U))
        u = float(np.clip(sc.u_back(best.guess[0][0]), *self.problem.settings.u_bounds))
        return MPCSolution(best.guess, best.cost, best.iterations, best.success, u, p)

    def _start(self, u_prev: float, last: MPCSolution | None) -> np.ndarray:
        """Scaled inputs to start from (``u_prev`` scaled): the last solution shifted by a sample,
        if it is still feasible, else ``u_prev`` held."""
        U0 = np.full(self.problem.horizon, float(np.clip(u_prev, 0.0, 1.0)))
        if last is not None:
            shifted = np.r_[last.guess[0][1:], last.guess[0][-1]]
            if abs(shifted[0] - u_prev) <= self.problem.scaled[4]:
                U0 = shifted
        return U0

    def _solve_from(self, x, ref, u_prev: float, U0: np.ndarray) -> MPCSolution:
        U, iterations, converged = self.sqp.solve(x, ref, u_prev, U0)
        return MPCSolution((U,), self.sqp.cost(x, U, ref, u_prev), iterations, converged)

    def _cost(self, x, U, ref, u_prev, D) -> float:
        return self.sqp.cost(x, U, ref, u_prev)

    def predicted_output(self, solution: MPCSolution) -> np.ndarray:
        N, nx, p = self.problem.horizon, self.problem.n_x, solution.p
        return self.problem.scale.y_back(self.sqp.predicted_output(p[:nx], solution.guess[0], p[nx + 1:nx + 1 + N], p[nx]))
