"""Tracking MPC on any exported step ``(x, u) -> (x_next, y)``.

Two ways to solve it. For a model that carries a cheap ``approximation`` (a
hybrid's physics), the adjoint-based SQP of :mod:`._adjoint_sqp` on the inputs
alone. Otherwise an NLP for ``sqpmethod`` or IPOPT, with multiple shooting: the states after each of the ``horizon`` steps are decision
variables beside the inputs, the step is called once through ``Function.map``
over the horizon, and the NLP is expanded to SX when the step is an SX function
(one flat graph, cheap derivatives). Between control steps the previous
solution, shifted by one sample, warm-starts the next solve.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike, NDArray

from physics.data.io import recording, stop_callback

from ._adjoint_sqp import AdjointSQP, _compiled
from ._fixed_sqp import fixed_sqp_function
from ._scaling import Scaling
from ._static import rest_output
from hybrid.export._codegen import has_compiler
from hybrid.export._model import ExportedModel, ExportError

__all__ = ["TrackingMPC", "MPCStats", "SOLVERS", "ADJOINT_TOL"]

#: The scaled cost is multiplied by this (the optimum does not change): an error of 3 % of the
#: output span costs about 1, about as 2 deg do on the catheter in its own units, where the solvers'
#: absolute tolerances and IPOPT's barrier were set. 1 leaves sqpmethod's steps too small to meet
#: them, 1e4 its dual tolerance too tight (measured on a sine and on out-of-reach references).
COST_SCALE = 1e3

#: The adjoint SQP's default step tolerance, as a share of the input bounds' span
#: (1 um on the catheter's 6 mm would be 1/6000; this is 1e-3 mm on 6 mm).
ADJOINT_TOL = 1e-3 / 6

#: SQP iterations per control step of the ``"fixed-sqp"`` solver (warm-started from the last solution):
#: 1 is the real-time iteration; a hybrid whose network carries much of the output may need 2-3.
FIXED_ITERATIONS = 1

#: Solver names -> (nlpsol plugin, default options). "sqp" is the fast one.
SOLVERS: dict[str, tuple[str, dict]] = {
    "ipopt": ("ipopt", {"print_time": False, "ipopt.print_level": 0, "ipopt.sb": "yes",
                        "ipopt.max_iter": 200, "ipopt.tol": 1e-8,
                        "ipopt.warm_start_init_point": "yes", "ipopt.mu_init": 1e-3}),
    "sqp": ("sqpmethod", {"qpsol": "qrqp", "print_time": False, "print_header": False,
                          "print_iteration": False, "print_status": False, "max_iter": 30,
                          "tol_pr": 1e-6, "tol_du": 1e-6, "error_on_fail": False,
                          "qpsol_options": {"print_iter": False, "print_header": False,
                                            "print_info": False, "error_on_fail": False}}),
}


@dataclass(frozen=True)
class _Solution:
    guess: tuple
    cost: float
    iterations: int
    success: bool


@dataclass
class MPCStats:
    """Wall time (s), iterations and success of every solve since the last reset."""

    solve_times: list[float] = field(default_factory=list)
    iterations: list[int] = field(default_factory=list)
    success: list[bool] = field(default_factory=list)

    def summary(self) -> dict[str, float]:
        t = np.asarray(self.solve_times) * 1e3
        if t.size == 0:
            return {"solves": 0}
        return {"solves": int(t.size), "median_ms": float(np.median(t)), "p99_ms": float(np.percentile(t, 99)),
                "max_ms": float(t.max()), "mean_iterations": float(np.mean(self.iterations)),
                "success_rate": float(np.mean(self.success))}


class TrackingMPC:
    """Track a reference of a model's output with a bounded input and input rate.

    Minimises ``sum_k w_track ((y_k - r_k)/s_y)^2 + w_du ((u_k - u_{k-1})/s_u)^2 + w_u ((u_k - u_ref)/s_u)^2``
    over ``k = 0..horizon-1`` subject to the model, ``u_bounds`` and
    ``|u_k - u_{k-1}| <= du_max`` (``u_{-1}`` is the input applied last).

    Parameters
    ----------
    step : casadi.Function or ExportedModel
        ``(x, u) -> (x_next, y)``; ``u`` is the command, or ``[command, *measured]`` for a model
        that also reads measured inputs (e.g. motor current): those are measured disturbances,
        given to :meth:`solve` and held over the horizon.
    horizon : int
        Samples predicted (25 = 1 s at 25 Hz).
    u_bounds : (float, float) or None
        Input limits, in the model's input units (mm of tendon for the catheter). Default: the
        range of the input the model was fitted on (``ExportedModel.input_range``); a model that
        does not record it (a physics spec never identified) needs them given.
    du_max : float or None
        Largest change of ``u`` per sample, in input units. Default: a twelfth of the bounds'
        span (0.5 mm for the catheter's 0-6 mm), at most the model's ``meta["max_input_step"]``
        where it records one (a neural ODE: the fastest input it was trained on, beyond which its
        exported fixed-step RK4 no longer equals its prediction).
    w_track, w_du, w_u : float
        Weights of the tracking error, the input rate and the input level, each measured in
        the model's own scales: the error over the span ``s_y`` of the model's output across
        the input bounds, the input and its change over the bounds' span ``s_u`` (unit-free,
        so a model in metres and radians is controlled as one in mm and deg; on the
        catheter, ``w_du = 1e-3`` is about 0.1 per mm^2 against 1 per deg^2). The solvers
        work on that scaled problem (:class:`hybrid.control._scaling.Scaling`), so their
        tolerances mean the same in any units too.
    solver : {"auto", "adjoint-sqp", "sqp", "ipopt"}
        ``"adjoint-sqp"``: SQP on the inputs with the exact gradient (one adjoint
        sweep of the model) and a Gauss-Newton Hessian from the model's
        ``approximation`` (a hybrid's physics; else the model itself), compiled
        with gcc (:class:`hybrid.control.AdjointSQP`): what makes MPC on an LSTM
        hybrid real-time. ``"sqp"``: CasADi's ``sqpmethod`` with ``qrqp`` on the
        full NLP; ``"ipopt"``: IPOPT (robust). ``"auto"`` (default): adjoint-sqp
        for a model with an approximation, else sqp. ``"fixed-sqp"``: a fixed number of
        SQP iterations per control step (``solver_options={"iterations": 1}``, the default: the
        real-time iteration), warm-started from the last solution, as one pure CasADi function
        (:attr:`control_function`, :mod:`hybrid.control._fixed_sqp`; ``"gradient": "exact"`` for
        a reverse sweep of a hybrid instead of its physics' Gauss-Newton gradient) that runs compiled and
        is generated as a C controller by ``hyst export --controller``: the same cost on every sample.
    hessian : {"gauss-newton", "exact"}
        Hessian used by ``"sqp"`` (IPOPT always uses the exact one).
    shooting : {"multiple", "single"} or None
        Multiple shooting (states are decision variables; default for ``n_x <= 16``)
        or single shooting (inputs only; default for long states such as a
        50-sample buffer or an LSTM's h and c).
    expand : bool or None
        Expand the NLP to SX; default: when the step is an SX function whose
        expanded horizon stays under 2 million instructions.
    y_bounds : (float, float), optional
        Output limits over the horizon, in the model's output units, None for no limit on one side
        (full-NLP solvers: ``ipopt``, ``sqp``; ``auto`` then means ``ipopt``: on a backlash's kinks,
        sqp with qrqp stalled with the constraints active).
    tighten : bool
        Keep the model's prediction interval, not only its prediction, inside ``y_bounds``: the
        constraints become ``y - h >= low`` and ``y + h <= high`` with ``h`` the half-width the
        model's export carries (:attr:`ExportedModel.half_width`, calibrated by ``hyst fit``),
        which grows where the inputs leave the training data. ``h`` is held fixed within a solve
        (a back-off: the half-widths along the warm start, then along the solution, the larger
        kept, solved again where they grew): the nearest-neighbour half-width is not smooth.
    solver_options : dict, optional
        Merged over the defaults in :data:`SOLVERS` (for the adjoint SQP: its ``max_iter``, and
        ``tol`` in input units, default :data:`ADJOINT_TOL` of the bounds' span). The NLP
        solvers' tolerances apply to the scaled problem.

    Examples
    --------
    >>> from physics import Series
    >>> from hybrid.export import export_model
    >>> from hybrid.control import TrackingMPC
    >>> model = export_model(Series.from_spec("lag+boucwen+linear"))
    >>> mpc = TrackingMPC(model, u_bounds=(0.0, 6.0), horizon=10, solver="sqp")
    >>> u0 = mpc.solve(model.x0(1.0), [50.0] * 10, u_prev=1.0)
    >>> 1.0 < u0 <= 1.0 + mpc.du_max + 1e-9
    True
    """

    def __init__(self, step, horizon: int = 25, u_bounds: tuple[float, float] | None = None,
                 du_max: float | None = None, w_track: float = 1.0, w_du: float = 1e-3, w_u: float = 0.0,
                 u_ref: float | None = None, solver: str = "auto", expand: bool | None = None,
                 hessian: str = "gauss-newton", shooting: str | None = None,
                 solver_options: dict | None = None, y_bounds: tuple[float, float] | None = None,
                 tighten: bool = False):
        self.model = step if isinstance(step, ExportedModel) else None
        self.y_bounds, self.tighten = _check_output_bounds(self.model, y_bounds, tighten, solver)
        if y_bounds is not None and solver == "auto":
            solver = "ipopt"  # output constraints live in the full NLP; sqp + qrqp stalls on a backlash's kinks
        self.step = step.step if isinstance(step, ExportedModel) else step
        _check_step(self.step)
        if int(horizon) != horizon or horizon < 1:
            raise ExportError(f"The 'horizon' of TrackingMPC must be a whole number >= 1. Got {horizon} instead.")
        if u_bounds is None:
            u_bounds = self.model.input_range if self.model is not None else None
            if u_bounds is None:
                raise ExportError("This model does not record the input range it was fitted on; give the MPC's "
                                  "input limits in its input units: TrackingMPC(..., u_bounds=(low, high)).")
        lo, hi = (float(v) for v in u_bounds)
        if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
            raise ExportError(f"The 'u_bounds' of TrackingMPC must be (low, high) with low < high. Got {u_bounds}.")
        if du_max is None:
            du_max = min((hi - lo) / 12, self.model.meta.get("max_input_step", np.inf) if self.model else np.inf)
        if not du_max > 0:
            raise ExportError(f"The 'du_max' of TrackingMPC must be > 0 input units per sample. Got {du_max} instead.")
        self.n_d = int(self.step.numel_in(1)) - 1  # measured disturbances beside the command
        if solver == "auto":
            approx = self.model is not None and self.model.approximation is not None
            solver = "adjoint-sqp" if approx and not self.n_d else "sqp"
        if solver in ("adjoint-sqp", "fixed-sqp") and self.n_d:
            what = "adjoint SQP" if solver == "adjoint-sqp" else "fixed-iteration SQP"
            raise ExportError(f"The {what} steps a model with one input; this one also reads {self.n_d} "
                              "measured input(s). Use solver='sqp' or 'ipopt'.")
        if solver not in (*SOLVERS, "adjoint-sqp", "fixed-sqp"):
            raise ExportError(f"Unknown MPC solver {solver!r}. Must be one of: auto, adjoint-sqp, fixed-sqp, "
                              f"{', '.join(SOLVERS)}.")
        self.horizon, self.u_bounds, self.du_max = int(horizon), (lo, hi), float(du_max)
        self.w_track, self.w_du, self.w_u = float(w_track), float(w_du), float(w_u)
        self.u_ref = 0.5 * (lo + hi) if u_ref is None else float(u_ref)
        self.solver_name = solver
        self._scale_problem()
        if hessian not in ("gauss-newton", "exact"):
            raise ExportError(f"hessian must be 'gauss-newton' or 'exact'. Got {hessian!r} instead.")
        self.hessian = hessian
        if shooting is None:  # a long state (buffer, LSTM) makes single shooting far smaller
            shooting = "multiple" if self.n_x <= 16 else "single"
        if shooting not in ("multiple", "single"):
            raise ExportError(f"shooting must be 'multiple' or 'single'. Got {shooting!r} instead.")
        self.shooting = shooting
        self._ns = self.n_x if shooting == "multiple" else 0
        if expand is None:  # expanding is worth it unless the flat graph gets huge (an SX LSTM)
            expand = self.step.is_a("SXFunction") and self.step.n_instructions() * self.horizon < 2_000_000
        self.expand = bool(expand)
        t0 = time.perf_counter()
        self._sqp = self._control = None
        if solver == "fixed-sqp":
            options = dict(solver_options or {})
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
            approx = self.model.approximation if self.model is not None else None
            self.iterations = int(iterations)
            rest = None
            if self.model is not None:  # the rest outputs across the bounds: a start off a flat region
                u_grid = np.linspace(lo, hi, 201)
                rest = (u_grid, np.array([rest_output(self.model, v) for v in u_grid]))
            self.control_function = fixed_sqp_function(
                self._step_n, self._scale.wrap(approx) if approx is not None else self._step_n, self._scale,
                self.horizon, self._scaled, self.iterations, rest, gradient)
            compile_ = has_compiler() if compile_ is None else bool(compile_)
            self._control = _compiled([self.control_function])[0] if compile_ else self.control_function
            self.shooting = "single"
        elif solver == "adjoint-sqp":
            approx = self.model.approximation if self.model is not None else None
            options = dict(solver_options or {})
            options["tol"] = options.get("tol", ADJOINT_TOL * (hi - lo)) / (hi - lo)
            sc, (w_track, w_du, w_u, u_ref, du_max) = self._scale, self._scaled
            self._sqp = AdjointSQP(self._step_n, sc.wrap(approx) if approx is not None else self._step_n,
                                   self.horizon, (0.0, 1.0), du_max, w_track, w_du, w_u, u_ref, **options)
            self._cost = lambda x0, U, ref, u_prev, D: self._sqp._cost(x0, U, ref, u_prev)
            self.shooting = "single"
        else:
            self._build(solver_options or {})
        self.build_time = time.perf_counter() - t0
        self.stats = MPCStats()
        self._guess, self._rest_map = None, None

    @property
    def n_x(self) -> int:
        return int(self.step.size1_in(0))

    def _scale_problem(self) -> None:
        """The problem in the model's scales (:class:`Scaling`): the step, the weights, and the
        input reference and rate limit scaled."""
        lo, hi = self.u_bounds
        rest = ()
        if self.model is not None:  # at rest at each bound: the static span, at any rate
            rest = tuple((self.model.x0(u0), rest_output(self.model, u0))
                         for u0 in (np.r_[u, np.zeros(self.n_d)] for u in (lo, hi)))
        x0 = rest[0][0] if rest else np.zeros(self.n_x)
        sc = self._scale = Scaling.measure(self.step, x0, self.u_bounds, self.n_d, rest)
        self._step_n = sc.wrap(self.step)
        k = COST_SCALE
        self._scaled = (k * self.w_track, k * self.w_du, k * self.w_u, float(sc.u(self.u_ref)), self.du_max / sc.u_span)

    def _build(self, user_options: dict) -> None:
        N, nx = self.horizon, self.n_x
        ns = self._ns  # states per stage among the decision variables
        x_init, u_prev, ref = ca.MX.sym("x_init", nx), ca.MX.sym("u_prev"), ca.MX.sym("ref", 1, N)
        D = ca.MX.sym("d", self.n_d, N)  # measured inputs over the horizon
        # stage-wise order [u_k; x_k] (x_k: state after step k) keeps the KKT system banded
        w = ca.MX.sym("w", (ns + 1) * N)
        stages = ca.reshape(w, ns + 1, N)
        U = stages[0, :]
        w_track, w_du, w_u, u_ref, du_max = self._scaled
        if ns:
            X = stages[1:, :]
            x_next, y = self._step_n.map(N, "serial")(ca.horzcat(x_init, X[:, :N - 1]), ca.vertcat(U, D))
            dynamics = ca.vec(x_next - X)
        else:
            _, y = self._step_n.mapaccum("horizon", N)(x_init, ca.vertcat(U, D))
            dynamics = ca.MX.zeros(0, 1)
        du = U - ca.horzcat(u_prev, U[:, :N - 1])
        residuals = ca.vertcat(np.sqrt(w_track) * (y - ref).T, np.sqrt(w_du) * du.T,
                               np.sqrt(w_u) * (U - u_ref).T)
        H = ca.MX.sym("h", N if self.tighten else 0)  # the interval's half-widths over the horizon (scaled)
        bound, lb_y, ub_y = self._output_constraints(y, H)
        g = ca.vertcat(dynamics, du.T, bound)
        nlp = {"x": w, "p": ca.vertcat(x_init, u_prev, ref.T, ca.vec(D), H), "f": ca.sumsqr(residuals), "g": g}
        plugin, options = SOLVERS[self.solver_name]
        if "qpsol" in user_options:  # another QP solver: its own options only
            options = {k: v for k, v in options.items() if k != "qpsol_options"}
        options = _merge(options, user_options)
        options["expand"] = self.expand
        if self.solver_name == "sqp" and self.hessian == "gauss-newton":
            options["hess_lag"] = self._gauss_newton(w, nlp["p"], residuals, g)
        elif self.solver_name == "sqp":  # exact Hessian of a hysteresis law is indefinite
            options = _merge({"convexify_strategy": "regularize", "convexify_margin": 1e-6}, options)
        # Ctrl-C ends a solve in progress (CasADi swallows the press; the loop then stops on it)
        self._stop = stop_callback(int(w.numel()), int(g.numel()), int(nlp["p"].numel()))
        options.setdefault("iteration_callback", self._stop)
        self._solver = ca.nlpsol("mpc", plugin, nlp, options)
        self._cost = self._cost_function()
        self._y = ca.Function("predicted", [w, nlp["p"]], [y])
        lbw = np.tile(np.r_[0.0, np.full(ns, -np.inf)], N)
        ubw = np.tile(np.r_[1.0, np.full(ns, np.inf)], N)
        self._bounds = dict(lbx=lbw, ubx=ubw, lbg=np.r_[np.zeros(ns * N), np.full(N, -du_max), lb_y],
                            ubg=np.r_[np.zeros(ns * N), np.full(N, du_max), ub_y])

    def _output_constraints(self, y, H):
        """``y_bounds`` over the horizon as constraints on the (scaled) outputs: ``y - h >= y_lo`` and
        ``y + h <= y_hi``, ``h`` the parameters ``H`` with ``tighten`` (the half-widths :meth:`_backoff`
        sets before each solve), else 0."""
        N = self.horizon
        if self.y_bounds is None:
            return ca.MX.zeros(0, 1), np.zeros(0), np.zeros(0)
        sc = self._scale
        h = H.T if self.tighten else 0
        lo, hi = (float(sc.y(v)) for v in self.y_bounds)
        rows, lower, upper = [], [], []
        if np.isfinite(lo):
            rows, lower, upper = [(y - h).T], [np.full(N, lo)], [np.full(N, np.inf)]
        if np.isfinite(hi):
            rows, lower, upper = [*rows, (y + h).T], [*lower, np.full(N, -np.inf)], [*upper, np.full(N, hi)]
        return ca.vertcat(*rows), np.concatenate(lower), np.concatenate(upper)
    def _cost_function(self) -> ca.Function:
        """The objective of a scaled input path by rollout: ``cost(x0, U, ref, u_prev)`` (``AdjointSQP._cost``'s
        signature), all scaled."""
        N = self.horizon
        x0, U, ref, u_prev = ca.MX.sym("x0", self.n_x), ca.MX.sym("U", 1, N), ca.MX.sym("ref", N), ca.MX.sym("u_prev")
        D = ca.MX.sym("d", self.n_d, N)
        w_track, w_du, w_u, u_ref, _ = self._scaled
        _, y = self._step_n.mapaccum("cost", N)(x0, ca.vertcat(U, D))
        du = U - ca.horzcat(u_prev, U[:, :N - 1])
        f = w_track * ca.sumsqr(y.T - ref) + w_du * ca.sumsqr(du) + w_u * ca.sumsqr(U - u_ref)
        return ca.Function("mpc_cost", [x0, U, ref, u_prev, D], [f])

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

    def reset(self) -> None:
        """Forget the warm start and the statistics."""
        self._guess, self.stats = None, MPCStats()

    def solve(self, x: ArrayLike, reference_window: ArrayLike, u_prev: float | None = None,
              measured: ArrayLike | None = None, half_widths: ArrayLike | None = None) -> float:
        """The input to apply now, from state ``x`` and the reference of the next ``horizon`` samples.

        ``reference_window[k]`` is the wanted output at sample ``k`` (``k = 0`` is now);
        a shorter window is padded with its last value. ``u_prev`` defaults to the
        input returned last (or the middle of ``u_bounds``). ``measured``: for a model that
        reads measured inputs besides the command, their values now (held over the horizon),
        or one row per coming sample (padded with its last row). ``half_widths`` (with
        ``tighten``): the interval's half-widths over the horizon in output units, one or ``horizon``
        values, e.g. an online band's (:meth:`hybrid.intervals.AdaptiveIntervals.half_width` with
        ``ahead = 1 .. horizon``); default: the exported model's own along the solution. Ctrl-C ends
        the solve in progress and raises KeyboardInterrupt.
        """
        given = self._given_half_widths(half_widths)
        with recording():
            self._online_h = given
            try:
                return self._solve(x, reference_window, u_prev, measured)
            finally:
                self._online_h = None

    def _given_half_widths(self, half_widths) -> np.ndarray | None:
        """``half_widths`` checked and scaled to the solver's output units (None: the model's own)."""
        if half_widths is None:
            return None
        if not self.tighten:
            raise ExportError("half_widths are the interval the output bounds keep inside: they need "
                              "TrackingMPC(..., tighten=True).")
        h = np.asarray(half_widths, dtype=float).ravel()
        if h.size not in (1, self.horizon) or not np.all(np.isfinite(h)) or np.any(h < 0):
            raise ExportError(f"half_widths must be one or {self.horizon} (the horizon) finite values >= 0; "
                              f"got {h.size} value(s): {h[:5].tolist()}.")
        return np.broadcast_to(h, (self.horizon,)) / self._scale.y_span

    def _solve_fixed(self, x: np.ndarray, ref: np.ndarray, u_prev: float) -> float:
        """One control step of the fixed-iteration SQP, from the last solution shifted by a sample."""
        guess = (np.full(self.horizon, u_prev) if self._guess is None
                 else np.r_[self._guess[0][1:], self._guess[0][-1]])
        t0 = time.perf_counter()
        u, U, step = self._control(x, u_prev, ref, guess)
        self.stats.solve_times.append(time.perf_counter() - t0)
        self.stats.iterations.append(self.iterations)
        self.stats.success.append(float(step) <= ADJOINT_TOL)
        self._guess = (np.asarray(U, dtype=float).ravel(),)
        self._last_p = (x, u_prev, ref)
        self._last_u = float(u)
        return self._last_u

    def _solve(self, x: ArrayLike, reference_window: ArrayLike, u_prev: float | None, measured=None) -> float:
        N, nx = self.horizon, self.n_x
        x = np.asarray(x, dtype=float).ravel()
        if x.size != nx:
            raise ExportError(f"The state must have {nx} entries; got {x.size}.")
        if not np.all(np.isfinite(x)):
            raise ExportError(f"The state has non-finite entries at {np.flatnonzero(~np.isfinite(x)).tolist()}; "
                              "pass the model's state (e.g. model.x0(u)) advanced on the applied inputs.")
        ref = np.asarray(reference_window, dtype=float).ravel()
        if ref.size == 0 or not np.all(np.isfinite(ref)):
            raise ExportError("The reference window must hold at least one finite value.")
        ref = np.r_[ref[:N], np.full(max(0, N - ref.size), ref[-1])]
        if u_prev is None:
            u_prev = self._last_u if self._guess is not None else self.u_ref
        if self._control is not None:
            self._measured(measured)
            return self._solve_fixed(x, ref, float(u_prev))
        D = self._measured(measured)
        sc = self._scale  # the solvers see the scaled problem
        x, ref, u_phys, u_prev = sc.x(x), sc.y(ref), float(u_prev), float(sc.u(u_prev))
        p = np.r_[x, u_prev, ref, D.ravel(order="F")]
        t0 = time.perf_counter()
        if self._sqp is not None:
            best = self._solve_adjoint(x, ref, u_prev, self._adjoint_guess(u_prev))
        else:
            start = self._warm_start(x, u_prev, D)
            h = self._backoff(x, start[0], u_prev, D)
            best = self._solve_nlp(np.r_[p, h], *start)
            if self.tighten:  # the half-widths where the solution goes; once more if they grew there
                h_new = self._backoff(x, best.guess[0], u_prev, D)
                if np.any(h_new > h + 1e-9):
                    h = np.maximum(h, h_new)
                    best = self._solve_nlp(np.r_[p, h], *best.guess)
            p = np.r_[p, h]
        self._last_p = p
        if self.model is not None:
            # a flat region (a backlash's dead band: dy/du = 0) holds a gradient method where it starts;
            # where the inputs whose rest outputs are the reference cost less, start again from them
            U = sc.u(self._static_guess(sc.y_back(ref), u_phys, D[:, 0]))
            if _clearly_less(float(self._cost(x, U, ref, u_prev, D)), best.cost):
                other = (self._solve_adjoint(x, ref, u_prev, U) if self._sqp is not None
                         else self._solve_nlp(p, *self._states_for(x, U, D)))
                if _clearly_less(other.cost, best.cost):
                    best = replace(other, iterations=best.iterations + other.iterations)
        self.stats.solve_times.append(time.perf_counter() - t0)
        self.stats.iterations.append(best.iterations)
        self.stats.success.append(best.success)
        self._guess = best.guess
        self._last_u = float(np.clip(sc.u_back(best.guess[0][0]), *self.u_bounds))
        return self._last_u

    def _backoff(self, x, w, u_prev: float, D) -> np.ndarray:
        """With ``tighten``: the model's half-widths (scaled) along the inputs of ``w`` (scaled) and
        the outputs they lead to from ``x``; else nothing."""
        if not self.tighten:
            return np.zeros(0)
        if getattr(self, "_online_h", None) is not None:  # given by the caller (an online band)
            return np.array(self._online_h)
        N, sc = self.horizon, self._scale
        U = np.clip(np.asarray(w, dtype=float)[::self._ns + 1], 0.0, 1.0)
        _, y = self._step_n.mapaccum("backoff", N)(x, np.vstack([U[None, :], D]))
        u = sc.u_back(U)
        h, _ = self.model.half_width.map(N)(u[None, :], np.r_[sc.u_back(u_prev), u[:-1]][None, :],
                                             sc.y_back(np.asarray(y, dtype=float))[None, :].reshape(1, N))
        return np.asarray(h, dtype=float).ravel() / sc.y_span

    def _solve_nlp(self, p, w0, lam_g0, lam_x0) -> "_Solution":
        """The NLP from ``w0``; its cost is that of its inputs' rollout, since an unconverged
        multiple-shooting iterate's own objective (states off the dynamics) can be far below it."""
        sol = self._solver(x0=w0, p=p, lam_g0=lam_g0, lam_x0=lam_x0, **self._bounds)
        st = self._solver.stats()
        w = np.asarray(sol["x"], dtype=float).ravel()
        guess = (w, np.asarray(sol["lam_g"], dtype=float).ravel(), np.asarray(sol["lam_x"], dtype=float).ravel())
        N, nx = self.horizon, self.n_x
        D = p[nx + 1 + N:nx + 1 + N + self.n_d * N].reshape(self.n_d, N, order="F")
        cost = float(self._cost(p[:nx], np.clip(w[::self._ns + 1], 0.0, 1.0), p[nx + 1:nx + 1 + N], p[nx], D))
        return _Solution(guess, cost if np.isfinite(cost) else np.inf, int(st.get("iter_count", -1)),
                         bool(st.get("success", False)))

    def _adjoint_guess(self, u_prev: float) -> np.ndarray:
        """Scaled inputs to start from (``u_prev`` scaled)."""
        U0 = np.full(self.horizon, float(np.clip(u_prev, 0.0, 1.0)))
        if self._guess is not None:  # the last solution shifted by a sample, if it is still feasible
            shifted = np.r_[self._guess[0][1:], self._guess[0][-1]]
            if abs(shifted[0] - u_prev) <= self._scaled[4]:
                U0 = shifted
        return U0

    def _solve_adjoint(self, x, ref, u_prev: float, U0: np.ndarray) -> "_Solution":
        U, iterations, converged = self._sqp.solve(x, ref, u_prev, U0)
        cost = float(self._sqp._cost(x, U, ref, u_prev))
        return _Solution((U,), cost, iterations, converged)

    def _measured(self, measured) -> np.ndarray:
        """The measured inputs over the horizon, ``n_d x horizon``."""
        N, n_d = self.horizon, self.n_d
        if n_d == 0:
            if measured is not None and np.size(measured):
                raise ExportError("This model reads no measured inputs besides the command; drop measured=.")
            return np.zeros((0, N))
        if measured is None:
            raise ExportError(f"This model also reads {n_d} measured input(s) (meta 'inputs' of the export); "
                              "give their values: solve(..., measured=[...]).")
        rows = np.atleast_2d(np.asarray(measured, dtype=float))
        if rows.shape[1] != n_d or not np.all(np.isfinite(rows)):
            raise ExportError(f"measured must hold {n_d} finite value(s) per sample; got shape {np.shape(measured)}.")
        rows = np.vstack([rows[:N], np.repeat(rows[-1:], max(0, N - rows.shape[0]), axis=0)])
        return rows.T

    def _static_guess(self, ref: np.ndarray, u_prev: float, d: np.ndarray) -> np.ndarray:
        """Inputs heading, within the rate limit, to those whose rest outputs are ``ref``."""
        key = tuple(np.round(d, 12))
        if self._rest_map is None or self._rest_map[0] != key:
            u = np.linspace(*self.u_bounds, 201)
            self._rest_map = (key, u, np.array([rest_output(self.model, np.r_[v, d]) for v in u]))
        _, u_grid, y_grid = self._rest_map
        out, u = np.empty(self.horizon), u_prev
        for k, r in enumerate(ref):
            target = u_grid[int(np.argmin(np.abs(y_grid - r)))]
            u = float(np.clip(target, u - self.du_max, u + self.du_max))
            out[k] = u
        return out

    def _states_for(self, x, U: np.ndarray, D: np.ndarray):
        """The NLP's start (scaled inputs ``U`` with the states they lead to) and zero multipliers."""
        N, ns = self.horizon, self._ns
        xs = (np.asarray(self._step_n.mapaccum("guess", N)(x, np.vstack([U[None, :], D]))[0]) if ns
              else np.zeros((0, N)))
        n_bound = 0 if self.y_bounds is None else N * int(np.isfinite(self.y_bounds).sum())
        return np.vstack([U[None, :], xs]).T.ravel(), np.zeros(ns * N + N + n_bound), np.zeros(N * (ns + 1))

    def predicted_output(self) -> NDArray[np.float64]:
        """Outputs the last solution predicts over the horizon."""
        if self._guess is None:
            raise ExportError("Call solve() first.")
        if self._control is not None:
            x, _, _ = self._last_p
            return self.model.simulate(self._guess[0], x0=x) if self.model is not None else np.asarray(
                self.step.mapaccum("p", self.horizon)(x, self._guess[0][None, :])[1], dtype=float).ravel()
        if self._sqp is not None:
            N, nx = self.horizon, self.n_x
            p = self._last_p
            return self._scale.y_back(self._sqp.predicted_output(p[:nx], self._guess[0], p[nx + 1:nx + 1 + N], p[nx]))
        return self._scale.y_back(np.asarray(self._y(self._guess[0], self._last_p), dtype=float).ravel())

    def _warm_start(self, x, u_prev, D):
        N, ns = self.horizon, self._ns
        if self._guess is None:  # hold the input, roll the model forward
            return self._states_for(x, np.full(N, u_prev), D)
        w, lam_g, lam_x = self._guess
        shift = lambda v, k: np.r_[v[k:], v[-k:]] if k else v  # noqa: E731  drop stage 0, repeat the last
        dyn, rate, outputs = lam_g[:ns * N], lam_g[ns * N:ns * N + N], lam_g[ns * N + N:]
        # the shifted inputs with the states they lead to from x: the dynamics hold at the start
        # (the states predicted last time need not, when the plant moved otherwise)
        w0 = self._states_for(x, shift(w, ns + 1)[::ns + 1], D)[0]
        bounds = [shift(v, 1) for v in np.split(outputs, outputs.size // N)] if outputs.size else []
        return w0, np.r_[shift(dyn, ns), shift(rate, 1), *bounds], shift(lam_x, ns + 1)


def _check_output_bounds(model, y_bounds, tighten, solver: str):
    """``(y_bounds, tighten)`` checked: finite ``low < high``; ``tighten`` needs them and a model
    that carries its interval (``ExportedModel.half_width``); both need the full NLP (sqp, ipopt)."""
    if tighten and y_bounds is None:
        raise ExportError("tighten=True keeps the model's interval inside the output bounds; give them: "
                          "TrackingMPC(..., y_bounds=(low, high), tighten=True).")
    if y_bounds is None:
        return None, False
    lo, hi = (-np.inf if v is None else float(v) for v in y_bounds)
    if not (lo < hi and (np.isfinite(lo) or np.isfinite(hi))) or np.isnan(lo) or np.isnan(hi):
        raise ExportError(f"The 'y_bounds' of TrackingMPC must be (low, high) with low < high (None or inf for no "
                          f"limit on one side). Got {y_bounds}.")
    hi = np.inf if y_bounds[1] is None else hi
    if solver in ("adjoint-sqp", "fixed-sqp"):
        raise ExportError(f"Output bounds are constraints of the full NLP; the {solver} solver bounds the inputs "
                          "only. Use solver='sqp' or 'ipopt' (or 'auto').")
    if tighten and getattr(model, "half_width", None) is None:
        raise ExportError("tighten=True needs a model that carries its prediction interval (ExportedModel.half_width: "
                          "the step.casadi of a model folder from `hyst fit`, or set it from "
                          "ConformalIntervals.function()).")
    if tighten and int(model.step.numel_in(1)) != 1:
        raise ExportError("tighten=True works for a model with one input; this one also reads measured inputs.")
    return (lo, hi), bool(tighten)


def _clearly_less(a: float, b: float) -> bool:
    """``a < b`` by more than rounding: a restart replaces a solution only where it is really better."""
    return a < b - 1e-6 * abs(b) - 1e-12


def _merge(base: dict, extra: dict) -> dict:
    out = dict(base)
    for k, v in extra.items():
        out[k] = _merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


def _check_step(step) -> None:
    if not isinstance(step, ca.Function) or step.n_in() != 2 or step.n_out() != 2:
        raise ExportError("The MPC needs a step Function (x, u) -> (x_next, y), e.g. export_model(model).step.")
    if step.numel_in(1) < 1 or step.numel_out(1) != 1:
        raise ExportError(f"The MPC handles a command (plus measured inputs) and one output; the step has {step.numel_in(1)} "
                          f"input(s) and {step.numel_out(1)} output(s).")
