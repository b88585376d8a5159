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
real-time iteration scheme; a control step costs at most the same on every sample. Output bounds
(``y_bounds``) are a soft constraint, a squared hinge in the cost, whose linearisation the QP
carries as rows of the ADMM with a proximal step: the QP is never infeasible.

Everything (the scaling, the warm start made feasible, the iterations, the QP's ADMM) is one
``Function('control', [x, u_prev, ref, U_guess], [u, U, step])`` in physical units (with output
bounds, ``control(x, u_prev, ref, U_guess, h)``, ``h`` the interval's half-widths), so the same
function runs in Python (compiled with gcc where it is there) and, generated as C, in a robot's
control loop with no Python, torch or CasADi runtime (:func:`write_controller`).
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from hybrid.export._codegen import has_compiler
from hybrid.export._model import ExportError

from ._adjoint_sqp import ADJOINT_TOL, _compiled
from ._mpc_problem import COST_SCALE, MPCProblem
from ._mpc_solver import MPCSolution, MPCSolver, register_solver
from ._static import rest_output

__all__ = ["fixed_sqp_function", "FixedSQPSolver", "STEP_LENGTHS", "ADMM_ITERATIONS", "FIXED_ITERATIONS",
           "BOUND_WEIGHT", "SOFT_RHO"]

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
#: Weight of the output bounds' squared hinge per unit of :data:`~hybrid.control.COST_SCALE` (a violation
#: of the scaled output costs this many times a tracking error of the same size with ``w_track = 1``): a
#: reference beyond a bound pushes the output past it by about ``w_track / BOUND_WEIGHT`` of the gap.
BOUND_WEIGHT = 1e3
#: The ADMM's rho on the output bounds' rows, over its rho on the input rows: OSQP's ratio for rows
#: that act as equalities, as a bound's row does when its band is at it (a penalty 1e3 times the
#: tracking's). With 1 the 40 iterations leave the band 0.1-0.6 deg past the bound at horizons
#: 25-50; with the penalty in the Hessian instead, the QP is too stiff for them.
SOFT_RHO = 1e3


def fixed_sqp_function(step_n: ca.Function, approx_n: ca.Function, scaling, horizon: int, weights: tuple,
                       iterations: int, rest: tuple[np.ndarray, np.ndarray] | None = None,
                       gradient: str = "gauss-newton", y_bounds: tuple[float, float] | None = None,
                       bound_weight: float = BOUND_WEIGHT) -> ca.Function:
    """``control(x, u_prev, ref, U_guess) -> (u, U, step)`` in physical units; with ``y_bounds``,
    ``control(x, u_prev, ref, U_guess, h) -> (u, U, step)``.

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

    ``y_bounds``: ``(low, high)`` in output units (an infinite side is no limit), kept by a soft
    constraint: the cost gains ``bound_weight * sum_k (max(0, y_k + h_k - high)^2 + max(0, low + h_k -
    y_k)^2)`` on the scaled outputs (a squared hinge; ``bound_weight`` is scaled as the weights are),
    ``h`` the extra input: the interval's half-widths over the horizon in output units (``horizon``
    values, >= 0; zeros keep the output itself inside). Each iteration's QP carries the hinge
    linearised, ``bound_weight dist(Y + J d, [low + h, high - h])^2``, as rows of the ADMM
    (:func:`_admm_function`); the line search's cost, and the start's, carry it whole.
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
    h_in = [] if y_bounds is None else [ca.MX.sym("h", N)]  # the half-widths, output units
    h_n = [h / sc.y_span for h in h_in]

    # cost, exact gradient, and the approximation's output Jacobian, as functions of (x, U, ref, u_prev[, h])
    x0s, Us, refs, ups = ca.MX.sym("x0", nx), ca.MX.sym("U", N), ca.MX.sym("ref", N), ca.MX.sym("u_prev")
    band = None if y_bounds is None else _Band(y_bounds, sc, bound_weight, N)
    hs = [] if band is None else [band.h]  # the scaled half-widths, an input of each function with bounds
    _, Y = step_n.mapaccum("horizon", N)(x0s, Us.T)
    du = Us - ca.vertcat(ups, Us[:N - 1])
    f = w_track * ca.sumsqr(Y.T - refs) + w_du * ca.sumsqr(du) + w_u * ca.sumsqr(Us - u_ref)
    if band is not None:
        f = f + band.penalty(Y.T)
    cost = ca.Function("cost", [x0s, Us, refs, ups, *hs], [f])
    cost_grad = ca.Function("cost_grad", [x0s, Us, refs, ups, *hs], [f, ca.gradient(f, Us), *([Y.T] if hs else [])])
    cost_outputs = ca.Function("cost_outputs", [x0s, Us, refs, ups, *hs], [f, Y.T])
    _, Ya = approx_n.mapaccum("approx", N)(x0s, Us.T)
    jac = ca.Function("output_jacobian", [x0s, Us], [ca.jacobian(Ya.T, Us)])
    if approx_n.is_a("SXFunction"):  # a physics' scalar step (a network's graph would take long to expand)
        jac = _scalar(jac)
    fa = w_track * ca.sumsqr(Ya.T - refs) + w_du * ca.sumsqr(du) + w_u * ca.sumsqr(Us - u_ref)
    if band is not None:
        fa = fa + band.penalty(Ya.T)
    approx_cost = ca.Function("approx_cost", [x0s, Us, refs, ups, *hs], [fa])

    D = np.eye(N) - np.eye(N, k=-1)  # dU = D U - e0 u_prev
    H0 = ca.DM(2 * (w_du * D.T @ D + w_u * np.eye(N)) + REGULARISATION * np.eye(N))
    e0 = ca.DM(np.eye(N)[:, 0])
    feasible = _feasible_function(N, du_max)
    admm = _admm_function(D)
    soft_admm = None if band is None else _admm_function(D, band.weight)
    # one SQP iteration as a function of its own: the generated C holds its code once, whatever the count
    Vs, xis, etas, vps = ca.MX.sym("V", N), ca.MX.sym("xi", nx), ca.MX.sym("eta", N), ca.MX.sym("v_prev")
    hv = [] if band is None else [ca.MX.sym("h", N)]
    J = jac(xis, Vs)
    if gradient == "exact":
        f0, g, *Yv = cost_grad(xis, Vs, etas, vps, *hv)  # with bounds, the outputs too
        Yv = Yv[0] if Yv else None
    else:
        f0, Yv = cost_outputs(xis, Vs, etas, vps, *hv)
        dv = Vs - ca.vertcat(vps, Vs[:N - 1])
        g = 2 * w_track * (J.T @ (Yv - etas)) + 2 * w_du * (ca.DM(D).T @ dv) + 2 * w_u * (Vs - u_ref)
    H = H0 + 2 * w_track * (J.T @ J)
    rate = ca.DM(D) @ Vs - e0 * vps
    lo_d, hi_d = ca.vertcat(-Vs, -du_max - rate), ca.vertcat(1 - Vs, du_max - rate)
    if band is None:
        d = admm(H, g, lo_d, hi_d)
    else:  # the squared hinge, linearised (w dist(Y + J d, [low + h, high - h])^2), in the QP's ADMM
        if gradient == "exact":  # the exact gradient holds the hinge's; the QP adds its linearisation's
            g = g - band.gradient(J, Yv, hv[0])
        d = soft_admm(H, g, lo_d, hi_d, J, *band.box(Yv, hv[0]))
    best_v = Vs  # backtracking: the first step length that lowers the cost; a shorter one is only
    for a in STEP_LENGTHS[::-1]:  # evaluated when the longer failed (short-circuit branches)
        trial = feasible(Vs + a * d, vps)
        best_v = ca.if_else(cost(xis, trial, etas, vps, *hv) < f0, trial, best_v, True)
    iteration = ca.Function("sqp_iteration", [Vs, xis, etas, vps, *hv], [best_v, ca.mmax(ca.fabs(best_v - Vs))])

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
            V = ca.if_else(approx_cost(xi, static, eta, v_prev, *h_n) < approx_cost(xi, V, eta, v_prev, *h_n),
                           static, V)
    for _ in range(int(iterations)):
        V, last = iteration(V, xi, eta, v_prev, *h_n)
    U = sc.u_lo + sc.u_span * V
    return ca.Function("control", [x, u_prev, ref, guess, *h_in], [U[0], U, last],
                       ["x", "u_prev", "ref", "U_guess", *(["h"] if h_in else [])], ["u", "U", "step"])


@register_solver
class FixedSQPSolver(MPCSolver):
    """``solver="fixed-sqp"``: a fixed number of SQP iterations per control step, warm-started from the
    last solution, as one pure CasADi function (:attr:`control_function`, :func:`fixed_sqp_function`)
    that runs compiled and is generated as a C controller by ``hyst export --controller``
    (:func:`~hybrid.control.write_controller`): the same cost on every sample.

    Options: ``iterations`` (default :data:`FIXED_ITERATIONS`: the real-time iteration),
    ``gradient`` (``"gauss-newton"``, default, or ``"exact"``: a reverse sweep of a hybrid instead of
    its physics' Gauss-Newton gradient), ``bound_weight`` (default :data:`BOUND_WEIGHT`: the output
    bounds' penalty, see below) and ``compile`` (gcc; default: when it is there). A solve succeeds when
    its last iteration moved no input by more than :data:`ADJOINT_TOL` (scaled).

    With ``y_bounds`` the outputs over the horizon stay inside them by a soft constraint (a squared
    hinge in the cost, :func:`fixed_sqp_function`): a reference beyond a bound takes the output past it
    by about ``w_track / bound_weight`` of the gap, not 0 as in the NLP solvers, and never an infeasible
    QP. The control function then takes the interval's half-widths ``h`` over the horizon as its fifth
    input: zeros without ``tighten``; with it, those given to :meth:`TrackingMPC.solve` (an online band),
    else the model's own ``half_width`` along the warm start (the NLP solvers also re-solve along their
    solution; here the cost of a step stays fixed).
    """

    name, title = "fixed-sqp", "fixed-iteration SQP"
    iterations_option = "iterations"
    measured_inputs = False

    def __init__(self, problem: MPCProblem, options=None):
        super().__init__(problem, options)
        options = dict(options or {})
        iterations = options.pop("iterations", FIXED_ITERATIONS)
        compile_ = options.pop("compile", None)
        gradient = options.pop("gradient", "gauss-newton")
        bound_weight = options.pop("bound_weight", BOUND_WEIGHT)
        if options:
            raise ExportError(f"Unknown fixed-sqp option(s) {sorted(options)}; it takes 'iterations', 'gradient', "
                              "'bound_weight' and 'compile'.")
        if (isinstance(bound_weight, bool) or not isinstance(bound_weight, (int, float, np.integer, np.floating))
                or not (np.isfinite(bound_weight) and bound_weight > 0)):
            raise ExportError(f"The fixed-sqp bound_weight must be a finite number > 0. Got {bound_weight!r}.")
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
        #: The output bounds' penalty weight, per unit of ``COST_SCALE``.
        self.bound_weight = float(bound_weight)
        #: ``control(x, u_prev, ref, U_guess) -> (u, U, step)`` in physical units; with ``y_bounds``,
        #: ``control(x, u_prev, ref, U_guess, h)``, ``h`` the half-widths over the horizon (output units).
        self.control_function = fixed_sqp_function(problem.step_n, problem.approximation_n(), problem.scale,
                                                   problem.horizon, problem.scaled, self.iterations, rest, gradient,
                                                   problem.settings.y_bounds, COST_SCALE * self.bound_weight)
        compile_ = has_compiler() if compile_ is None else bool(compile_)
        #: :attr:`control_function` as it runs here (compiled with gcc where asked).
        self.control = _compiled([self.control_function])[0] if compile_ else self.control_function
        self._cost_fn = problem.cost_function()

    def solve(self, x, ref, u_prev, D, last, half_widths=None) -> MPCSolution:
        """One control step, from the last solution shifted by a sample (``u_prev`` held at first)."""
        guess = np.full(self.problem.horizon, u_prev) if last is None else np.r_[last.guess[0][1:], last.guess[0][-1]]
        h = () if self.problem.settings.y_bounds is None else (self._half_widths(x, guess, u_prev, D, half_widths),)
        u, U, step = self.control(x, u_prev, ref, guess, *h)
        return MPCSolution((np.asarray(U, dtype=float).ravel(),), np.nan, self.iterations, float(step) <= ADJOINT_TOL,
                           float(u), (x, u_prev, ref, *h))

    def _half_widths(self, x, guess, u_prev: float, D, given) -> np.ndarray:
        """The control function's ``h`` (output units): zeros without ``tighten``; the caller's (scaled:
        :meth:`TrackingMPC.solve`); else the model's along the warm start held inside the input bounds."""
        pb = self.problem
        sc = pb.scale
        if not pb.settings.tighten:
            return np.zeros(pb.horizon)
        if given is not None:
            return sc.y_span * np.asarray(given, dtype=float)
        U = np.clip(sc.u(guess), 0.0, 1.0)
        return sc.y_span * pb.half_widths(sc.x(x), U, float(sc.u(u_prev)), D)

    def _cost(self, x, U, ref, u_prev, D) -> float:
        return float(self._cost_fn(x, U, ref, u_prev, D))

    def predicted_output(self, solution: MPCSolution) -> np.ndarray:
        pb, x = self.problem, solution.p[0]
        if pb.model is not None:
            return pb.model.simulate(solution.guess[0], x0=x)
        return np.asarray(pb.step.mapaccum("p", pb.horizon)(x, solution.guess[0][None, :])[1], dtype=float).ravel()


class _Band:
    """The output bounds' squared hinge on the scaled outputs ``Y`` over the horizon: the band ``Y +- h``
    (``h`` the scaled half-widths, :attr:`h` in the cost functions) inside ``(low, high)``, i.e. ``Y``
    inside ``[low + h, high - h]``."""

    def __init__(self, y_bounds, scaling, weight: float, N: int):
        self.lo, self.hi = (float(scaling.y(v)) for v in y_bounds)  # an infinite side stays infinite
        self.weight, self.h = float(weight), ca.MX.sym("h", N)

    def excess(self, Y, h) -> tuple:
        """``(above, below)``: by how much ``Y`` is above ``high - h`` and below ``low + h`` (0 inside,
        and on a side without a bound)."""
        return (ca.fmax(Y + h - self.hi, 0) if np.isfinite(self.hi) else 0,
                ca.fmax(self.lo + h - Y, 0) if np.isfinite(self.lo) else 0)

    def penalty(self, Y):
        return self.weight * sum(ca.sumsqr(e) for e in self.excess(Y, self.h))

    def gradient(self, J, Y, h):
        """``2 w J' (above - below)``: the penalty's gradient through the outputs' Jacobian ``J``."""
        above, below = self.excess(Y, h)
        return 2 * self.weight * (J.T @ (above - below))

    def box(self, Y, h):
        """``(lo_s, hi_s)``: the box the output changes ``J d`` keep the outputs in (an infinite side stays)."""
        return self.lo + h - Y, self.hi - h - Y


#: Most instructions an expanded function may hold to replace its MX graph (:func:`_scalar`): the output
#: Jacobian of lag+backlash+linear over 25 samples holds 7,187; of lag+boucwen+linear 42,424, whose C took
#: gcc -O2 10.8 s against 3.0 s for the whole controller with it as MX, for 23 % less time per step.
SCALAR_LIMIT = 20_000


def _scalar(fn: ca.Function) -> ca.Function:
    """``fn`` as scalar (SX) code where it expands to at most :data:`SCALAR_LIMIT` instructions: straight-line
    C with no calls or copies between its pieces; else as it is (a long Jacobian whose C would take gcc
    long to compile, a network's graph, a block with no SX form)."""
    try:
        expanded = fn.expand()
    except RuntimeError:
        return fn
    return expanded if expanded.n_instructions() <= SCALAR_LIMIT else fn


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


def _admm_function(D: np.ndarray, soft_weight: float | None = None) -> ca.Function:
    """``admm(H, g, lo, hi) -> d``: ``argmin_d 1/2 d'Hd + g'd  s.t.  lo <= [I; D] d <= hi`` by
    :data:`ADMM_ITERATIONS` iterations of OSQP's ADMM (Stellato et al. 2020: relaxation 1.6, sigma
    1e-6, rho from H's diagonal), branch-free: a fixed cost, and an answer (close to the QP's) even
    where an active-set method fails on degenerate constraints (an input at its bound and its rate
    limit at once).

    With ``soft_weight`` ``w``: ``admm(H, g, lo, hi, J, lo_s, hi_s)`` also adds ``w dist(J d, [lo_s,
    hi_s])^2`` to the objective (the output bounds' squared hinge, linearised): the rows ``J`` join
    ``A`` with rho times :data:`SOFT_RHO`, and their ``z`` update is that term's proximal map in place
    of a projection, so the stiff penalty stays out of ``H`` (and the rho it sets) and the QP is
    never infeasible."""
    N = D.shape[0]
    soft = soft_weight is not None
    H, g = ca.MX.sym("H", N, N), ca.MX.sym("g", N)
    lo, hi = ca.MX.sym("lo", 2 * N), ca.MX.sym("hi", 2 * N)
    Jm, lo_s, hi_s = ca.MX.sym("J", N, N), ca.MX.sym("lo_s", N), ca.MX.sym("hi_s", N)
    rho = ca.fmax(ca.trace(H) / N, 1e-6)
    sigma, alpha = 1e-6, 1.6
    K = H + (sigma + rho) * ca.DM.eye(N) + rho * ca.DM(D.T @ D)
    K_inv = ca.solve(K + SOFT_RHO * rho * (Jm.T @ Jm) if soft else K, ca.DM.eye(N), "ldl")
    # one iteration, a function of its own (its C is written once)
    m = 3 * N if soft else 2 * N
    d, z, y = ca.MX.sym("d", N), ca.MX.sym("z", m), ca.MX.sym("y", m)
    Ki, gs, r = ca.MX.sym("K_inv", N, N), ca.MX.sym("g", N), ca.MX.sym("rho")
    los, his = ca.MX.sym("lo", m), ca.MX.sym("hi", m)
    Ji = ca.MX.sym("J", N, N)
    # [I; D] as its 3N - 1 nonzeros: each iteration's two products with it cost 6N, not 4N^2 (as dense);
    # K is symmetric positive definite: LDL' (the generated C's QR of it took a quarter of a control step)
    rows = ca.sparsify(ca.DM(np.vstack([np.eye(N), D])))
    A = ca.vertcat(rows, Ji) if soft else rows
    rv = ca.vertcat(r * ca.DM.ones(2 * N), SOFT_RHO * r * ca.DM.ones(N)) if soft else r  # rho per row
    d1 = Ki @ (sigma * d - gs + A.T @ (rv * z - y))
    relaxed = alpha * (A @ d1) + (1 - alpha) * z
    v = relaxed + y / rv
    z1 = ca.fmin(ca.fmax(v, los), his)
    if soft:  # the proximal map of w dist(., box)^2: a point outside moves 2w / (2w + rho) of the way in
        rs = SOFT_RHO * r
        z1 = ca.vertcat(z1[:2 * N], v[2 * N:] - 2 * soft_weight / (2 * soft_weight + rs) * (v[2 * N:] - z1[2 * N:]))
    step = ca.Function("admm_iteration", [d, z, y, Ki, gs, los, his, r, *([Ji] if soft else [])],
                       [d1, z1, y + rv * (relaxed - z1)]).expand()  # scalar code: no copies of K_inv per call
    lo_all, hi_all = (ca.vertcat(lo, lo_s), ca.vertcat(hi, hi_s)) if soft else (lo, hi)
    dk, zk, yk = ca.MX.zeros(N, 1), ca.vertcat(ca.fmin(ca.fmax(ca.MX.zeros(2 * N, 1), lo), hi),
                                               *([ca.MX.zeros(N, 1)] if soft else [])), ca.MX.zeros(m, 1)
    for _ in range(ADMM_ITERATIONS):
        dk, zk, yk = step(dk, zk, yk, K_inv, g, lo_all, hi_all, rho, *([Jm] if soft else []))
    return ca.Function("admm", [H, g, lo, hi, *([Jm, lo_s, hi_s] if soft else [])], [dk])
