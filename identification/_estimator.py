"""A scikit-learn-style estimator around :func:`identify`."""

from __future__ import annotations

import numpy as np

from physics import Series
from physics.data import BaseEstimator

from ._checks import data_rate
from ._errors import IdentificationError
from ._identify import identify
from ._result import FitResult
from ._solver_settings import SolverSettings


class PhysicsEstimator(BaseEstimator):
    """Fit a physics model (a spec string) to trajectories; predict outputs.

    ``__init__`` stores settings only; :meth:`fit` validates, identifies and
    sets ``result_`` (:class:`FitResult`), ``model_`` (the fitted
    :class:`physics.Series`) and ``params_`` (name -> value).

    Parameters
    ----------
    model : str
        Model spec, e.g. ``"lag+boucwen+linear"``.
    rate_hz : float, optional
        The model's sample rate; trajectories must be sampled at it. Default: the
        trajectories' own rate (from their time stamps).
    starts, fixed, free, x0, max_iter, max_wall_time, seed, allow_failure
        Passed to :func:`identify`.

    Examples
    --------
    >>> import numpy as np
    >>> from physics import Series
    >>> from identification import PhysicsEstimator
    >>> truth = Series.from_spec("lag+linear", dt=0.04).set_params(**{"lag.time_constant_s": 0.2})
    >>> u = 3 - 3 * np.cos(2 * np.pi * 0.2 * np.arange(0, 20, 0.04))
    >>> class Run:
    ...     pass
    >>> run = Run(); run.u = u; run.y = truth.simulate(u)
    >>> est = PhysicsEstimator("lag+linear", rate_hz=25).fit([run])  # run has no time stamps
    >>> round(est.params_["lag.time_constant_s"], 4)
    0.2
    >>> round(est.score([run]), 6)  # R², as scikit-learn's regressors
    1.0
    """

    def __init__(self, model: str = "lag+boucwen+linear", rate_hz: float | None = None, starts: int | None = None,
                 fixed=None, free=None, x0="steady", max_iter: int = 3000, max_wall_time: float | None = None,
                 seed: int = 0,
                 allow_failure: bool = False):
        self.model = model
        self.rate_hz = rate_hz
        self.starts = starts
        self.fixed = fixed
        self.free = free
        self.x0 = x0
        self.max_iter = max_iter
        self.max_wall_time = max_wall_time
        self.seed = seed
        self.allow_failure = allow_failure

    def fit(self, trajectories) -> "PhysicsEstimator":
        rate = self.rate_hz if self.rate_hz is not None else data_rate(trajectories)
        if not (np.isfinite(rate) and rate > 0):
            raise IdentificationError(f"rate_hz must be > 0. Got {rate} instead.")
        model = Series.from_spec(self.model, dt=1.0 / rate)
        self.result_: FitResult = identify(
            model, trajectories, fixed=self.fixed, free=self.free, x0=self.x0,
            starts=self.starts, seed=self.seed, allow_failure=self.allow_failure,
            solver=SolverSettings(max_iter=self.max_iter, max_wall_time=self.max_wall_time))
        self.model_ = self.result_.model()
        self.params_ = dict(self.result_.parameters)
        return self

    def _check_fitted(self) -> None:
        if not hasattr(self, "result_"):
            raise IdentificationError(
                "This PhysicsEstimator is not fitted yet; call fit(trajectories) first.")

    def predict(self, data, warmup=None) -> np.ndarray | list[np.ndarray]:
        """Output for a trajectory (its ``u``), an input array, or a list of trajectories.

        ``warmup``: the measured samples just before ``data`` (a Trajectory or ``(u_w, y_w)``)
        set the state (:meth:`physics.Series.simulate`); for one run only.
        """
        self._check_fitted()
        if warmup is not None:
            if isinstance(data, (list, tuple)):
                raise IdentificationError("A warm-up window belongs to one run; predict the runs one at a time.")
            return self.model_.simulate(np.asarray(getattr(data, "u", data), dtype=float), warmup=warmup)
        if hasattr(data, "u"):
            return self.model_.simulate(np.asarray(data.u, dtype=float))
        if isinstance(data, (list, tuple)) and data and hasattr(data[0], "u"):
            return [self.model_.simulate(np.asarray(t.u, dtype=float)) for t in data]
        return self.model_.simulate(np.asarray(data, dtype=float))

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self.get_params(deep=False).items())
        return f"PhysicsEstimator({args})"
