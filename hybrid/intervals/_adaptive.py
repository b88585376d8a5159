"""Intervals that learn from the tip measured now and then: adaptive conformal inference online.

Offline, a new run's band must cover its unknown offset (:mod:`._shift`). Once the output is measured,
the offset is no longer unknown: the measured residuals estimate it, and the last one says where the
error is now. ``j`` samples after measurement ``k`` the band is centred on ``y_hat + e_hat``, the
forecast of :mod:`._forecast` (the last residual and the running offset, weighted by least squares
on the calibration's held-out runs, each replayed as if measured every ``every`` samples), so it is
centred on the run at hand rather than on the model. Its half-width covers what that forecast
misses, calibrated on the same replays lag by lag for ``j = 1 .. every`` (later samples take lag
``every``'s): narrow just after a measurement, widening until the next, and only as wide as what
moves within a run (the offset the offline band must cover is measured out).

A run's forecast misses are larger or smaller than the held-out runs' as a whole, so the scores are
multiplied by the run's scale: the mean of its misses over the held-out runs' mean at their lag, with
the calibration's scale (1) counted as ``prior`` measurements. How many is read from the held-out
runs themselves (:func:`._forecast.scale_prior`): where their mean misses differ from run to run
well beyond their noise within a run, a run soon trusts its own misses (NiTi's held-out runs, at
different frequencies: 0.6-1.7 measurements); where they do not, the calibration's scale stands.
After a run's first measurements the scores are also multiplied by the held-out runs' start factor
(:func:`._forecast.start_factor`: their misses there over their later ones), and the run's misses
are judged against it, so a start every run makes neither raises the level nor the scale.

Whether those scores hold on the run at hand is what adaptive conformal inference (Gibbs and Candes
2021) checks: at each measurement, a miss of the current band raises the working level and a hit
lowers it,

    L_{k+1} = L_k + gamma * (miss_k - (1 - level)),    half-width = quantile(s_j, L_k) * sigma,

so over a long operation the share of measured samples outside the band tends to ``1 - level`` even
where the calibration was wrong (Gibbs and Candes bound the gap by ``(L_max + gamma) / (gamma K)``
after K measurements). The bound holds whatever the band's centre, as long as it is computed from
the measurements before the one scored, so centring on the forecast keeps it. Their band is infinite
above ``L = 1``; a controller needs a finite one, so beyond 1 the half-width grows by the largest
score of its lag with every ``1 - level`` of working level, which still grows past any error the run
makes, up to :data:`MAX_STEPS` such steps. Below 0 the band has no width and the level stops. Before
the first measurement the band is the offline one.

The guarantee is for the measured samples, the last lag. The samples between share the working
level, read in their own lag's scores; where a run's error moves unlike the held-out runs', their
coverage can differ from the measured samples' (``benchmarks/intervals.py`` reports the coverage of
every sample).

The state is explicit (:class:`AdaptiveState`), passed in and out, so a controller or an estimator
carries it like any other state.
"""

from __future__ import annotations

from typing import NamedTuple

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike

from physics.data import DataError, NotFittedError

from ._conformal import ConformalIntervals, Interval, check_level
from ._forecast import QUANTILES, error_forecast, offset_weight, scale_prior
from ._shift import nested_folds

__all__ = ["AdaptiveIntervals", "AdaptiveState", "MAX_STEPS"]

#: Most steps of the largest calibration score added above a working level of 1.
MAX_STEPS = 100


class AdaptiveState(NamedTuple):
    """The online band's state: the working level, the running offset and the last measured residual
    (output units; :mod:`._forecast`), the run's scale (its forecast misses over the calibration's, 1
    before any), the samples since that measurement (0: at it) and how many measurements were taken."""

    level: float
    offset: float
    residual: float
    scale: float
    since: int
    measured: int


class AdaptiveIntervals:
    """Online intervals: centred on the error forecast from the measured residuals, their width adapted
    from the misses.

    Parameters
    ----------
    every : int
        Samples between measurements the forecast and its scores are calibrated for (the measurements
        themselves may come at any samples).
    gamma : float
        ACI step: how far one miss (or hit) moves the working level.
    prior : float, optional
        How many measurements the calibration's scale counts for in the run's scale (see the module's
        notes): the band widens or narrows to the run's own forecast misses as they outnumber it.
        Default (None): from the held-out runs, by how much their forecast misses differ from run to
        run against within a run (:func:`._forecast.scale_prior`, empirical Bayes).
    level : float, optional
        Target coverage (default: the offline calibration's).

    Attributes
    ----------
    intervals_ : ConformalIntervals
        The offline calibration.
    forecast_ : ErrorForecast
        The forecast of the error from the measured residuals and, ``forecast_.table``, the
        ``(every, QUANTILES)`` quantiles of what it misses at each lag on the held-out runs over the
        start factor ``forecast_.start`` (output units; the band multiplies them by the start factor,
        the run's scale and the width factor ``sigma``, 1 inside the data).
    offline_ : float
        The offline half-width (before ``sigma``) at ``level_``: the band before the first measurement.
    prior_ : float
        The prior weight used: ``prior``, or the one the held-out runs give.

    Examples
    --------
    >>> online = AdaptiveIntervals(every=25).fit(intervals)  # doctest: +SKIP
    >>> state = online.update(online.initial(), y_measured - y_hat)  # doctest: +SKIP
    >>> state = online.advance(state)  # doctest: +SKIP  (one sample later)
    >>> centre, half = y_hat + online.centre(state), online.half_width(state)  # doctest: +SKIP
    """

    def __init__(self, every: int = 25, gamma: float = 0.05, prior: float | None = None, level: float | None = None):
        self.every = every
        self.gamma = gamma
        self.prior = prior
        self.level = level

    def fit(self, intervals: ConformalIntervals) -> AdaptiveIntervals:
        """The error forecast and its lag scores from the held-out runs of an offline calibration."""
        if isinstance(self.every, bool) or not isinstance(self.every, (int, np.integer)) or self.every < 1:
            raise DataError(f"every must be a whole number of samples >= 1 between measurements. "
                            f"Got {self.every!r} instead.")
        if isinstance(self.gamma, bool) or not isinstance(self.gamma, (int, float)) or not 0 < self.gamma < 1:
            raise DataError(f"gamma must be a number between 0 and 1 (e.g. 0.05). Got {self.gamma!r} instead.")
        if self.prior is not None and (isinstance(self.prior, bool) or not isinstance(self.prior, (int, float))
                                       or not 0 < self.prior < np.inf):
            raise DataError(f"prior must be a number of measurements > 0 (e.g. 20), or None to take it from the "
                            f"calibration. Got {self.prior!r} instead.")
        if not isinstance(intervals, ConformalIntervals) or not hasattr(intervals, "residuals_"):
            raise DataError("AdaptiveIntervals.fit needs calibrated ConformalIntervals (a model folder's "
                            "intervals.json, or ConformalIntervals().fit(train, held_out)).")
        self.level_ = check_level(intervals.level if self.level is None else self.level)
        self._learn(intervals.errors_)
        self.intervals_, self.offline_ = intervals, intervals.quantile(self.level_)
        return self

    def _learn(self, errors) -> None:
        """The forecast, its lag scores and the prior weight from held-out runs' errors."""
        self.forecast_ = error_forecast(errors, int(self.every), self.level_)
        self.mean_scores_ = self.forecast_.table.mean(axis=1)  # each lag's mean miss on the held-out runs
        self.prior_ = (scale_prior(errors, self.forecast_, int(self.every)) if self.prior is None
                       else float(self.prior))

    def nested_coverage(self) -> float | None:
        """What this online band covers of a held-out run it was not fitted on, from the training data
        alone: each held-out run (each condition's runs, where they carry conditions) replayed measured
        every ``every`` samples on a forecast, scores and prior fitted without it; the share of the
        replayed samples after each run's first measurement inside the band (width factor 1). None
        with fewer than 3 held-out runs. Like :meth:`ConformalIntervals.nested_coverage` offline, it
        foresees a band that will over- or under-cover where the held-out runs differ as new runs will."""
        self._check_fitted()
        folds = nested_folds(len(self.intervals_.errors_), self.intervals_.conditions_)
        if not folds:
            return None
        errors, hits = self.intervals_.errors_, []
        for others, held in folds:
            fold = AdaptiveIntervals(self.every, gamma=self.gamma, prior=self.prior, level=self.level_)
            fold.level_ = self.level_
            fold._learn([errors[i] for i in others])
            hits += [fold._hits(errors[i]) for i in held]
        return float(np.concatenate(hits).mean())

    def _hits(self, errors) -> np.ndarray:
        """Whether each sample of a run's ``errors`` after its first is inside the online band, measured
        every ``every`` samples from the first (width factor 1)."""
        e = np.asarray(errors, dtype=float).ravel()
        state, out = self.update(self.initial(), e[0]), np.empty(max(e.size - 1, 0), bool)
        for t in range(1, e.size):
            state = self.advance(state)
            out[t - 1] = abs(e[t] - self.centre(state)) <= self.half_width(state)
            if t % int(self.every) == 0:
                state = self.update(state, e[t])
        return out

    def initial(self) -> AdaptiveState:
        """The state before any measurement: the offline band."""
        self._check_fitted()
        return AdaptiveState(self.level_, 0.0, 0.0, 1.0, 0, 0)

    def _top(self) -> float:
        """The highest working level: :data:`MAX_STEPS` steps above 1."""
        return 1.0 + MAX_STEPS * (1 - self.level_)

    def _lag(self, lag: int) -> int:
        return min(max(int(lag), 1), self.forecast_.table.shape[0])

    def quantile(self, level: float, lag: int) -> float:
        """The scores' quantile at lag ``lag`` (>= 1) and working ``level`` (0 at 0; above 1, the largest
        score once more for every ``1 - level`` beyond it)."""
        self._check_fitted()
        row = self.forecast_.table[self._lag(lag) - 1]
        level = float(np.clip(level, 0.0, self._top()))
        if level > 1:
            return float(row[-1] * (1 + (level - 1) / (1 - self.level_)))
        return float(row[int(np.ceil(level * (row.size - 1)))])

    def centre(self, state: AdaptiveState, ahead: int = 0) -> float:
        """The band's centre relative to the prediction, ``ahead`` samples after the state's: the
        forecast error (0 before the first measurement)."""
        self._check_fitted()
        if not state.measured:
            return 0.0
        return self.forecast_.centre(state.residual, state.offset, state.since + int(ahead))

    def half_width(self, state: AdaptiveState, sigma: float | ArrayLike = 1.0, ahead: int = 0):
        """The half-width in output units at width factor ``sigma``, ``ahead`` samples after the state's
        (the offline band before the first measurement)."""
        q = (self.offline_ if not state.measured else state.scale * self.forecast_.factor(state.measured)
             * self.quantile(state.level, state.since + int(ahead)))
        return q * np.asarray(sigma, dtype=float)

    def advance(self, state: AdaptiveState, samples: int = 1) -> AdaptiveState:
        """The state ``samples`` later without a measurement."""
        return state._replace(since=state.since + int(samples))

    def update(self, state: AdaptiveState, residual: float, sigma: float = 1.0) -> AdaptiveState:
        """The state after measuring ``residual = y_measured - y_hat`` at the state's sample (width factor
        ``sigma``): the working level moves by the miss or hit of the band there, the run's scale by
        the forecast's miss over the calibration's mean at that lag, the running offset takes the
        residual in (:func:`._forecast.offset_weight`)."""
        self._check_fitted()
        residual = float(residual)
        if not np.isfinite(residual):
            raise DataError(f"A measured residual must be finite; got {residual!r}. Drop the sample instead.")
        level, scale = state.level, state.scale
        if state.measured:  # the first measurement scores the offline band, not an online one
            missed = abs(residual - self.centre(state))
            miss = float(missed > self.half_width(state, sigma))
            level = float(np.clip(level + self.gamma * (miss - (1 - self.level_)), 0.0, self._top()))
            seen = self.prior_ + state.measured - 1  # the calibration's weight and the misses scored so far
            expected = self.mean_scores_[self._lag(state.since) - 1] * self.forecast_.factor(state.measured)
            ratio = missed / float(sigma) / max(float(expected), 1e-300)
            scale = float((scale * seen + ratio) / (seen + 1))
        n = state.measured + 1
        offset = state.offset + offset_weight(self.forecast_.beta, n) * (residual - state.offset)
        return AdaptiveState(level, float(offset), residual, scale, 0, n)

    def function(self) -> ca.Function:
        """``Function('online_band', [level, offset, residual, scale, since, measured], [centre,
        half_width])``: the online band of a state for an export or a C controller: its centre (relative
        to the prediction) and half-width (before ``sigma``) ``since`` >= 1 samples after the
        ``measured``-th (>= 1) measurement (:meth:`update_function` moves the state). The lookups are
        linear interpolations of the table over the working level (exact at its :data:`QUANTILES`
        points), clipped to ``[0, 1]``; above 1 the largest score grows as in :meth:`quantile`; the
        start factor is exact at whole ``measured``."""
        self._check_fitted()
        table, coef = self.forecast_.table, self.forecast_.coef
        lags = np.arange(1, table.shape[0] + 1, dtype=float)
        grid = np.linspace(0, 1, QUANTILES)
        names = ("level", "offset", "residual", "scale", "since", "measured")
        level, offset, residual, scale, since, measured = (ca.SX.sym(n) for n in names)
        lag = ca.fmin(ca.fmax(since, 1), lags[-1])
        inner = ca.fmin(ca.fmax(level, 0), 1)
        a, b, top = (self._by_lag(n, v, lag) for n, v in (("a", coef[:, 0]), ("b", coef[:, 1]), ("top", table[:, -1])))
        if lags.size > 1:
            scores = ca.interpolant("lag_scores", "linear", [grid, lags], table.T.ravel(order="F").tolist())
            inside = scores(ca.vertcat(inner, lag))
        else:
            inside = ca.interpolant("lag_scores", "linear", [grid], table[0].tolist())(inner)
        above = top * (1 + (level - 1) / (1 - self.level_))
        half = scale * self._start(measured) * ca.if_else(level > 1, above, inside)
        return ca.Function("online_band", [level, offset, residual, scale, since, measured],
                           [a * residual + b * offset, half], list(names), ["centre", "half_width"])

    def _start(self, measured):
        """The start factor (:meth:`ErrorForecast.factor`) at the symbolic ``measured``."""
        start = self.forecast_.start
        if start is None or start.size == 1:
            return 1.0 if start is None else float(start[0])
        k = ca.fmin(ca.fmax(measured - 1, 0), start.size - 1)
        return ca.interpolant("start", "linear", [np.arange(float(start.size))], start.tolist())(k)

    def _by_lag(self, name: str, values, lag):
        """A per-lag value at the symbolic ``lag`` (a constant with one lag)."""
        if values.size == 1:
            return float(values[0])
        return ca.interpolant(name, "linear", [np.arange(1.0, values.size + 1)], np.asarray(values).tolist())(lag)

    def update_function(self) -> ca.Function:
        """``Function('online_update', [level, offset, residual, scale, since, measured, new_residual,
        sigma], [level_next, offset_next, scale_next])``: :meth:`update` for an export: the state after
        measuring ``new_residual`` at width factor ``sigma`` (its ``residual`` becomes ``new_residual``,
        ``since`` 0 and ``measured`` one more; at the first measurement, ``measured`` = 0, only the
        offset moves)."""
        self._check_fitted()
        names = ("level", "offset", "residual", "scale", "since", "measured", "new_residual", "sigma")
        level, offset, residual, scale, since, n, r, sigma = (ca.SX.sym(v) for v in names)
        centre, half = self.function()(level, offset, residual, scale, since, n)
        missed = ca.fabs(r - centre)
        moved = ca.fmin(ca.fmax(level + self.gamma * ((missed > half * sigma) - (1 - self.level_)), 0), self._top())
        seen = self.prior_ + n - 1
        mean = self._by_lag("mean_scores", self.mean_scores_, ca.fmin(ca.fmax(since, 1), self.mean_scores_.size))
        ratio = missed / sigma / ca.fmax(mean * self._start(n), 1e-300)
        off = offset + offset_weight(self.forecast_.beta, n + 1) * (r - offset)
        rescaled = (scale * seen + ratio) / (seen + 1)
        return ca.Function("online_update", [level, offset, residual, scale, since, n, r, sigma],
                           [ca.if_else(n > 0, moved, level), off, ca.if_else(n > 0, rescaled, scale)],
                           list(names), ["level_next", "offset_next", "scale_next"])

    def run(self, y_hat: ArrayLike, u: ArrayLike, dt: float, y: ArrayLike,
            measured: ArrayLike | None = None, window=None) -> Interval:
        """Replay one run: the band of each sample before that sample's measurement is taken, then the
        update where ``measured`` (a boolean mask; default every ``every``-th sample from the first).
        ``outside`` also flags the samples after a measured residual beyond the offline band: the run
        has drifted where the calibration did not see a run go (and, with the measured warm-up
        ``window``, every sample of a run that starts unlike the training runs,
        :meth:`ConformalIntervals.start_outside`)."""
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
        offline = self.intervals_.interval(y_hat, u, dt, self.level_, window=window)
        sigma = offline.half_width / max(self.offline_, 1e-300)
        centre, half, drift = np.empty_like(y), np.empty_like(y), np.zeros(y.size, bool)
        state, drifted = self.initial(), False
        for t in range(y.size):
            if t:
                state = self.advance(state)
            # the offline band until the first measurement; then the online one, in output units (its lag
            # scores are of the raw errors: the measured misses, not the distance, say where they grow)
            factor = 1.0 if state.measured else sigma[t]
            centre[t], half[t], drift[t] = self.centre(state), self.half_width(state, factor), drifted
            if mask[t] and np.isfinite(y[t]):
                state = self.update(state, y[t] - y_hat[t])
                drifted = abs(state.residual) > offline.half_width[t]
        return Interval(y_hat, y_hat + centre - half, y_hat + centre + half, offline.outside | drift,
                        offline.distance)

    def _check_fitted(self) -> None:
        if not hasattr(self, "forecast_"):
            raise NotFittedError("These online intervals are not fitted yet. Call fit(intervals) first.")

    def __repr__(self) -> str:
        return f"AdaptiveIntervals(every={self.every}, gamma={self.gamma}, prior={self.prior})"
