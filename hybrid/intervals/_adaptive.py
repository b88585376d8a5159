"""Intervals that learn from the tip measured now and then: adaptive conformal inference online.

Offline, a new run's band must cover its unknown offset (:mod:`._shift`). Once the output is measured,
the offset is known: ``j`` samples after a measured residual ``r_k`` the band is centred on
``y_hat + rho_j r_k``, ``rho_j`` the least-squares coefficient of the error ``j`` samples ahead on the
error now over the held-out runs (1 for an offset that stays, 0 for white noise, where a measurement
says nothing of the next sample and the band stays as wide as the noise). Its half-width covers what
that forecast misses, calibrated from the held-out runs lag by lag, for ``j = 1 .. every`` (later
samples take lag ``every``'s):

    s_j = | e_{t+j} - rho_j e_t |    over every t of every held-out run,

so the band is narrow just after a measurement and widens until the next.

Whether those scores hold on the run at hand is what adaptive conformal inference (Gibbs and Candes
2021) checks: at each measurement, a miss of the current band raises the working level and a hit
lowers it,

    L_{k+1} = L_k + gamma * (miss_k - (1 - level)),    half-width = quantile(s_j, L_k) * sigma,

so over a long operation the share of measured samples outside the band tends to ``1 - level`` even
where the calibration was wrong (Gibbs and Candes bound the gap by ``(L_max + gamma) / (gamma K)``
after K measurements). Their band is infinite above ``L = 1``; a controller needs a finite one, so
beyond 1 the half-width grows by the largest score of its lag with every ``1 - level`` of working
level, which still grows past any error the run makes, up to :data:`MAX_STEPS` such steps.
Below 0 the band has no width and the level stops. Before the first measurement the band is the
offline one. ``gamma = 0.05`` lets one miss raise the level by 4.5 points, so that a run of a few
dozen measurements can correct a calibration that is far off (0.01 to 0.2 on the real splits:
``docs/benchmarks.md``).

The state is explicit (:class:`AdaptiveState`), passed in and out, so a controller or an estimator
carries it like any other state.
"""

from __future__ import annotations

from typing import NamedTuple

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike, NDArray

from physics.data import DataError, NotFittedError

from ._conformal import ConformalIntervals, Interval, check_level

__all__ = ["AdaptiveIntervals", "AdaptiveState", "lag_scores", "MAX_STEPS", "QUANTILES"]

#: Most steps of the largest calibration score added above a working level of 1.
MAX_STEPS = 100


class AdaptiveState(NamedTuple):
    """The online band's state: the working level, the last measured residual (output units), the
    samples since that measurement (0: at it) and how many measurements were taken."""

    level: float
    offset: float
    since: int
    measured: int


#: Points of each lag's score distribution kept (its quantiles): the table stays small for any run length.
QUANTILES = 1001


def lag_scores(residuals, every: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``(table, rho)``: ``rho[j - 1]`` the least-squares coefficient of ``e_{t+j}`` on ``e_t`` (in [0, 1])
    and row ``j - 1`` of the ``(every, QUANTILES)`` table the quantiles (0 to 1) of
    ``|e_{t+j} - rho_j e_t|``, over every ``t`` of every run in ``residuals`` (one array each); a lag no
    run is long enough for repeats the last one that is."""
    runs = [np.asarray(r, dtype=float).ravel() for r in residuals]
    grid = np.linspace(0, 1, QUANTILES)
    table, rho = [], []
    for j in range(1, int(every) + 1):
        now = np.concatenate([r[:-j] for r in runs if r.size > j] or [np.zeros(0)])
        ahead = np.concatenate([r[j:] for r in runs if r.size > j] or [np.zeros(0)])
        if now.size < 2:
            break
        power = float(now @ now)
        rho.append(float(np.clip((now @ ahead) / power, 0.0, 1.0)) if power > 0 else 0.0)
        table.append(np.quantile(np.abs(ahead - rho[-1] * now), grid, method="higher"))
    if not table:
        raise DataError("The held-out runs are too short for a lag of one sample: no lag scores.")
    table += [table[-1]] * (int(every) - len(table))
    rho += [rho[-1]] * (int(every) - len(rho))
    return np.array(table), np.array(rho)


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
        ``(every, QUANTILES)``: the quantiles of its held-out runs' scores at each lag (output units; the
        band multiplies them by the width factor ``sigma``, 1 inside the data), :func:`lag_scores`.
    offline_ : float
        The offline half-width (before ``sigma``) at ``level_``: the band before the first measurement.

    Examples
    --------
    >>> online = AdaptiveIntervals(every=25).fit(intervals)  # doctest: +SKIP
    >>> state = online.update(online.initial(), y_measured - y_hat)  # doctest: +SKIP
    >>> state = online.advance(state)  # doctest: +SKIP  (one sample later)
    >>> centre, half = y_hat + online.centre(state), online.half_width(state)  # doctest: +SKIP
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
        self.scores_, self.rho_ = lag_scores(intervals.errors_, int(self.every))
        self.intervals_, self.offline_ = intervals, intervals.quantile(self.level_)
        return self

    def initial(self) -> AdaptiveState:
        """The state before any measurement: the offline band."""
        self._check_fitted()
        return AdaptiveState(self.level_, 0.0, 0, 0)

    def _top(self) -> float:
        """The highest working level: :data:`MAX_STEPS` steps above 1."""
        return 1.0 + MAX_STEPS * (1 - self.level_)

    def quantile(self, level: float, lag: int) -> float:
        """The scores' quantile at lag ``lag`` (>= 1) and working ``level`` (0 at 0; above 1, the largest
        score once more for every ``1 - level`` beyond it)."""
        self._check_fitted()
        row = self.scores_[min(max(int(lag), 1), self.scores_.shape[0]) - 1]
        level = float(np.clip(level, 0.0, self._top()))
        if level > 1:
            return float(row[-1] * (1 + (level - 1) / (1 - self.level_)))
        return float(row[int(np.ceil(level * (row.size - 1)))])

    def centre(self, state: AdaptiveState, ahead: int = 0) -> float:
        """The band's centre relative to the prediction, ``ahead`` samples after the state's:
        ``rho_j`` times the last measured residual (0 before the first measurement)."""
        self._check_fitted()
        if not state.measured:
            return 0.0
        lag = min(max(state.since + int(ahead), 1), self.rho_.size)
        return float(self.rho_[lag - 1] * state.offset)

    def half_width(self, state: AdaptiveState, sigma: float | ArrayLike = 1.0, ahead: int = 0):
        """The half-width in output units at width factor ``sigma``, ``ahead`` samples after the state's
        (the offline band before the first measurement)."""
        q = (self.offline_ if not state.measured else
             self.quantile(state.level, state.since + int(ahead)))
        return q * np.asarray(sigma, dtype=float)

    def advance(self, state: AdaptiveState, samples: int = 1) -> AdaptiveState:
        """The state ``samples`` later without a measurement."""
        return state._replace(since=state.since + int(samples))

    def update(self, state: AdaptiveState, residual: float, sigma: float = 1.0) -> AdaptiveState:
        """The state after measuring ``residual = y_measured - y_hat`` at the state's sample (width factor
        ``sigma``): the working level moves by the miss or hit of the band there, the centre moves to
        the residual."""
        self._check_fitted()
        residual = float(residual)
        if not np.isfinite(residual):
            raise DataError(f"A measured residual must be finite; got {residual!r}. Drop the sample instead.")
        level = state.level
        if state.measured:  # the first measurement scores the offline band, not an online one
            miss = float(abs(residual - self.centre(state)) > self.half_width(state, sigma))
            level = float(np.clip(level + self.gamma * (miss - (1 - self.level_)), 0.0, self._top()))
        return AdaptiveState(level, residual, 0, state.measured + 1)

    def function(self) -> ca.Function:
        """``Function('online_band', [level, offset, since], [centre, half_width])``: the online band
        for an export or a C controller: its centre (relative to the prediction) and half-width (before
        ``sigma``) ``since`` >= 1 samples after a measured residual ``offset``, at working ``level``
        (:meth:`update_function` moves it). The lookups are linear interpolations of the table over
        the working level (exact at its :data:`QUANTILES` points), clipped to ``[0, 1]``; above 1 the
        largest score grows as in :meth:`quantile`."""
        self._check_fitted()
        lags = np.arange(1, self.scores_.shape[0] + 1, dtype=float)
        grid = np.linspace(0, 1, QUANTILES)
        level, offset, since = ca.SX.sym("level"), ca.SX.sym("offset"), ca.SX.sym("since")
        lag = ca.fmin(ca.fmax(since, 1), lags[-1])
        if lags.size > 1:
            table = ca.interpolant("lag_scores", "linear", [grid, lags], self.scores_.T.ravel(order="F").tolist())
            rho = ca.interpolant("rho", "linear", [lags], self.rho_.tolist())(lag)
            top = ca.interpolant("top", "linear", [lags], self.scores_[:, -1].tolist())(lag)
            inside = table(ca.vertcat(ca.fmin(ca.fmax(level, 0), 1), lag))
        else:
            rho, top = float(self.rho_[0]), float(self.scores_[0, -1])
            inside = ca.interpolant("lag_scores", "linear", [grid], self.scores_[0].tolist())(ca.fmin(ca.fmax(level, 0), 1))
        half = ca.if_else(level > 1, top * (1 + (level - 1) / (1 - self.level_)), inside)
        return ca.Function("online_band", [level, offset, since], [rho * offset, half],
                           ["level", "offset", "since"], ["centre", "half_width"])

    def update_function(self) -> ca.Function:
        """``Function('online_level', [level, residual, centre, half_width], [level_next])``: the ACI step
        of :meth:`update` (after the first measurement) for an export: the working level after a
        measured ``residual`` against the band ``centre +- half_width`` (``sigma`` included)."""
        self._check_fitted()
        level, r, c, h = ca.SX.sym("level"), ca.SX.sym("residual"), ca.SX.sym("centre"), ca.SX.sym("half_width")
        miss = ca.fabs(r - c) > h
        nxt = ca.fmin(ca.fmax(level + self.gamma * (miss - (1 - self.level_)), 0), self._top())
        return ca.Function("online_level", [level, r, c, h], [nxt], ["level", "residual", "centre", "half_width"],
                           ["level_next"])

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
            if t:
                state = self.advance(state)
            centre[t], half[t], drift[t] = self.centre(state), self.half_width(state, sigma[t]), drifted
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
