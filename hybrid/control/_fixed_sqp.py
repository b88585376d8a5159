"""A control step of bounded cost: a fixed number of SQP iterations, its QPs solved by DAQP.

The tracking problem of :class:`~hybrid.control.TrackingMPC`, condensed onto the horizon's
inputs (single shooting, the scaled problem of :class:`~hybrid.control._scaling.Scaling`), is
solved from a warm start (the last solution shifted by a sample) by exactly ``iterations``
SQP iterations: each one rolls the model out once, takes the output Jacobian of its
``approximation`` (a hybrid's physics; else the model itself) for a Gauss-Newton Hessian and
gradient (or the exact gradient by a reverse sweep, ``gradient="exact"``), solves the dense QP
under the input and rate bounds with DAQP (a dual active-set solver, Arnstrom et al. 2022), and
takes the first of the step lengths 1 and 1/2 that lowers the cost, or none (a backtracking line
search of at most two evaluations). With one iteration this is
the real-time iteration scheme. Output bounds (``y_bounds``) are a soft constraint, a squared hinge
in the cost, whose linearisation the QP carries by slack variables: the QP is never infeasible.

The step is written once, as CasADi pieces (:func:`sqp_pieces`: the start, an iteration's QP, its
line search, the way back to physical units). :func:`compose` joins them around CasADi's DAQP into
one ``Function('control', [x, u_prev, ref, U_guess], [u, U, step])`` (with output bounds,
``control(x, u_prev, ref, U_guess, h)``, ``h`` the interval's half-widths): the reference, which runs
anywhere. ``c/control.c`` joins the same pieces, generated as C, around DAQP's own C sources
(vendored in ``c/daqp``, MIT licence), with the QP's workspace allocated once and its working set
warm-started from the last step's, shifted by a sample: the controller :func:`write_controller`
writes for a robot (no Python, torch or CasADi runtime), and what :class:`FixedSQPSolver` runs where
gcc is there (:func:`compiled_control`, loaded by ``casadi.external``).
"""

from __future__ import annotations

from typing import NamedTuple

import casadi as ca
import numpy as np

from hybrid.export._codegen import has_compiler
from hybrid.export._model import ExportError

from ._adjoint_sqp import ADJOINT_TOL, QP_OPTIONS, QP_SOLVER
from ._control_c import compiled_control
from ._mpc_problem import COST_SCALE, MPCProblem
from ._mpc_solver import MPCSolution, MPCSolver, register_solver
from ._scaling import Scaling
from ._static import rest_output

__all__ = ["fixed_sqp_function", "sqp_pieces", "compose", "SQPPieces", "FixedSQPSolver", "STEP_LENGTHS",
           "FIXED_ITERATIONS", "BOUND_WEIGHT", "QP_INF"]

#: SQP iterations per control step of the ``"fixed-sqp"`` solver (warm-started from the last solution):
#: 1 is the real-time iteration; a hybrid whose network carries much of the output may need 2-3.
FIXED_ITERATIONS = 1

#: Step lengths tried in turn on the QP's direction each iteration (backtracking: the first that lowers the
#: cost is taken, the next only evaluated when it did not); none: the iterate is kept (never worse). With 1/4
#: and 1/8 as well, tracking the virtual catheter's truth was the same (0.081 deg RMSE, physics and FNN-HIB
#: hybrid), and the hybrid's C control step took 165 us median, 388 us p99, against 108 and 149 us: its
#: network's rollout is most of a step, and the physics' direction often fails the full length on it.
STEP_LENGTHS = (1.0, 0.5)
#: A warm start holds the input (is at rest) where no input of it is further than this from the last one
#: (scaled): the rest inputs' path may then replace it where it is cheaper (:func:`sqp_pieces`).
REST_STILL = 1e-9
#: Elsewhere the rest inputs' path replaces the warm start only where it costs at most this share of the warm
#: start's (on the approximation). A switch on a small difference flips with the measurement's noise and
#: makes the input jitter; a warm start stuck at an input bound (a local minimum: a lag+boucwen+linear fitted
#: to the catheter's set 1, whose descending branch cannot reach the reference from there) needs the switch.
#: Tracking, 0.15 deg noise, deg RMSE (virtual catheter's truth: mean of 5 seeds), physics / FNN-HIB hybrid /
#: catheter fit on itself: 1 (whichever is cheaper) 0.120 / - / 0.077; 0.5 0.081 / 0.089 / 0.077; 0.4 0.081 /
#: 0.081 / 0.069; 0.33 and below 0.081 / 0.081 / 1.25 (the QP by 40 ADMM iterations before, with 1: 0.083 /
#: 0.083 / 0.145). A hybrid's approximation (its physics) does not cost what the hybrid does: with the margin
#: on it, the FNN-HIB hybrid tracked with 0.120 (0.7) and 0.155 deg (1), so a hybrid switches only without a
#: warm start to go on from.
REST_MARGIN = 0.4
#: An infinite bound in the QP (DAQP's ``DAQP_INF``): a side of the output band with no limit.
QP_INF = 1e30
#: Levenberg term added to the Hessian's diagonal (scaled units): a flat model region (a
#: backlash's dead band, dy/du = 0) with no rate or level weight still gives a bounded step.
REGULARISATION = 1e-8
#: Weight of the output bounds' squared hinge per unit of :data:`~hybrid.control.COST_SCALE` (a violation
#: of the scaled output costs this many times a tracking error of the same size with ``w_track = 1``): a
#: reference beyond a bound pushes the output past it by about ``w_track / BOUND_WEIGHT`` of the gap.
BOUND_WEIGHT = 1e3


class SQPPieces(NamedTuple):
    """The control step's CasADi pieces (all scaled inside, physical units outside), composed around a QP
    solver by :func:`fixed_sqp_function` (CasADi's DAQP) and by the generated ``control.c`` (DAQP in C,
    warm-started): ``(V, p) = start(x, u_prev, ref, U_guess[, h])``; each iteration ``(H, f, At, lower,
    upper, f0) = qp(V, p)``, ``z = argmin 1/2 z'Hz + f'z  s.t.  lower <= [z; At' z] <= upper``,
    ``(V, step) = line(V, z, p, f0)``; then ``(u, U) = finish(V)``."""

    start: ca.Function
    qp: ca.Function
    line: ca.Function
    finish: ca.Function

    @property
    def sizes(self) -> dict:
        """The QP's variables ``nv`` and rows ``nc``, the parameters ``np`` and the horizon ``n``."""
        return dict(n=self.finish.size1_out(1), nv=self.qp.size1_out(1), nc=self.qp.size2_out(2),
                    np=self.start.size1_out(1), nx=self.start.size1_in(0), n_in=self.start.n_in())


def fixed_sqp_function(step_n: ca.Function, approx_n: ca.Function, scaling, horizon: int, weights: tuple,
                       iterations: int, rest: tuple[np.ndarray, np.ndarray] | None = None,
                       gradient: str = "gauss-newton", y_bounds: tuple[float, float] | None = None,
                       bound_weight: float = BOUND_WEIGHT) -> ca.Function:
    """``control(x, u_prev, ref, U_guess) -> (u, U, step)`` in physical units; with ``y_bounds``,
    ``control(x, u_prev, ref, U_guess, h) -> (u, U, step)``: :func:`sqp_pieces` composed with CasADi's
    DAQP as the QP solver (the reference the generated ``control.c`` is checked against)."""
    return compose(sqp_pieces(step_n, approx_n, scaling, horizon, weights, rest, gradient, y_bounds, bound_weight),
                   iterations)


def compose(pieces: SQPPieces, iterations: int) -> ca.Function:
    """The control step of ``pieces`` with ``iterations`` SQP iterations, its QPs solved by CasADi's DAQP
    (each from an empty working set: the optimum is unique, so only rounding differs from ``control.c``)."""
    size = pieces.sizes
    nv, nc = size["nv"], size["nc"]
    solver = ca.conic("control_qp_solver", QP_SOLVER, {"h": pieces.qp.sparsity_out(0),
                                                       "a": pieces.qp.sparsity_out(2).T}, QP_OPTIONS)
    inputs = [ca.MX.sym(pieces.start.name_in(i), pieces.start.sparsity_in(i)) for i in range(size["n_in"])]
    V, p = pieces.start(*inputs)
    last = ca.MX(0)
    for _ in range(int(iterations)):
        H, f, At, lower, upper, f0 = pieces.qp(V, p)
        z = solver(h=H, g=f, a=At.T, lbx=lower[:nv], ubx=upper[:nv], lba=lower[nv:nv + nc], uba=upper[nv:])["x"]
        V, last = pieces.line(V, z, p, f0)
    u, U = pieces.finish(V)
    return ca.Function("control", inputs, [u, U, last], [pieces.start.name_in(i) for i in range(size["n_in"])],
                       ["u", "U", "step"])


def sqp_pieces(step_n: ca.Function, approx_n: ca.Function, scaling, horizon: int, weights: tuple,
               rest: tuple[np.ndarray, np.ndarray] | None = None, gradient: str = "gauss-newton",
               y_bounds: tuple[float, float] | None = None, bound_weight: float = BOUND_WEIGHT,
               bounded: tuple[ca.Function, ca.Function, Scaling] | None = None) -> SQPPieces:
    """The pieces of the control step (:class:`SQPPieces`).

    ``step_n`` and ``approx_n`` are the model and its approximation on the scaled problem
    (``scaling.wrap``), ``weights`` the scaled ``(w_track, w_du, w_u, u_ref, du_max)``; ``U`` is the
    solution (the next call's guess, shifted), ``step`` the largest input change of the last
    iteration in the scaled inputs (0 to 1 over the bounds): a converged solve takes ~0 there.

    ``rest``: the model's rest output on a grid of inputs ``(u, y)``, physical units (with ``bounded``, ``(u, y,
    y_bounded)``: the path then stops where the bounded output's rest reaches ``y_bounds``). With it the
    iterations start from the cheaper of the warm start and the inputs heading (within the rate
    limit) to those whose rest outputs are the reference: in a flat region (a backlash's dead band,
    dy/du = 0) a gradient step from the warm start would not move. Where there is no warm start to go on from
    (one that holds the input, at rest, or one that the bounds and rate limit had to move: it does not continue
    from the input just applied, a jump of the state or of the input) the cheaper of the two is taken;
    elsewhere the rest inputs' path only where it costs at most :data:`REST_MARGIN` of the warm start's, and
    only where the approximation is the model itself (a physics model; a hybrid's physics does not cost what
    the hybrid does).

    ``gradient``: ``"gauss-newton"`` (default: ``2 J'(Y - ref)`` plus the rate and level terms,
    with the model's outputs ``Y`` and the Jacobian ``J`` the Hessian uses: the exact gradient when
    ``J`` is the model's own, a physics model's; for a hybrid it leaves out the network's share of
    dy/du, and costs one rollout of the model instead of a reverse sweep of about three) or
    ``"exact"`` (the reverse sweep: a fixed point then solves the hybrid's own problem).

    The QP of an iteration, in the input changes ``d`` (scaled): ``min 1/2 d'Hd + g'd`` with ``H`` the
    Gauss-Newton Hessian ``2 (w_track J'J + w_du D'D + w_u I)``, ``V + d`` in [0, 1] (simple bounds) and
    its rates within ``du_max`` (``N`` rows ``D d``).

    ``y_bounds``: ``(low, high)`` in output units (an infinite side is no limit), kept by a soft
    constraint: the cost gains ``bound_weight * sum_k (max(0, y_k + h_k - high)^2 + max(0, low + h_k -
    y_k)^2)`` on the scaled outputs (a squared hinge; ``bound_weight`` is scaled as the weights are),
    ``h`` the extra input: the interval's half-widths over the horizon in output units (``horizon``
    values, >= 0; zeros keep the output itself inside). Each iteration's QP carries the hinge
    linearised, ``bound_weight dist(Y + J d, [low + h, high - h])^2``, by ``N`` slacks ``s`` (``z = [d;
    s]``): ``bound_weight |s|^2`` in the objective and ``N`` rows ``low + h - Y <= J d - s <= high - h -
    Y``, so the QP is never infeasible; the line search's cost, and the start's, carry the hinge whole.

    ``bounded``: ``(step, approximation, scaling)`` of another output of the same model (the same state:
    :meth:`MPCProblem.bound_views`), which ``y_bounds`` limit instead of the tracked one (in its own scale):
    the hinge, its rows and its Jacobian are that output's.
    """
    if gradient not in ("exact", "gauss-newton"):
        raise ValueError(f"gradient must be 'exact' or 'gauss-newton'; got {gradient!r}.")
    N, nx = int(horizon), int(step_n.size1_in(0))
    w_track, w_du, w_u, u_ref, du_max = (float(v) for v in weights)
    D = np.eye(N) - np.eye(N, k=-1)  # dU = D U - e0 u_prev
    sc = scaling
    x, u_prev = ca.MX.sym("x", nx), ca.MX.sym("u_prev")
    ref, guess = ca.MX.sym("ref", N), ca.MX.sym("U_guess", N)
    # scaled: state, previous input, reference, guess
    xi = (x - ca.DM(sc.x_mid)) / ca.DM(sc.x_span)
    v_prev = (u_prev - sc.u_lo) / sc.u_span
    eta = (ref - sc.y_mid) / sc.y_span
    V = (guess - sc.u_lo) / sc.u_span
    h_in = [] if y_bounds is None else [ca.MX.sym("h", N)]  # the half-widths, the bounded output's units
    h_n = [h / (sc if bounded is None else bounded[2]).y_span for h in h_in]

    # cost, exact gradient, and the approximation's output Jacobian, as functions of (x, U, ref, u_prev[, h])
    x0s, Us, refs, ups = ca.MX.sym("x0", nx), ca.MX.sym("U", N), ca.MX.sym("ref", N), ca.MX.sym("u_prev")
    band = None if y_bounds is None else _Band(y_bounds, sc if bounded is None else bounded[2], bound_weight, N)
    hs = [] if band is None else [band.h]  # the scaled half-widths, an input of each function with bounds
    _, Y = step_n.mapaccum("horizon", N)(x0s, Us.T)
    Yb = Y if bounded is None else bounded[0].mapaccum("bounded", N)(x0s, Us.T)[1]  # the bounded output
    du = Us - ca.vertcat(ups, Us[:N - 1])
    f = w_track * ca.sumsqr(Y.T - refs) + w_du * ca.sumsqr(du) + w_u * ca.sumsqr(Us - u_ref)
    if band is not None:
        f = f + band.penalty(Yb.T)
    cost = ca.Function("cost", [x0s, Us, refs, ups, *hs], [f])
    cost_grad = ca.Function("cost_grad", [x0s, Us, refs, ups, *hs], [f, ca.gradient(f, Us), *([Yb.T] if hs else [])])
    cost_outputs = ca.Function("cost_outputs", [x0s, Us, refs, ups, *hs],
                               [f, Y.T, *([Yb.T] if bounded is not None and hs else [])])
    jac, Ya = _output_jacobian(approx_n, x0s, Us, N)
    jac_b, Yba = (jac, Ya) if bounded is None else _output_jacobian(bounded[1], x0s, Us, N)
    fa = w_track * ca.sumsqr(Ya.T - refs) + w_du * ca.sumsqr(du) + w_u * ca.sumsqr(Us - u_ref)
    if band is not None:
        fa = fa + band.penalty(Yba.T)
    approx_cost = ca.Function("approx_cost", [x0s, Us, refs, ups, *hs], [fa])
    feasible = _feasible_function(N, du_max)

    # start: the guess within the bounds and the rate limit from u_prev (or the rest inputs' path), and the
    # parameters p = [xi; eta; v_prev; h (scaled, with bounds)] the iterations read
    guess_v, V = V, feasible(V, v_prev)
    if rest is not None:
        u_grid, y_grid = (np.asarray(v, dtype=float).ravel() for v in rest[:2])
        order = np.argsort(y_grid, kind="stable")
        y_sorted, keep = np.unique(y_grid[order], return_index=True)  # strictly increasing for the lookup
        if y_sorted.size >= 2:
            inverse = ca.interpolant("rest_inverse", "linear", [y_sorted], u_grid[order][keep])
            target = (inverse(ca.fmin(ca.fmax(ref.T, y_sorted[0]), y_sorted[-1])).T - sc.u_lo) / sc.u_span
            if bounded is not None and band is not None and len(rest) > 2:  # held where the bounded output rests
                target = _within(target, u_grid, np.asarray(rest[2], dtype=float).ravel(), y_bounds, sc)
            static = feasible(target, v_prev)
            # compared on the approximation (a hybrid's physics costs microseconds where its network costs a
            # rollout); the cheaper where there is no warm start to go on from (one that holds the input, at rest,
            # or one the bounds and rate limit had to move: it does not continue from the input just applied),
            # elsewhere by a margin
            fresh = ca.logic_or(ca.mmax(ca.fabs(V - v_prev)) <= REST_STILL, ca.mmax(ca.fabs(V - guess_v)) > REST_STILL)
            cost_static, cost_warm = approx_cost(xi, static, eta, v_prev, *h_n), approx_cost(xi, V, eta, v_prev, *h_n)
            if approx_n is step_n:  # a physics model: also where it costs at most REST_MARGIN of the warm start
                V = ca.if_else(cost_static < ca.if_else(fresh, 1.0, REST_MARGIN) * cost_warm, static, V)
            else:  # a hybrid's physics does not cost what the hybrid does: no margin on it says the warm start
                # is stuck (switching on it tracked worse), so only a missing one switches, and only then are
                # the two rollouts run (short-circuit)
                V = ca.if_else(fresh, ca.if_else(cost_static < cost_warm, static, V), V, True)
    start = ca.Function("control_start", [x, u_prev, ref, guess, *h_in], [V, ca.vertcat(xi, eta, v_prev, *h_n)],
                        ["x", "u_prev", "ref", "U_guess", *(["h"] if h_in else [])], ["V", "p"])

    # one SQP iteration's QP, and its line search
    Vs, ps = ca.MX.sym("V", N), ca.MX.sym("p", nx + N + 1 + (N if band is not None else 0))
    xis, etas, vps = ps[:nx], ps[nx:nx + N], ps[nx + N]
    hv = [] if band is None else [ps[nx + N + 1:]]
    J = jac(xis, Vs)
    Jb = J if bounded is None or band is None else jac_b(xis, Vs)  # the bounded output's
    if gradient == "exact":
        f0, g, *Yv = cost_grad(xis, Vs, etas, vps, *hv)  # with bounds, the bounded outputs too
        Yv = Yv[0] if Yv else None
    else:
        f0, Yv, *Ybv = cost_outputs(xis, Vs, etas, vps, *hv)
        dv = Vs - ca.vertcat(vps, Vs[:N - 1])
        g = 2 * w_track * (J.T @ (Yv - etas)) + 2 * w_du * (ca.DM(D).T @ dv) + 2 * w_u * (Vs - u_ref)
        Yv = Ybv[0] if Ybv else Yv  # what the band reads from here on
    H = ca.DM(2 * (w_du * D.T @ D + w_u * np.eye(N)) + REGULARISATION * np.eye(N)) + 2 * w_track * (J.T @ J)
    rate = ca.DM(D) @ Vs - ca.DM(np.eye(N)[:, 0]) * vps
    lower, upper = [-Vs], [1 - Vs]  # the simple bounds on z, then the rows
    rows, row_lo, row_hi = [ca.horzcat(ca.DM(D), *([ca.DM(N, N)] if band is not None else []))], [-du_max - rate], \
        [du_max - rate]
    if band is not None:  # the squared hinge, linearised: w |s|^2, J d - s within the band's box
        if gradient == "exact":  # the exact gradient holds the hinge's; the QP adds its linearisation's
            g = g - band.gradient(Jb, Yv, hv[0])
        H = ca.diagcat(H, ca.DM.eye(N) * 2 * band.weight)
        g = ca.vertcat(g, ca.DM.zeros(N))
        lower.append(-QP_INF * ca.DM.ones(N))
        upper.append(QP_INF * ca.DM.ones(N))
        rows.append(ca.horzcat(Jb, -ca.DM.eye(N)))
        lo_s, hi_s = band.box(Yv, hv[0])
        row_lo.append(ca.fmax(lo_s, -QP_INF))
        row_hi.append(ca.fmin(hi_s, QP_INF))
    A = ca.densify(ca.vertcat(*rows))
    qp = ca.Function("control_qp", [Vs, ps], [ca.densify(H), g, A.T, ca.vertcat(*lower, *row_lo),
                                              ca.vertcat(*upper, *row_hi), f0],
                     ["V", "p"], ["H", "f", "At", "lower", "upper", "f0"])
    z, f0s = ca.MX.sym("z", H.size1()), ca.MX.sym("f0")
    best_v = Vs  # backtracking: the first step length that lowers the cost; a shorter one is only
    for a in STEP_LENGTHS[::-1]:  # evaluated when the longer failed (short-circuit branches)
        trial = feasible(Vs + a * z[:N], vps)
        best_v = ca.if_else(cost(xis, trial, etas, vps, *hv) < f0s, trial, best_v, True)
    line = ca.Function("control_line", [Vs, z, ps, f0s], [best_v, ca.mmax(ca.fabs(best_v - Vs))],
                       ["V", "z", "p", "f0"], ["V_next", "step"])
    Vf = ca.MX.sym("V", N)
    U = sc.u_lo + sc.u_span * Vf
    finish = ca.Function("control_finish", [Vf], [U[0], U], ["V"], ["u", "U"])
    return SQPPieces(start, qp, line, finish)


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
            rest = (u_grid, np.array([rest_output(model, v) for v in u_grid]),
                    *([] if problem.bounded is None else [np.array([rest_output(problem.bounded, v) for v in u_grid])]))
        #: The output bounds' penalty weight, per unit of ``COST_SCALE``.
        self.bound_weight = float(bound_weight)
        #: ``control(x, u_prev, ref, U_guess) -> (u, U, step)`` in physical units; with ``y_bounds``,
        #: ``control(x, u_prev, ref, U_guess, h)``, ``h`` the half-widths over the horizon (output units).
        #: The control step's CasADi pieces (:func:`sqp_pieces`), which the generated C joins around DAQP.
        self.pieces = sqp_pieces(problem.step_n, problem.approximation_n(), problem.scale, problem.horizon,
                                 problem.scaled, rest, gradient, problem.settings.y_bounds,
                                 COST_SCALE * self.bound_weight, problem.bound_views())
        self.control_function = compose(self.pieces, self.iterations)
        compile_ = has_compiler() if compile_ is None else bool(compile_)
        #: The control step as it runs here: with gcc, ``control.c`` compiled (:func:`compiled_control`,
        #: DAQP warm-started from the last step's working set); else :attr:`control_function`.
        self.control = compiled_control(self.pieces, self.iterations) if compile_ else self.control_function
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
        sc, span = pb.scale, pb.y_scale.y_span  # the half-widths are the bounded output's
        if not pb.settings.tighten:
            return np.zeros(pb.horizon)
        if given is not None:
            return span * np.asarray(given, dtype=float)
        U = np.clip(sc.u(guess), 0.0, 1.0)
        return span * pb.half_widths(sc.x(x), U, float(sc.u(u_prev)), D)

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


def _within(target, u_grid: np.ndarray, yb_grid: np.ndarray, y_bounds, sc: Scaling):
    """The rest inputs' path ``target`` (scaled) held to the inputs whose rest output of the bounded output lies
    within ``y_bounds``: heading to a reference the bounds forbid, the path stops where the bounded output
    reaches its bound (else, from a flat region, a path past it costs the hinge and the warm start stays put)."""
    lo, hi = y_bounds
    inside = u_grid[(yb_grid >= lo) & (yb_grid <= hi)]
    if inside.size == 0:
        return target
    return ca.fmin(ca.fmax(target, (inside.min() - sc.u_lo) / sc.u_span), (inside.max() - sc.u_lo) / sc.u_span)


def _output_jacobian(approx_n: ca.Function, x0s, Us, N: int) -> tuple[ca.Function, ca.MX]:
    """``(jac, Ya)``: the Jacobian of ``approx_n``'s outputs over the horizon with respect to the inputs,
    ``jac(x0, U)``, taken on the states its output reads, and those outputs as expressions of ``(x0s, Us)``."""
    kept, approx_r = _output_states(approx_n)  # the states its output depends on, and it on those alone
    _, Ya = approx_r.mapaccum("approx", N)(x0s[kept], Us.T)
    jac = ca.Function("output_jacobian", [x0s, Us], [ca.jacobian(Ya.T, Us)])
    if approx_n.is_a("SXFunction"):  # a physics' scalar step (a network's graph would take long to expand)
        jac = _scalar(jac)
    return jac, Ya


#: Most instructions an expanded function may hold to replace its MX graph (:func:`_scalar`): the output
#: Jacobian of lag+backlash+linear over 25 samples holds 7,187; of lag+boucwen+linear 42,424 (a hybrid's
#: physics the same, :func:`_output_states`). As scalar code the latter's control step took 46 us against
#: 77 us as MX (the generated closed_loop, gcc -O2), for 26 s of gcc against 10 s.
SCALAR_LIMIT = 50_000


def _output_states(step: ca.Function) -> tuple[list[int], ca.Function]:
    """``(kept, reduced)``: the states ``step``'s output depends on, now or later (those it reads, and those
    their next values read, to a fixed point), and ``reduced(x[kept], u) -> (x_next[kept], y)``, which gives
    the same outputs. A hybrid's physics carries the network's states (an FNN-HIB's buffer of 100) that its
    output never reads: its Jacobian over the horizon then holds half the instructions. A step with no
    scalar form is returned whole."""
    n = step.size1_in(0)
    if not step.is_a("SXFunction"):
        return list(range(n)), step
    x, u = ca.SX.sym("x", n), ca.SX.sym("u", step.size1_in(1))
    x_next, y = step(x, u)
    reads = lambda e: set(np.nonzero(np.asarray(ca.DM(ca.jacobian_sparsity(e, x), 1)).any(axis=0))[0])  # noqa: E731
    kept = reads(y)
    while True:
        more = kept | (reads(x_next[sorted(kept)]) if kept else set())
        if more == kept:
            break
        kept = more
    kept = sorted(int(i) for i in kept)
    if len(kept) == n:
        return kept, step
    xs = ca.SX.sym("x", len(kept))
    full = ca.SX.zeros(n)
    full[kept] = xs
    x_next, y = step(full, u)
    return kept, ca.Function(step.name(), [xs, u], [x_next[kept], y], ["x", "u"], ["x_next", "y"])


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
