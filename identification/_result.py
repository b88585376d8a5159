"""The result of :func:`identify`: parameters, their standard errors and the fit's quality."""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field

import numpy as np

from physics import Series

from ._checks import check_trajectories


def _finite_or_none(v: float):
    return float(v) if math.isfinite(v) else None


def pooled_rmse(errors: list[np.ndarray]) -> tuple[float, tuple[float, ...]]:
    """Root-mean-square over all samples, and per trajectory."""
    per = tuple(float(np.sqrt(np.mean(e**2))) for e in errors)
    n = sum(e.size for e in errors)
    return float(np.sqrt(sum(float(e @ e) for e in errors) / n)), per


@dataclass(frozen=True)
class FitResult:
    """Parameters fitted by :func:`identify`, with standard errors and diagnostics.

    Attributes
    ----------
    spec : str
        The model's spec, e.g. ``"lag+boucwen+linear"`` (``"model"`` in :meth:`to_dict`).
    dt : float
        The model's sample time (s).
    parameters : dict of str to float
        Every parameter of the model (fitted and held), by name.
    standard_errors : dict of str to float
        For the fitted parameters: ``sqrt(diag(sigma^2 (J^T J)^-1))`` with ``J``
        the Jacobian of the residuals at the optimum and ``sigma^2`` the residual
        variance. ``inf`` where the data do not determine the parameter
        (``covariance_singular`` is then True), NaN for a parameter at a bound.
    units : dict of str to str
        Unit of each parameter.
    fixed : dict of str to float
        The parameters held (not fitted) and their values.
    train_rmse, train_rmse_per_trajectory
        Output RMSE on the training data (output units): pooled over all
        samples, and per trajectory.
    status : str
        The solver's return status (IPOPT ``return_status``).
    success : bool
        False when the solver did not converge (only with ``allow_failure=True``).
    iterations, wall_time_s, n_samples, n_trajectories
        Solver iterations (of the best start), total wall time (s) including
        the initial guesses and all starts, data size.
    method : str
        ``"single"`` or ``"multiple"`` shooting, or ``"lsq"`` (exact linear
        least squares: Preisach weights).
    noise_std : float
        Residual standard deviation (output units), the ``sigma`` above.
    starts : tuple of dict
        ``status``, ``cost`` and ``iterations`` of each start, the best marked.

    Examples
    --------
    >>> import numpy as np
    >>> from physics import Series
    >>> from identification import identify
    >>> model = Series.from_spec("linear")
    >>> u = np.linspace(0, 5, 50)
    >>> class Run:  # any object with .u and .y
    ...     pass
    >>> run = Run(); run.u = u; run.y = 2.0 * u + 1.0
    >>> fit = identify(model, [run])
    >>> round(fit.parameters["linear.gain"], 6), fit.success
    (2.0, True)
    """

    spec: str
    dt: float
    parameters: dict[str, float]
    standard_errors: dict[str, float]
    units: dict[str, str]
    fixed: dict[str, float]
    train_rmse: float
    train_rmse_per_trajectory: tuple[float, ...]
    status: str
    success: bool
    iterations: int
    wall_time_s: float
    n_samples: int
    n_trajectories: int
    method: str = "single"
    noise_std: float = float("nan")
    covariance_singular: bool = False
    at_bounds: tuple[str, ...] = ()
    initial_parameters: dict[str, float] = field(default_factory=dict)
    initial_states: tuple[tuple[float, ...], ...] = ()
    starts: tuple[dict, ...] = ()
    fitted_model: Series | None = field(default=None, repr=False, compare=False)

    # -- the fitted model --------------------------------------------------------
    def model(self) -> Series:
        """A new :class:`physics.Series` with the fitted parameters."""
        base = self.fitted_model if self.fitted_model is not None else \
            Series.from_spec(self.spec, dt=self.dt)
        out = copy.deepcopy(base)
        out.set_params(**self.parameters)
        return out

    def predict(self, u, x0=None) -> np.ndarray:
        """Output of the fitted model for the input path ``u`` (steady start by default)."""
        return self.model().simulate(np.asarray(u, dtype=float), x0=x0)

    def rmse(self, trajectories) -> tuple[float, tuple[float, ...]]:
        """Pooled and per-trajectory output RMSE of the fitted model on other data."""
        model = self.model()
        records = check_trajectories(trajectories, self.dt)
        return pooled_rmse([model.simulate(r.u) - r.y for r in records])

    # -- reporting ---------------------------------------------------------------
    def to_dict(self) -> dict:
        """JSON-ready dictionary; non-finite standard errors become ``None``.

        ``"series"`` is the fitted model's :meth:`physics.Series.to_dict` (dt, every
        block's structural settings and the parameters): ``Series.from_dict`` rebuilds it.
        """
        return {
            "model": self.spec,
            "dt": self.dt,
            "series": self.model().to_dict(),
            "parameters": dict(self.parameters),
            "standard_errors": {k: _finite_or_none(v) for k, v in self.standard_errors.items()},
            "units": dict(self.units),
            "fixed": dict(self.fixed),
            "train_rmse": self.train_rmse,
            "train_rmse_per_trajectory": list(self.train_rmse_per_trajectory),
            "status": self.status,
            "success": self.success,
            "iterations": self.iterations,
            "wall_time_s": self.wall_time_s,
            "n_samples": self.n_samples,
            "n_trajectories": self.n_trajectories,
            "method": self.method,
            "noise_std": self.noise_std,
            "covariance_singular": self.covariance_singular,
            "at_bounds": list(self.at_bounds),
            "initial_parameters": dict(self.initial_parameters),
            "starts": [dict(s) for s in self.starts],
        }

    def report(self, max_rows: int = 30) -> str:
        """A short human-readable table of the fit."""
        lines = [f"model {self.spec}  ({self.n_trajectories} trajectories, "
                 f"{self.n_samples} samples at {1 / self.dt:.4g} Hz)"]
        names = list(self.parameters)
        width = max(len(n) for n in names) if names else 0
        for name in names[:max_rows]:
            value = self.parameters[name]
            if name in self.fixed:
                err = "(fixed)"
            else:
                se = self.standard_errors.get(name, float("nan"))
                err = f"+/- {se:.3g}" if math.isfinite(se) else "+/- inf (not identifiable)" if se == math.inf \
                    else "(at bound)" if name in self.at_bounds else "(unavailable)"
            lines.append(f"  {name:<{width}}  {value:12.6g} {err:<16} {self.units.get(name, '')}")
        if len(names) > max_rows:
            lines.append(f"  ... {len(names) - max_rows} more parameters")
        lines.append(f"train RMSE {self.train_rmse:.4g}  (noise std {self.noise_std:.4g})")
        flag = "" if self.success else "  ** NOT CONVERGED: do not trust these numbers **"
        lines.append(f"status {self.status}  iterations {self.iterations}  "
                     f"wall time {self.wall_time_s:.2f} s{flag}")
        if self.covariance_singular:
            lines.append("warning: J^T J is singular: some parameters are not identifiable "
                         "from these data (standard error inf)")
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.report()
