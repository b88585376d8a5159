"""Intervals that learn from the tip measured now and then: adaptive conformal inference online.

Offline, a new run's band must cover its unknown offset (:mod:`._shift`). Once the output is measured,
the offset is known: the band is centred on the last measured residual, ``y_hat + r_k``, and its
half-width needs to cover only how far the error moves until the next measurement. That distance is
calibrated from the held-out runs of the offline calibration, as scores at lags up to ``every``
samples:

    s_t = | e_t - e_k |,    k the last measurement before t (every ``every`` samples).

Whether those scores hold on the run at hand is what adaptive conformal inference (Gibbs and Candes
2021) checks: at each measurement, a miss of the current band raises the working level and a hit
lowers it,

    L_{k+1} = L_k + gamma * (miss_k - (1 - level)),    half-width_k = quantile(s, L_k) * sigma,

so over a long operation the share of measured samples outside the band tends to ``1 - level`` even
where the calibration was wrong (the bound is ``(1 + gamma) / (gamma K)`` after K measurements). The
working level is kept in [0, 1]: at 1 the band is the largest calibration score. Before the first
measurement the band is the offline one. ``gamma = 0.05`` lets one miss raise the level by 4.5
points, so that a run of a few dozen measurements can correct a calibration that is far off.

The state is explicit (:class:`AdaptiveState`), passed in and out, so a controller or an estimator
carries it like any other state.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from physics.data import DataError, NotFittedError

from ._conformal import ConformalIntervals, Interval, check_level

__all__ = ["AdaptiveIntervals", "AdaptiveState", "lag_scores"]


class AdaptiveState(NamedTuple):
    """The online band's state: the working level, the centre (the last measured residual, in output
    units), the half-width before the width factor ``sigma``, and how many measurements were taken."""

    level: float
    offset: float
    half_width: float
    measured: int


def lag_scores(residuals: ArrayLike, every: int) -> NDArray[np.float64]:
    """``|e_t - e_k|`` for ``t`` not measured, ``k`` the last measured sample before ``t``
    (measurements at samples 0, every, 2 every, ...)."""
    e = np.asarray(residuals, dtype=float).ravel()
    t = np.arange(1, e.size)
    return np.abs(e[t] - e[((t - 1) // every) * every])


class AdaptiveIntervals:
    """Online intervals: centred on the last measured residual, their width adapted from the misses.

    Parameters
    ----------
    every : int
        Samples between measurements the lag scores are calibrated for (the measurements themselves may
        come at any samples).
    gamma : float
        ACI step: how far one miss (or hit) moves the working level.
    level : float, optional
        Target coverage (default: the offline calibration's).

    Attributes
    ----------
    intervals_ : ConformalIntervals
        The offline calibration.
    scores_ : ndarray
        Sorted lag scores of its held-out runs (in units of the width factor ``sigma``).
    offline_ : float
        The offline half-width (before ``sigma``) at ``level_``: the band before the first measurement.

    Examples
    --------
    >>> online = AdaptiveIntervals(every=25).fit(intervals)  # doctest: +SKIP
    >>> state = online.initial()  # doctest: +SKIP
    >>> state = online.update(state, y_measured - y_hat)  # doctest: +SKIP
    >>> centre, half = y_hat + state.offset, online.half_width(state)  # doctest: +SKIP
    """

    def __init__(self, every: int = 25, gamma: float = 0.05, level: float | None = None):
        self.every = every
        self.gamma = gamma
        self.level = level

    def fit(self, intervals: ConformalIntervals) -> AdaptiveIntervals:
        """Lag scores from the held-out runs of an offline calibration."""
        if isinstance(self.every, bool) or not isinstance(self.every, (int, np.integer)) or self.every < 1:
            raise DataError(f"every must be a whole number of samples >= 1 between measurements. "
                            f"Got {self.every!r} instead.")
        if isinstance(self.gamma, bool) or not isinstance(self.gamma, (int, float)) or not 0 < self.gamma < 1:
            raise DataError(f"gamma must be a number between 0 and 1 (e.g. 0.05). Got {self.gamma!r} instead.")
        if not isinstance(intervals, ConformalIntervals) or not hasattr(intervals, "residuals_"):
            raise DataError("AdaptiveIntervals.fit needs calibrated ConformalIntervals (a model folder's "
                            "intervals.json, or ConformalIntervals().fit(train, held_out)).")
        self.level_ = check_level(intervals.level if self.level is None else self.level)
        scores = [lag_scores(r, int(self.every)) for r in intervals.residuals_]
        scores = np.sort(np.concatenate([s for s in scores if s.size] or [np.zeros(0)]))
        if scores.size < 2:
            raise DataError(f"The held-out runs are too short for lags of {self.every} samples: no lag scores. "
                            "Measure more often (a smaller every) or calibrate on longer runs.")
        self.intervals_, self.scores_ = intervals, scores
        self.offline_ = intervals.quantile(self.level_)
        return self

    def initial(self) -> AdaptiveState:
        """The state before any measurement: the offline band."""
        self._check_fitted()
        return AdaptiveState(self.level_, 0.0, self.offline_, 0)

    def quantile(self, level: float) -> float:
        """The lag scores' quantile at the working ``level`` (the largest at 1, 0 at 0)."""
        self._check_fitted()
        level = float(np.clip(level, 0.0, 1.0))
        return float(np.quantile(self.scores_, level, method="higher")) if level > 0 else 0.0

    def update(self, state: AdaptiveState, residual: float, sigma: float = 1.0) -> AdaptiveState:
        """The state after measuring ``residual = y_measured - y_hat`` at a sample of width factor ``sigma``:
        the working level moves by the miss or hit of the current band, the centre moves to the residual."""
        self._check_fitted()
        residual = float(residual)
        if not np.isfinite(residual):
            raise DataError(f"A measured residual must be finite; got {residual!r}. Drop the sample instead.")
        level = state.level
        if state.measured:  # the first measurement scores the offline band, not this one's
            miss = float(abs(residual - state.offset) > state.half_width * sigma)
            level = float(np.clip(level + self.gamma * (miss - (1 - self.level_)), 0.0, 1.0))
        return AdaptiveState(level, residual, self.quantile(level), state.measured + 1)

    def half_width(self, state: AdaptiveState, sigma: float | ArrayLike = 1.0):
        """The band's half-width in output units at width factor ``sigma``."""
        return state.half_width * np.asarray(sigma, dtype=float)

    def run(self, y_hat: ArrayLike, u: ArrayLike, dt: float, y: ArrayLike,
            measured: ArrayLike | None = None) -> Interval:
        """Replay one run: the band of each sample before that sample's measurement is taken, then the
        update where ``measured`` (a boolean mask; default every ``every``-th sample from the first).
        ``outside`` also flags the samples after a measured residual beyond the offline band: the run
        has drifted where the calibration did not see a run go."""
        self._check_fitted()
        y_hat, y = np.asarray(y_hat, dtype=float).ravel(), np.asarray(y, dtype=float).ravel()
        if y.shape != y_hat.shape:
            raise DataError(f"The measurements ({y.size}) and the prediction ({y_hat.size}) differ in length.")
        mask = np.zeros(y.size, bool)
        if measured is None:
            mask[:: int(self.every)] = True
        else:
            mask = np.asarray(measured, dtype=bool).ravel()
            if mask.shape != y.shape:
                raise DataError(f"measured must be a boolean mask as long as the run ({y.size}); got {mask.size}.")
        offline = self.intervals_.interval(y_hat, u, dt, self.level_)
        sigma = offline.half_width / max(self.offline_, 1e-300)
        centre, half, drift = np.empty_like(y), np.empty_like(y), np.zeros(y.size, bool)
        state, drifted = self.initial(), False
        for t in range(y.size):
            centre[t], half[t], drift[t] = state.offset, state.half_width * sigma[t], drifted
            if mask[t] and np.isfinite(y[t]):
                state = self.update(state, y[t] - y_hat[t], sigma[t])
                drifted = abs(state.offset) > offline.half_width[t]
        return Interval(y_hat, y_hat + centre - half, y_hat + centre + half, offline.outside | drift,
                        offline.distance)

    def _check_fitted(self) -> None:
        if not hasattr(self, "scores_"):
            raise NotFittedError("These online intervals are not fitted yet. Call fit(intervals) first.")

    def __repr__(self) -> str:
        return f"AdaptiveIntervals(every={self.every}, gamma={self.gamma})"
