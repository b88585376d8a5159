"""Tracking MPC on any exported step ``(x, u) -> (x_next, y)``.

``TrackingMPC(model, MPCSettings(...))`` (do-mpc's ``MPC(model, settings)``): the settings are
resolved on the model into an :class:`MPCProblem` (the problem in the model's own scales), and the
solver class the settings name is read from :data:`SOLVERS` and built on it: the full NLP for
``sqpmethod`` (:class:`SQPSolver`) or IPOPT (:class:`IpoptSolver`), the adjoint-based SQP on the
inputs alone for a model that carries a cheap ``approximation`` (:class:`AdjointSQPSolver`), or a
fixed number of SQP iterations as one CasADi function (:class:`FixedSQPSolver`). Between control
steps the previous solution, shifted by one sample, warm-starts the next solve.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from physics.data.io import recording

from . import _adjoint_sqp, _fixed_sqp, _nlp  # noqa: F401  each registers its solvers
from ._mpc_settings import MPCSettings
from ._mpc_problem import MPCProblem
from ._mpc_solver import SOLVERS, MPCSolution, MPCSolver
from hybrid.export._model import ExportError

__all__ = ["TrackingMPC", "MPCStats"]


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
    ``|u_k - u_{k-1}| <= du_max`` (``u_{-1}`` is the input applied last); :class:`MPCSettings`
    describes every setting.

    Parameters
    ----------
    step : casadi.Function or ExportedModel
        ``(x, u) -> (x_next, y)``; ``u`` is the command, or ``[command, *measured]`` for a model
        that also reads measured inputs (e.g. motor current): those are measured disturbances,
        given to :meth:`solve` and held over the horizon.
    settings : MPCSettings, optional
        What the MPC minimises and how it solves it (default: ``MPCSettings()``).
    horizon, u_bounds, du_max, solver, solver_options, y_bounds, tighten : optional
        Given (not None), they replace the fields of ``settings`` of the same name: the
        problem's constraints and the choice of solver, which nearly every MPC sets, stay one
        keyword away; the weights and the solvers' numerics live in ``settings`` only.

    Attributes
    ----------
    settings : MPCSettings
        The settings the MPC runs with, resolved on the model (``u_bounds``, ``du_max``,
        ``u_ref``, ``solver`` (``"auto"``: the one chosen)).
    problem : MPCProblem
        The problem in the model's own scales, which the solver is built on.
    solver : MPCSolver
        The solver, of the class :data:`SOLVERS` holds under ``settings.solver``.
    stats : MPCStats
        Time, iterations and success of each solve since the last :meth:`reset`.
    build_time : float
        Seconds the solver took to build (code generation and gcc included).

    Examples
    --------
    >>> from physics import Series
    >>> from hybrid.export import export_model
    >>> from hybrid.control import MPCSettings, TrackingMPC
    >>> model = export_model(Series.from_spec("lag+boucwen+linear"))
    >>> mpc = TrackingMPC(model, MPCSettings(horizon=10, u_bounds=(0.0, 6.0), solver="sqp"))
    >>> u0 = mpc.solve(model.x0(1.0), [50.0] * 10, u_prev=1.0)
    >>> 1.0 < u0 <= 1.0 + mpc.du_max + 1e-9
    True
    >>> TrackingMPC(model, u_bounds=(0.0, 6.0), horizon=10).solver_name   # the keywords replace the settings'
    'sqp'
    """

    def __init__(self, step, settings: MPCSettings | None = None, *, horizon: int | None = None,
                 u_bounds: tuple[float, float] | None = None, du_max: float | None = None, solver: str | None = None,
                 solver_options: dict | None = None, y_bounds: tuple[float | None, float | None] | None = None,
                 tighten: bool | None = None):
        if settings is None:
            settings = MPCSettings()
        if not isinstance(settings, MPCSettings):
            raise ExportError(f"settings must be an MPCSettings, e.g. TrackingMPC(model, MPCSettings(horizon=25)). "
                              f"Got {type(settings).__name__} instead.")
        given = {k: v for k, v in (("horizon", horizon), ("u_bounds", u_bounds), ("du_max", du_max), ("solver", solver),
                                   ("solver_options", solver_options), ("y_bounds", y_bounds), ("tighten", tighten))
                 if v is not None}
        self.problem = MPCProblem.build(step, replace(settings, **given) if given else settings)
        self.settings, self.model, self.step = self.problem.settings, self.problem.model, self.problem.step
        t0 = time.perf_counter()
        self.solver: MPCSolver = SOLVERS[self.settings.solver](self.problem, self.settings.solver_options)
        self.build_time = time.perf_counter() - t0
        self.stats = MPCStats()
        self._last: MPCSolution | None = None
        self._online_h = None

    @property
    def horizon(self) -> int:
        return self.settings.horizon

    @property
    def u_bounds(self) -> tuple[float, float]:
        return self.settings.u_bounds

    @property
    def du_max(self) -> float:
        return self.settings.du_max

    @property
    def solver_name(self) -> str:
        return self.settings.solver

    @property
    def shooting(self) -> str:
        return self.solver.shooting

    @property
    def expand(self) -> bool:
        return self.solver.expand

    @property
    def y_bounds(self) -> tuple[float, float] | None:
        return self.settings.y_bounds

    @property
    def tighten(self) -> bool:
        return self.settings.tighten

    @property
    def n_x(self) -> int:
        return self.problem.n_x

    @property
    def n_d(self) -> int:
        """Measured inputs the model reads besides the command."""
        return self.problem.n_d

    def reset(self) -> None:
        """Forget the warm start and the statistics."""
        self._last, self.stats = None, MPCStats()

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
        return np.broadcast_to(h, (self.horizon,)) / self.problem.y_scale.y_span

    def _solve(self, x: ArrayLike, reference_window: ArrayLike, u_prev: float | None, measured=None) -> float:
        pb = self.problem
        x, ref = pb.state(x), pb.reference(reference_window)
        if u_prev is None:
            u_prev = self._last.u if self._last is not None else self.settings.u_ref
        D = pb.measured(measured)
        t0 = time.perf_counter()
        solution = self.solver.solve(x, ref, float(u_prev), D, self._last, self._online_h)
        self.stats.solve_times.append(time.perf_counter() - t0)
        self.stats.iterations.append(solution.iterations)
        self.stats.success.append(solution.success)
        self._last = solution
        return solution.u

    def predicted_output(self) -> NDArray[np.float64]:
        """Outputs the last solution predicts over the horizon."""
        if self._last is None:
            raise ExportError("Call solve() first.")
        return self.solver.predicted_output(self._last)
