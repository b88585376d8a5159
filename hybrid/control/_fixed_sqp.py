"""A control step of bounded cost: a fixed number of SQP iterations, as one pure CasADi function.

The tracking problem of :class:`~hybrid.control.TrackingMPC`, condensed onto the horizon's
inputs (single shooting, the scaled problem of :class:`~hybrid.control._scaling.Scaling`), is
solved from a warm start (the last solution shifted by a sample) by exactly ``iterations``
SQP iterations: each one rolls the model out once, takes the output Jacobian of its
``approximation`` (a hybrid's physics; else the model itself) for a Gauss-Newton Hessian and
gradient (or the exact gradient by a reverse sweep, ``gradient="exact"``), solves the dense QP
under the input and rate bounds by a fixed number of ADMM iterations (OSQP's algorithm), and takes
the first of the step lengths 1, 1/2, 1/4, 1/8 (each moved into the bounds) that lowers the cost,
or none (a backtracking line search of at most four evaluations). With one iteration this is the
real-time iteration scheme; a control step costs at most the same on every sample.

Everything (the scaling, the warm start made feasible, the iterations, the QP's ADMM) is one
``Function('control', [x, u_prev, ref, U_guess], [u, U, step])`` in physical units, so the same
function runs in Python (compiled with gcc where it is there) and, generated as C, in a robot's
control loop with no Python, torch or CasADi runtime (:func:`write_controller`).
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from hybrid.export._codegen import has_compiler
from hybrid.export._model import ExportError

from ._adjoint_sqp import ADJOINT_TOL, _compiled
from ._mpc_problem import MPCProblem
from ._mpc_solver import MPCSolution, MPCSolver, register_solver
from ._static import rest_output

__all__ = ["fixed_sqp_function", "FixedSQPSolver", "STEP_LENGTHS", "ADMM_ITERATIONS", "FIXED_ITERATIONS"]

#: SQP iterations per control step of the ``"fixed-sqp"`` solver (warm-started from the last solution):
#: 1 is the real-time iteration; a hybrid whose network carries much of the output may need 2-3.
FIXED_ITERATIONS = 1

#: Step lengths tried in turn on the QP's direction each iteration (backtracking: the first that lowers the
#: cost is taken, the next only evaluated when it did not); none: the iterate is kept (never worse).
STEP_LENGTHS = (1.0, 0.5, 0.25, 0.125)
#: Iterations of the QP's ADMM (OSQP's algorithm, written out in CasADi: code-generated with the rest).
ADMM_ITERATIONS = 40
#: Levenberg term added to the Hessian's diagonal (scaled units): a flat model region (a
#: backlash's dead band, dy/du = 0) with no rate or level weight still gives a bounded step.
REGULARISATION = 1e-8


def fixed_sqp_function(step_n: ca.Function, approx_n: ca.Function, scaling, horizon: int, weights: tuple,
                       iterations: int, rest: tuple[np.ndarray, np.ndarray] | None = None,
                       gradient: str = "gauss-newton") -> ca.Function:
    """``control(x, u_prev, ref, U_guess) -> (u, U, step)`` in physical units.

    ``step_n`` and ``approx_n`` are the model and its approximation on the scaled problem
    (``scaling.wrap``), ``weights`` the scaled ``(w_track, w_du, w_u, u_ref, du_max)``; ``U`` is the
    solution (the next call's guess, shifted), ``step`` the largest input change of the last
    iteration in the scaled inputs (0 to 1 over the bounds): a converged solve takes ~0 there.

    ``rest``: the model's rest output on a grid of inputs ``(u, y)``, physical units. With it the
    iterations start from the cheaper of the warm start and the inputs heading (within the rate
    limit) to those whose rest outputs are the reference: in a flat region (a backlash's dead band,
    dy/du = 0) a gradient step from the warm start would not move.

    ``gradient``: ``"gauss-newton"`` (default: ``2 J'(Y - ref)`` plus the rate and level terms,
    with the model's outputs ``Y`` and the Jacobian ``J`` the Hessian uses: the exact gradient when
    ``J`` is the model's own, a physics model's; for a hybrid it leaves out the network's share of
    dy/du, and costs one rollout of the model instead of a reverse sweep of about three) or
    ``"exact"`` (the reverse sweep: a fixed point then solves the hybrid's own problem).
    """
    if gradient not in ("exact", "gauss-newton"):
        raise ValueError(f"gradient must be 'exact' or 'gauss-newton'; got {gradient!r}.")
    N, nx = int(horizon), int(step_n.size1_in(0))
    w_track, w_du, w_u, u_ref, du_max = (float(v) for v in weights)
    sc = scaling
    x, u_prev = ca.MX.sym("x", nx), ca.MX.sym("u_prev")
    ref, guess = ca.MX.sym("ref", N), ca.MX.sym("U_guess", N)
    # scaled: state, previous input, reference, guess
    xi = (x - ca.DM(sc.x_mid)) / ca.DM(sc.x_span)
    v_prev = (u_prev - sc.u_lo) / sc.u_span
    eta = (ref - sc.y_mid) / sc.y_span
    V = (guess - sc.u_lo) / sc.u_span

    # cost, exact gradient, and the approximation's output Jacobian, as functions of (x, U, ref, u_prev)
    x0s, Us, refs, ups = ca.MX.sym("x0", nx), ca.MX.sym("U", N), ca.MX.sym("ref", N), ca.MX.sym("u_prev")
    _, Y = step_n.mapaccum("horizon", N)(x0s, Us.T)
    du = Us - ca.vertcat(ups, Us[:N - 1])
    f = w_track * ca.sumsqr(Y.T - refs) + w_du * ca.sumsqr(du) + w_u * ca.sumsqr(Us - u_ref)
    cost = ca.Function("cost", [x0s, Us, refs, ups], [f])
    cost_grad = ca.Function("cost_grad", [x0s, Us, refs, ups], [f, ca.gradient(f, Us)])
    cost_outputs = ca.Function("cost_outputs", [x0s, Us, refs, ups], [f, Y.T])
    _, Ya = approx_n.mapaccum("approx", N)(x0s, Us.T)
    jac = ca.Function("output_jacobian", [x0s, Us], [ca.jacobian(Ya.T, Us)])
    fa = w_track * ca.sumsqr(Ya.T - refs) + w_du * ca.sumsqr(du) + w_u * ca.sumsqr(Us - u_ref)
    approx_cost = ca.Function("approx_cost", [x0s, Us, refs, ups], [fa])

    D = np.eye(N) - np.eye(N, k=-1)  # dU = D U - e0 u_prev
    H0 = ca.DM(2 * (w_du * D.T @ D + w_u * np.eye(N)) + REGULARISATION * np.eye(N))
    e0 = ca.DM(np.eye(N)[:, 0])
    feasible = _feasible_function(N, du_max)
    admm = _admm_function(D)
    # one SQP iteration as a function of its own: the generated C holds its code once, whatever the count
    Vs, xis, etas, vps = ca.MX.sym("V", N), ca.MX.sym("xi", nx), ca.MX.sym("eta", N), ca.MX.sym("v_prev")
    J = jac(xis, Vs)
    if gradient == "exact":
        f0, g = cost_grad(xis, Vs, etas, vps)
    else:
        f0, Yv = cost_outputs(xis, Vs, etas, vps)
        dv = Vs - ca.vertcat(vps, Vs[:N - 1])
        g = 2 * w_track * (J.T @ (Yv - etas)) + 2 * w_du * (ca.DM(D).T @ dv) + 2 * w_u * (Vs - u_ref)
    rate = ca.DM(D) @ Vs - e0 * vps
    d = admm(H0 + 2 * w_track * (J.T @ J), g, ca.vertcat(-Vs, -du_max - rate), ca.vertcat(1 - Vs, du_max - rate))
    best_v = Vs  # backtracking: the first step length that lowers the cost; a shorter one is only
    for a in STEP_LENGTHS[::-1]:  # evaluated when the longer failed (short-circuit branches)
        trial = feasible(Vs + a * d, vps)
        best_v = ca.if_else(cost(xis, trial, etas, vps) < f0, trial, best_v, True)
    iteration = ca.Function("sqp_iteration", [Vs, xis, etas, vps], [best_v, ca.mmax(ca.fabs(best_v - Vs))])

    V, last = feasible(V, v_prev), ca.MX(0)  # the guess within the bounds and the rate limit from u_prev
    if rest is not None:
        u_grid, y_grid = (np.asarray(v, dtype=float).ravel() for v in rest)
        order = np.argsort(y_grid, kind="stable")
        y_sorted, keep = np.unique(y_grid[order], return_index=True)  # strictly increasing for the lookup
        if y_sorted.size >= 2:
            inverse = ca.interpolant("rest_inverse", "linear", [y_sorted], u_grid[order][keep])
            target = (inverse(ca.fmin(ca.fmax(ref.T, y_sorted[0]), y_sorted[-1])).T - sc.u_lo) / sc.u_span
            static = feasible(target, v_prev)
            # compared on the approximation: a hybrid's physics costs microseconds where its network costs a rollout
            V = ca.if_else(approx_cost(xi, static, eta, v_prev) < approx_cost(xi, V, eta, v_prev), static, V)
    for _ in range(int(iterations)):
        V, last = iteration(V, xi, eta, v_prev)
    U = sc.u_lo + sc.u_span * V
    return ca.Function("control", [x, u_prev, ref, guess], [U[0], U, last],
                       ["x", "u_prev", "ref", "U_guess"], ["u", "U", "step"])


@register_solver
class FixedSQPSolver(MPCSolver):
    """``solver="fixed-sqp"``: a fixed number of SQP iterations per control step, warm-started from the
    last solution, as one pure CasADi function (:attr:`control_function`, :func:`fixed_sqp_function`)
    that runs compiled and is generated as a C controller by ``hyst export --controller``
    (:func:`~hybrid.control.write_controller`): the same cost on every sample.

    Options: ``iterations`` (default :data:`FIXED_ITERATIONS`: the real-time iteration),
    ``gradient`` (``"gauss-newton"``, default, or ``"exact"``: a reverse sweep of a hybrid instead of
    its physics' Gauss-Newton gradient) and ``compile`` (gcc; default: when it is there). A solve
    succeeds when its last iteration moved no input by more than :data:`ADJOINT_TOL` (scaled).
    """

    name, title = "fixed-sqp", "fixed-iteration SQP"
    iterations_option = "iterations"
    output_bounds = measured_inputs = False

    def __init__(self, problem: MPCProblem, options=None):
        super().__init__(problem, options)
        options = dict(options or {})
        iterations = options.pop("iterations", FIXED_ITERATIONS)
        compile_ = options.pop("compile", None)
        gradient = options.pop("gradient", "gauss-newton")
        if options:
            raise ExportError(f"Unknown fixed-sqp option(s) {sorted(options)}; it takes 'iterations', 'gradient' "
                              "and 'compile'.")
        if gradient not in ("exact", "gauss-newton"):
            raise ExportError(f"The fixed-sqp gradient must be 'exact' or 'gauss-newton'. Got {gradient!r}.")
        if isinstance(iterations, bool) or int(iterations) != iterations or iterations < 1:
            raise ExportError(f"The fixed-sqp iterations must be a whole number >= 1. Got {iterations!r}.")
        #: SQP iterations per control step.
        self.iterations = int(iterations)
        model, rest = problem.model, None
        if model is not None:  # the rest outputs across the bounds: a start off a flat region
            u_grid = np.linspace(*problem.settings.u_bounds, 201)
            rest = (u_grid, np.array([rest_output(model, v) for v in u_grid]))
        #: ``control(x, u_prev, ref, U_guess) -> (u, U, step)`` in physical units.
        self.control_function = fixed_sqp_function(problem.step_n, problem.approximation_n(), problem.scale,
                                                   problem.horizon, problem.scaled, self.iterations, rest, gradient)
        compile_ = has_compiler() if compile_ is None else bool(compile_)
        #: :attr:`control_function` as it runs here (compiled with gcc where asked).
        self.control = _compiled([self.control_function])[0] if compile_ else self.control_function
        self._cost_fn = problem.cost_function()

    def solve(self, x, ref, u_prev, D, last, half_widths=None) -> MPCSolution:
        """One control step, from the last solution shifted by a sample (``u_prev`` held at first)."""
        guess = np.full(self.problem.horizon, u_prev) if last is None else np.r_[last.guess[0][1:], last.guess[0][-1]]
        u, U, step = self.control(x, u_prev, ref, guess)
        return MPCSolution((np.asarray(U, dtype=float).ravel(),), np.nan, self.iterations, float(step) <= ADJOINT_TOL,
                           float(u), (x, u_prev, ref))

    def _cost(self, x, U, ref, u_prev, D) -> float:
        return float(self._cost_fn(x, U, ref, u_prev, D))

    def predicted_output(self, solution: MPCSolution) -> np.ndarray:
        pb, (x, _, _) = self.problem, solution.p
        if pb.model is not None:
            return pb.model.simulate(solution.guess[0], x0=x)
        return np.asarray(pb.step.mapaccum("p", pb.horizon)(x, solution.guess[0][None, :])[1], dtype=float).ravel()


def _feasible_function(N: int, du_max: float) -> ca.Function:
    """``feasible(V, v_prev)``: ``V`` moved into the constraints, each input within ``du_max`` of the one
    before (``v_prev`` before the first), then within [0, 1] (which keeps the first, since the one
    before is inside)."""
    V, v_prev = ca.MX.sym("V", N), ca.MX.sym("v_prev")
    v, rows = v_prev, []
    for k in range(N):
        v = ca.fmin(ca.fmax(ca.fmin(ca.fmax(V[k], v - du_max), v + du_max), 0.0), 1.0)
        rows.append(v)
    return ca.Function("feasible", [V, v_prev], [ca.vertcat(*rows)])


def _admm_function(D: np.ndarray) -> ca.Function:
    """``admm(H, g, lo, hi) -> d``: ``argmin_d 1/2 d'Hd + g'd  s.t.  lo <= [I; D] d <= hi`` by
    :data:`ADMM_ITERATIONS` iterations of OSQP's ADMM (Stellato et al. 2020: relaxation 1.6, sigma
    1e-6, rho from H's diagonal), branch-free: a fixed cost, and an answer (close to the QP's) even
    where an active-set method fails on degenerate constraints (an input at its bound and its rate
    limit at once)."""
    N = D.shape[0]
    A = ca.DM(np.vstack([np.eye(N), D]))
    H, g = ca.MX.sym("H", N, N), ca.MX.sym("g", N)
    lo, hi = ca.MX.sym("lo", 2 * N), ca.MX.sym("hi", 2 * N)
    rho = ca.fmax(ca.trace(H) / N, 1e-6)
    sigma, alpha = 1e-6, 1.6
    K_inv = ca.solve(H + (sigma + rho) * ca.DM.eye(N) + rho * ca.DM(D.T @ D), ca.DM.eye(N))
    # one iteration, a function of its own (its C is written once)
    d, z, y = ca.MX.sym("d", N), ca.MX.sym("z", 2 * N), ca.MX.sym("y", 2 * N)
    Ki, gs, los, his, r = ca.MX.sym("K_inv", N, N), ca.MX.sym("g", N), ca.MX.sym("lo", 2 * N), ca.MX.sym("hi", 2 * N), ca.MX.sym("rho")
    d1 = Ki @ (sigma * d - gs + A.T @ (r * z - y))
    relaxed = alpha * (A @ d1) + (1 - alpha) * z
    z1 = ca.fmin(ca.fmax(relaxed + y / r, los), his)
    step = ca.Function("admm_iteration", [d, z, y, Ki, gs, los, his, r], [d1, z1, y + r * (relaxed - z1)])
    dk, zk, yk = ca.MX.zeros(N, 1), ca.fmin(ca.fmax(ca.MX.zeros(2 * N, 1), lo), hi), ca.MX.zeros(2 * N, 1)
    for _ in range(ADMM_ITERATIONS):
        dk, zk, yk = step(dk, zk, yk, K_inv, g, lo, hi, rho)
    return ca.Function("admm", [H, g, lo, hi], [dk])
