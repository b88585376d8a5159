"""The MPC's full NLP, for CasADi's ``sqpmethod`` (``"sqp"``) or IPOPT (``"ipopt"``).

With multiple shooting the states after each of the ``horizon`` steps are decision variables
beside the inputs, the step is called once through ``Function.map`` over the horizon, and the NLP
is expanded to SX when the step is an SX function (one flat graph, cheap derivatives). Between
control steps the previous solution, shifted by one sample, warm-starts the next solve. The full NLP
carries output bounds (``y_bounds``, ``tighten``) as constraints: hard ones for ``sqpmethod``; for IPOPT soft ones,
each row with a slack of its own at an exact (L1) penalty, so a bound the horizon cannot reach from the current state
(a run that starts outside it) costs its excess instead of leaving IPOPT without a feasible point (the fixed-iteration
SQP's is soft too, a squared hinge).
"""

from __future__ import annotations

from typing import Any, ClassVar, Mapping

import casadi as ca
import numpy as np
from numpy.typing import NDArray

from physics.data.io import stop_callback

from hybrid.export._model import ExportError

from ._mpc_problem import COST_SCALE, MPCProblem
from ._mpc_solver import MPCSolution, MPCSolver, register_solver

__all__ = ["NLPSolver", "SQPSolver", "IpoptSolver"]


class NLPSolver(MPCSolver):
    """The tracking problem as one NLP for an ``nlpsol`` plugin (abstract: :class:`SQPSolver`,
    :class:`IpoptSolver`).

    Options: ``shooting``, multiple (the states are decision variables; default for ``n_x <= 16``)
    or single (inputs only; default for long states such as a 50-sample buffer or an LSTM's h and
    c); ``expand``, the NLP expanded to SX (default: when the step is an SX function whose expanded
    horizon stays under 2 million instructions); the rest are the plugin's, merged over the class's
    :attr:`options` (nested dicts merged). The tolerances apply to the scaled problem.
    """

    plugin: ClassVar[str]
    #: Output bounds as soft constraints (a slack per row at :data:`BOUND_PENALTY`), or hard ones.
    soft_bounds: ClassVar[bool] = False
    #: The plugin's default options.
    options: ClassVar[dict[str, Any]]

    def __init__(self, problem: MPCProblem, options: Mapping[str, Any] | None = None):
        super().__init__(problem, options)
        options = dict(options or {})
        shooting, expand = options.pop("shooting", None), options.pop("expand", None)
        if shooting is None:  # a long state (buffer, LSTM) makes single shooting far smaller
            shooting = "multiple" if problem.n_x <= 16 else "single"
        if shooting not in ("multiple", "single"):
            raise ExportError(f"shooting must be 'multiple' or 'single'. Got {shooting!r} instead.")
        if expand is None:  # expanding is worth it unless the flat graph gets huge (an SX LSTM)
            step = problem.step
            expand = step.is_a("SXFunction") and step.n_instructions() * problem.horizon < 2_000_000
        if not isinstance(expand, (bool, np.bool_)):
            raise ExportError(f"expand must be True, False or None (decide by size). Got {expand!r} instead.")
        self._shooting, self._expand = shooting, bool(expand)
        self._ns = problem.n_x if shooting == "multiple" else 0  # states per stage among the variables
        self._build(self._own_options(options))

    @property
    def shooting(self) -> str:
        return self._shooting

    @property
    def expand(self) -> bool:
        return self._expand

    def _own_options(self, options: dict) -> dict:
        """Take this class's own options out of ``options``; the rest go to the plugin."""
        return options

    def _plugin_options(self, options: dict, w, p, residuals, g) -> dict:
        """The plugin's options for this NLP: ``options`` (the user's, merged over the defaults)."""
        return options

    def _build(self, user_options: dict) -> None:
        pb = self.problem
        N, nx, n_d, tighten = pb.horizon, pb.n_x, pb.n_d, pb.settings.tighten
        ns = self._ns
        x_init, u_prev, ref = ca.MX.sym("x_init", nx), ca.MX.sym("u_prev"), ca.MX.sym("ref", 1, N)
        D = ca.MX.sym("d", n_d, N)  # measured inputs over the horizon
        # stage-wise order [u_k; x_k] (x_k: state after step k) keeps the KKT system banded
        #: the output bounds' rows over the horizon (N per finite side), and a slack for each where they are soft
        self._n_bound = 0 if pb.settings.y_bounds is None else N * int(np.isfinite(pb.settings.y_bounds).sum())
        self._n_slack = self._n_bound if self.soft_bounds else 0
        self._penalty = BOUND_PENALTY * max(1.0, pb.settings.w_track)  # per unit of a slack (scaled excess)
        w = ca.MX.sym("w", (ns + 1) * N + self._n_slack)
        stages, slack = ca.reshape(w[:(ns + 1) * N], ns + 1, N), w[(ns + 1) * N:]
        U = stages[0, :]
        w_track, w_du, w_u, u_ref, du_max = pb.scaled
        if ns:
            X = stages[1:, :]
            x_next, y = pb.step_n.map(N, "serial")(ca.horzcat(x_init, X[:, :N - 1]), ca.vertcat(U, D))
            dynamics = ca.vec(x_next - X)
            bounded = None if pb.bound_n is None else pb.bound_n.map(N, "serial")(
                ca.horzcat(x_init, X[:, :N - 1]), ca.vertcat(U, D))[1]
        else:
            _, y = pb.step_n.mapaccum("horizon", N)(x_init, ca.vertcat(U, D))
            dynamics = ca.MX.zeros(0, 1)
            bounded = None if pb.bound_n is None else pb.bound_n.mapaccum("bounded", N)(x_init, ca.vertcat(U, D))[1]
        du = U - ca.horzcat(u_prev, U[:, :N - 1])
        residuals = ca.vertcat(np.sqrt(w_track) * (y - ref).T, np.sqrt(w_du) * du.T,
                               np.sqrt(w_u) * (U - u_ref).T)
        H = ca.MX.sym("h", N if tighten else 0)  # the interval's half-widths over the horizon (scaled)
        bound, lb_y, ub_y = self._output_constraints(y if bounded is None else bounded, H)
        f = ca.sumsqr(residuals)
        if self._n_slack:  # y - h + s >= lo, y + h - s <= hi, s >= 0, at an exact penalty: s = 0 where reachable
            bound = bound + ca.DM(np.where(np.isfinite(lb_y), 1.0, -1.0)) * slack
            f = f + self._penalty * ca.sum1(slack)
        g = ca.vertcat(dynamics, du.T, bound)
        nlp = {"x": w, "p": ca.vertcat(x_init, u_prev, ref.T, ca.vec(D), H), "f": f, "g": g}
        options = self.options
        if "qpsol" in user_options:  # another QP solver: its own options only
            options = {k: v for k, v in options.items() if k != "qpsol_options"}
        options = _merge(options, user_options)
        options["expand"] = self.expand
        options = self._plugin_options(options, w, nlp["p"], residuals, g)
        # Ctrl-C ends a solve in progress (CasADi swallows the press; the loop then stops on it)
        self._stop = stop_callback(int(w.numel()), int(g.numel()), int(nlp["p"].numel()))
        options.setdefault("iteration_callback", self._stop)
        try:
            self._solver = ca.nlpsol("mpc", self.plugin, nlp, options)
        except RuntimeError as e:
            if "Unknown option" not in str(e) and "unknown option" not in str(e).lower():
                raise
            raise ExportError(f"The {self.name} solver does not know an option of {sorted(user_options)}: "
                              f"{str(e).strip().splitlines()[-1]} (MPCSettings.solver_options take its own "
                              f"options and {self.plugin}'s).") from None
        self._cost_fn = pb.cost_function()
        self._y = ca.Function("predicted", [w, nlp["p"]], [y])
        lbw = np.r_[np.tile(np.r_[0.0, np.full(ns, -np.inf)], N), np.zeros(self._n_slack)]
        ubw = np.r_[np.tile(np.r_[1.0, np.full(ns, np.inf)], N), np.full(self._n_slack, np.inf)]
        self._bounds = dict(lbx=lbw, ubx=ubw, lbg=np.r_[np.zeros(ns * N), np.full(N, -du_max), lb_y],
                            ubg=np.r_[np.zeros(ns * N), np.full(N, du_max), ub_y])

    def _output_constraints(self, y, H):
        """``y_bounds`` over the horizon as constraints on the (scaled) outputs: ``y - h >= y_lo`` and
        ``y + h <= y_hi``, ``h`` the parameters ``H`` with ``tighten`` (the half-widths :meth:`_backoff`
        sets before each solve), else 0. ``y``: the bounded output (another than the tracked one where
        ``settings.bound`` names it, in its own scale)."""
        N, s = self.problem.horizon, self.problem.settings
        if s.y_bounds is None:
            return ca.MX.zeros(0, 1), np.zeros(0), np.zeros(0)
        sc = self.problem.y_scale
        h = H.T if s.tighten else 0
        lo, hi = (float(sc.y(v)) for v in s.y_bounds)
        rows, lower, upper = [], [], []
        if np.isfinite(lo):
            rows, lower, upper = [(y - h).T], [np.full(N, lo)], [np.full(N, np.inf)]
        if np.isfinite(hi):
            rows, lower, upper = [*rows, (y + h).T], [*lower, np.full(N, -np.inf)], [*upper, np.full(N, hi)]
        return ca.vertcat(*rows), np.concatenate(lower), np.concatenate(upper)

    def solve(self, x, ref, u_prev, D, last, half_widths=None) -> MPCSolution:
        sc, tighten = self.problem.scale, self.problem.settings.tighten  # the solver sees the scaled problem
        x, ref, u_phys, u_prev = sc.x(x), sc.y(ref), float(u_prev), float(sc.u(u_prev))
        p = np.r_[x, u_prev, ref, D.ravel(order="F")]
        start = self._warm_start(x, u_prev, D, last)
        h = self._backoff(x, start[0], u_prev, D, half_widths)
        best = self._solve_nlp(np.r_[p, h], *start)
        if tighten:  # the half-widths where the solution goes; once more if they grew there
            h_new = self._backoff(x, best.guess[0], u_prev, D, half_widths)
            if np.any(h_new > h + 1e-9):
                h = np.maximum(h, h_new)
                best = self._solve_nlp(np.r_[p, h], *best.guess)
        p = np.r_[p, h]
        best = self._from_rest(best, x, ref, u_phys, u_prev, D, lambda U: self._solve_nlp(p, *self._states_for(x, U, D)))
        u = float(np.clip(sc.u_back(best.guess[0][0]), *self.problem.settings.u_bounds))
        return MPCSolution(best.guess, best.cost, best.iterations, best.success, u, p)

    def _cost(self, x, U, ref, u_prev, D) -> float:
        return float(self._cost_fn(x, U, ref, u_prev, D))

    def _backoff(self, x, w, u_prev: float, D, given) -> np.ndarray:
        """With ``tighten``: the model's half-widths (scaled) along the inputs of ``w`` (scaled) and
        the outputs they lead to from ``x``; else nothing. ``given``: the caller's (an online band)."""
        pb = self.problem
        if not pb.settings.tighten:
            return np.zeros(0)
        if given is not None:  # given by the caller (an online band)
            return np.array(given)
        return pb.half_widths(x, np.clip(self._inputs(w), 0.0, 1.0), u_prev, D)

    def _inputs(self, w) -> np.ndarray:
        """The (scaled) inputs over the horizon in the decision variables ``w`` (stages ``[u_k; x_k]``, then the
        bounds' slacks)."""
        return np.asarray(w, dtype=float)[:(self._ns + 1) * self.problem.horizon:self._ns + 1]

    def _solve_nlp(self, p, w0, lam_g0, lam_x0) -> MPCSolution:
        """The NLP from ``w0``; its cost is that of its inputs' rollout, since an unconverged
        multiple-shooting iterate's own objective (states off the dynamics) can be far below it."""
        sol = self._solver(x0=w0, p=p, lam_g0=lam_g0, lam_x0=lam_x0, **self._bounds)
        st = self._solver.stats()
        w = np.asarray(sol["x"], dtype=float).ravel()
        guess = (w, np.asarray(sol["lam_g"], dtype=float).ravel(), np.asarray(sol["lam_x"], dtype=float).ravel())
        N, nx, n_d = self.problem.horizon, self.problem.n_x, self.problem.n_d
        D = p[nx + 1 + N:nx + 1 + N + n_d * N].reshape(n_d, N, order="F")
        cost = self._cost(p[:nx], np.clip(self._inputs(w), 0.0, 1.0), p[nx + 1:nx + 1 + N], p[nx], D)
        cost += self._penalty * float(np.sum(w[(self._ns + 1) * N:]))  # the bounds' excess, where soft
        return MPCSolution(guess, cost if np.isfinite(cost) else np.inf, int(st.get("iter_count", -1)),
                           bool(st.get("success", False)))

    def _states_for(self, x, U: np.ndarray, D: np.ndarray):
        """The NLP's start (scaled inputs ``U`` with the states they lead to) and zero multipliers."""
        pb = self.problem
        N, ns = pb.horizon, self._ns
        xs = (np.asarray(pb.step_n.mapaccum("guess", N)(x, np.vstack([U[None, :], D]))[0]) if ns
              else np.zeros((0, N)))
        w0 = np.r_[np.vstack([U[None, :], xs]).T.ravel(), np.zeros(self._n_slack)]
        return w0, np.zeros(ns * N + N + self._n_bound), np.zeros(N * (ns + 1) + self._n_slack)

    def _warm_start(self, x, u_prev, D, last: MPCSolution | None):
        N, ns = self.problem.horizon, self._ns
        if last is None:  # hold the input, roll the model forward
            return self._states_for(x, np.full(N, u_prev), D)
        w, lam_g, lam_x = last.guess
        shift = lambda v, k: np.r_[v[k:], v[-k:]] if k else v  # noqa: E731  drop stage 0, repeat the last
        dyn, rate, outputs = lam_g[:ns * N], lam_g[ns * N:ns * N + N], lam_g[ns * N + N:]
        # the shifted inputs with the states they lead to from x: the dynamics hold at the start
        # (the states predicted last time need not, when the plant moved otherwise)
        w0 = self._states_for(x, shift(self._inputs(w), 1), D)[0]
        bounds = [shift(v, 1) for v in np.split(outputs, outputs.size // N)] if outputs.size else []
        n = (ns + 1) * N  # the stages' multipliers shifted by a stage, each side's slacks' by a sample
        slacks = [shift(v, 1) for v in np.split(lam_x[n:], self._n_slack // N)] if self._n_slack else []
        return w0, np.r_[shift(dyn, ns), shift(rate, 1), *bounds], np.r_[shift(lam_x[:n], ns + 1), *slacks]

    def predicted_output(self, solution: MPCSolution) -> NDArray[np.float64]:
        return self.problem.scale.y_back(np.asarray(self._y(solution.guess[0], solution.p), dtype=float).ravel())


@register_solver
class SQPSolver(NLPSolver):
    """``solver="sqp"``: CasADi's ``sqpmethod`` with ``qrqp`` on the full NLP, the fast one. Options:
    those of :class:`NLPSolver`, ``hessian`` (``"gauss-newton"``, default, or ``"exact"``,
    regularised: a hysteresis law's is indefinite) and ``sqpmethod``'s, over :attr:`options`."""

    name, title, plugin = "sqp", "SQP", "sqpmethod"
    options = {"qpsol": "qrqp", "print_time": False, "print_header": False,
               "print_iteration": False, "print_status": False, "max_iter": 30,
               "tol_pr": 1e-6, "tol_du": 1e-6, "error_on_fail": False,
               "qpsol_options": {"print_iter": False, "print_header": False,
                                 "print_info": False, "error_on_fail": False}}

    def _own_options(self, options: dict) -> dict:
        hessian = options.pop("hessian", "gauss-newton")
        if hessian not in ("gauss-newton", "exact"):
            raise ExportError(f"hessian must be 'gauss-newton' or 'exact'. Got {hessian!r} instead.")
        self.hessian = hessian  #: ``"gauss-newton"`` or ``"exact"``
        return options

    def _plugin_options(self, options: dict, w, p, residuals, g) -> dict:
        if self.hessian == "gauss-newton":
            options["hess_lag"] = self._gauss_newton(w, p, residuals, g)
            return options
        return _merge({"convexify_strategy": "regularize", "convexify_margin": 1e-6}, options)

    def _gauss_newton(self, w, p, residuals, g) -> ca.Function:
        """Hessian of the Lagrangian without the constraints' curvature: ``2 lam_f J^T J``.

        Positive semi-definite, so the QP needs no convexification; the exact
        Hessian carries the smoothed ``|du|`` of hysteresis laws (curvature ~ 1e6),
        which forces heavy regularisation and tiny steps.
        """
        lam_f, lam_g = ca.MX.sym("lam_f"), ca.MX.sym("lam_g", g.shape[0])
        J = ca.jacobian(residuals, w)
        hess = 2 * lam_f * ca.mtimes(J.T, J)
        f = ca.Function("nlp_hess_l", [w, p, lam_f, lam_g], [hess],
                        ["x", "p", "lam_f", "lam_g"], ["hess_gamma_x_x"])
        return f.expand() if self.expand else f


@register_solver
class IpoptSolver(NLPSolver):
    """``solver="ipopt"``: IPOPT on the full NLP (robust; exact Hessian), warm-started from the last
    solution. Options: IPOPT's (``"ipopt.max_iter"``, ...), over :attr:`options`."""

    name, title, plugin = "ipopt", "IPOPT", "ipopt"
    soft_bounds = True
    iterations_option = "ipopt.max_iter"
    options = {"print_time": False, "ipopt.print_level": 0, "ipopt.sb": "yes",
               "ipopt.max_iter": 200, "ipopt.tol": 1e-8,
               "ipopt.warm_start_init_point": "yes", "ipopt.mu_init": 1e-3}


#: The soft output bounds' exact (L1) penalty per unit of scaled excess, times ``max(1, w_track)``: far above what
#: tracking a scaled output gains there (its cost's gradient is at most ``2 COST_SCALE w_track`` per sample), so a
#: bound the horizon can keep is kept as a hard one would be.
BOUND_PENALTY = 100.0 * COST_SCALE


def _merge(base: dict, extra: dict) -> dict:
    out = dict(base)
    for k, v in extra.items():
        out[k] = _merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out
