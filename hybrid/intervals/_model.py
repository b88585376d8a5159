"""Any forward model with intervals: fitted on folds of whole runs, calibrated on the runs left out."""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import numpy as np
from numpy.typing import NDArray

from physics.data import BaseEstimator, DataError, NotFittedError, Trajectory, check_warmup_length, warmup_split

from ._conditions import condition_folds, run_conditions
from ._conformal import ConformalIntervals, HeldOut, Interval, check_level

__all__ = ["ConformalModel", "held_out_predictions", "predict_with"]


def predict_with(model, traj: Trajectory, window: Trajectory | None = None) -> NDArray[np.float64]:
    """A forward model's free run over ``traj`` from the state ``window`` sets: ``predict`` of an
    estimator, ``simulate`` of a physics :class:`~physics.Series`."""
    kwargs = {} if window is None else {"warmup": window}
    if hasattr(model, "predict"):
        return np.asarray(model.predict(traj, **kwargs), dtype=float).ravel()
    return np.asarray(model.simulate(traj.u, **kwargs), dtype=float).ravel()


def held_out_predictions(models: Sequence, folds: Sequence[Sequence[int]], runs: Sequence[Trajectory],
                         warmup: int = 0, conditions: Sequence[str] | None = None,
                         fits: Sequence[Sequence[int]] | None = None) -> list[HeldOut]:
    """Each fold's fitted model predicts the runs held out of its fit (after their first ``warmup``
    samples, which set its state); ``conditions`` names each run's condition where whole conditions
    were left out; ``fits`` the runs each fold was fitted on (default: every run it does not hold out)."""
    out = []
    for k, (model, held) in enumerate(zip(models, folds)):
        trained_on = ([runs[i] for i in fits[k]] if fits is not None
                      else [r for i, r in enumerate(runs) if i not in set(held)])
        for i in held:
            window, rest = warmup_split(runs[i], warmup)
            out.append(HeldOut(rest, predict_with(model, rest, window), trained_on,
                               None if conditions is None else conditions[i]))
    return out


def _clone(model):
    if not hasattr(model, "get_params") or not hasattr(model, "fit"):
        raise DataError(f"ConformalModel refits its model on folds of the runs, so the model must be an unfitted "
                        f"estimator (fit and get_params); got {type(model).__name__}. For a model fitted elsewhere, "
                        "calibrate with ConformalIntervals().fit(train, held_out) on predictions of runs it did not see.")
    return type(model)(**model.get_params(deep=False))


class ConformalModel(BaseEstimator):
    """A forward model with split-conformal intervals calibrated on whole runs it was not fitted on.

    ``fit(runs)`` fits a copy of ``model`` on each fold of the runs (leave one condition out where the
    runs carry one, :func:`run_conditions`; else leave one run out, at most ``max_folds`` folds), scores the runs held out of each (:class:`ConformalIntervals`), then fits
    ``model`` on all runs. The calibration costs one fit per fold.

    Parameters
    ----------
    model : estimator
        Unfitted: ``LearnedModel``, ``HybridModel``, ``NeuralODEHybrid``, ``PhysicsEstimator``, a peer.
    level : float
        Default interval level (0.9).
    max_folds : int
        At most this many folds (runs dealt round-robin beyond it).
    warmup : int
        Each held-out run's first ``warmup`` samples set the state, as in ``predict(..., warmup=...)``.
    spread : float
        Width growth per radius of input distance beyond the data (:class:`ConformalIntervals`).
    group : str, optional
        The runs' condition: a ``meta`` key or a file-name pattern (:func:`run_conditions`; default: a
        condition the runs' ``meta`` carries, else none).

    Examples
    --------
    >>> from physics.virtual import VirtualCatheter  # doctest: +SKIP
    >>> cm = ConformalModel(PhysicsEstimator("backlash+linear")).fit(runs)  # doctest: +SKIP
    >>> y, lo, hi, outside, distance = cm.predict(test, interval=0.9)  # doctest: +SKIP
    """

    def __init__(self, model, level: float = 0.9, max_folds: int = 10, warmup: int = 0, spread: float = 1.0,
                 group: str | None = None):
        self.model = model
        self.group = group
        self.level = level
        self.max_folds = max_folds
        self.warmup = warmup
        self.spread = spread

    def fit(self, data: Trajectory | Iterable[Trajectory]) -> ConformalModel:
        from identification.discovery import run_folds

        runs = [data] if isinstance(data, Trajectory) else list(data)
        check_level(self.level)
        check_warmup_length(self.warmup)
        labels, _ = run_conditions(runs, self.group)
        folds = condition_folds(labels) if labels is not None else run_folds(runs, max_folds=self.max_folds)[0]
        models = [_clone(self.model).fit([r for i, r in enumerate(runs) if i not in set(f)]) for f in folds]
        held = held_out_predictions(models, folds, runs, self.warmup, labels)
        self.intervals_ = ConformalIntervals(self.level, self.spread).fit(runs, held)
        self.model_ = _clone(self.model).fit(runs)
        self.direction = getattr(self.model_, "direction", "forward")
        return self

    @classmethod
    def from_fitted(cls, model, intervals: ConformalIntervals) -> ConformalModel:
        """A model fitted elsewhere with intervals calibrated on runs it was not fitted on."""
        out = cls(model, level=intervals.level, spread=intervals.spread)
        out.model_, out.intervals_, out.direction = model, intervals, getattr(model, "direction", "forward")
        return out

    def predict(self, data: Trajectory, warmup: Trajectory | None = None,
                interval: float | None = None) -> NDArray[np.float64] | Interval:
        """The prediction, or with ``interval=level`` an :class:`Interval` ``(y, lo, hi, outside, distance)``."""
        if not hasattr(self, "model_"):
            raise NotFittedError("This ConformalModel is not fitted yet. Call fit(runs) first.")
        y = predict_with(self.model_, data, warmup)
        if interval is None:
            return y
        return self.intervals_.interval(y, data.u, data.dt, check_level(interval), window=warmup)
