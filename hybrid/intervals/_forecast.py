"""The model's error some samples after a measurement, forecast from the residuals measured so far.

A free run's error on a new run is its offset plus what moves within the run (:mod:`._shift`). Each
measured residual ``r_k = y - y_hat`` says something of both: averaged over the measurements of a
run, the residuals estimate the offset; the last one says where the error is now. The forecast of
the error ``j`` samples after measurement ``k`` combines the two,

    e_hat(t_k + j) = a_j r_k + b_j o_k,    o_k = o_{k-1} + w_k (r_k - o_{k-1}),    o_0 = 0,

``o_k`` the running offset: an exponentially weighted mean of the measured residuals with forgetting
``beta``, its weights ``w_k = beta / (1 - (1 - beta)^k)`` corrected for the start (the first
measurement is the whole estimate, ``w_1 = 1``; then a plain mean of the first few, then a moving
one with memory about ``1 / beta`` measurements). ``a_j`` and ``b_j`` are least squares over the
held-out runs of the calibration, each replayed as if measured every ``every`` samples from
:data:`PHASES` starting samples: 0 and 0 for white noise (a measurement says nothing of the next
sample), ``b_j = 1`` for an offset that stays, ``a_j`` near 1 at short lags for an error that moves
slowly. ``beta`` is the one of :data:`BETAS` whose forecast misses least at the level asked (the
mean over the lags of the quantile of ``|e - e_hat|``).

What the forecast misses on the held-out replays, lag by lag, is the online band's score table
(:class:`~hybrid.intervals.AdaptiveIntervals` moves the level it is read at). A free run misses more
after its first measurements than later (its start from the warm-up state, the offset not yet
measured): :func:`start_factor` reads by how much from the held-out runs, and the table holds the
misses over it, so the band multiplies it back in at the same point of a run. How many measurements
the table's scale counts for against a run's own misses is read from them too (:func:`scale_prior`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from scipy.optimize import isotonic_regression

from physics.data import DataError

__all__ = ["ErrorForecast", "error_forecast", "running_offsets", "offset_weight", "scale_prior", "start_factor",
           "BETAS", "PHASES", "QUANTILES", "MAX_PRIOR"]

#: Forgetting factors of the running offset tried (1: the last residual only).
BETAS = (0.05, 0.1, 0.2, 0.35, 0.5, 1.0)
#: Starting samples each held-out run is replayed from (spread over ``every``).
PHASES = 5
#: Points of each lag's score distribution kept (its quantiles): the table stays small for any run length.
QUANTILES = 1001
#: The prior weight (in measurements) where the held-out runs show no run-to-run difference in how much the
#: forecast misses: the calibration's scale then stands for any run (no run is measured this often).
MAX_PRIOR = 1e6


def offset_weight(beta: float, measured: int):
    """The weight of the ``measured``-th measurement (>= 1) in the running offset: ``beta / (1 - (1 -
    beta)^measured)`` (1 for the first). Works on numbers and on CasADi expressions."""
    return beta / (1 - (1 - beta) ** measured)


def running_offsets(residuals: NDArray[np.float64], beta: float) -> NDArray[np.float64]:
    """The running offset after each of a run's measured ``residuals`` (see the module's notes)."""
    out, o = np.empty(len(residuals)), 0.0
    for k, r in enumerate(residuals):
        o += offset_weight(beta, k + 1) * (r - o)
        out[k] = o
    return out


@dataclass(frozen=True)
class ErrorForecast:
    """The forecast of the error ``j = 1 .. every`` samples after a measurement and what it misses.

    ``coef[j - 1] = (a_j, b_j)``: the weights of the last measured residual and of the running offset
    (forgetting ``beta``); row ``j - 1`` of ``table`` the quantiles (0 to 1, :data:`QUANTILES` points)
    of ``|e - e_hat| / start[k]`` at lag ``j`` over the held-out replays, ``k`` the measurement the
    forecast is from; ``start[k]`` (k = 0, 1, ...; the last value beyond) how much larger the misses
    are after a run's ``k + 1``-th measurement than on average (:func:`start_factor`; None: 1)."""

    beta: float
    coef: NDArray[np.float64]
    table: NDArray[np.float64]
    start: NDArray[np.float64] | None = None

    def centre(self, residual: float, offset: float, lag: int) -> float:
        a, b = self.coef[min(max(int(lag), 1), self.coef.shape[0]) - 1]
        return float(a * residual + b * offset)

    def factor(self, measured: int) -> float:
        """The start factor after ``measured`` (>= 1) measurements of a run."""
        if self.start is None:
            return 1.0
        return float(self.start[min(max(int(measured) - 1, 0), self.start.size - 1)])


def _phases(every: int) -> list[int]:
    return sorted({int(v) for v in np.linspace(0, every - 1, PHASES)})


def _pairs(runs: Sequence[NDArray], every: int, beta: float) -> list[tuple[NDArray, NDArray]]:
    """Per lag ``j``: the features (last residual, running offset) and the error ``j`` samples later,
    over every measurement of every replay."""
    out = [([], []) for _ in range(every)]
    for _, e, t, r, o in _replays(runs, every, beta):
        x = np.column_stack([r, o])
        for j in range(1, every + 1):
            ok = t + j < e.size
            out[j - 1][0].append(x[ok])
            out[j - 1][1].append(e[t[ok] + j])
    return [(np.concatenate(x), np.concatenate(y)) for x, y in out]


def _replays(runs: Sequence[NDArray], every: int, beta: float):
    """Each run replayed measured every ``every`` samples from each of the :data:`PHASES` starts:
    ``(run index, errors, measured sample indices, measured residuals, running offsets)``."""
    for i, e in enumerate(runs):
        for p in _phases(every):
            t = np.arange(p, e.size, every)
            r = e[t]
            yield i, e, t, r, running_offsets(r, beta)


def _fit(runs, every: int, beta: float) -> tuple[NDArray, NDArray]:
    grid = np.linspace(0, 1, QUANTILES)
    coef, table = [], []
    for x, ahead in _pairs(runs, every, beta):
        if ahead.size < 2:
            break
        c = np.linalg.lstsq(x, ahead, rcond=None)[0] if np.any(x) else np.zeros(x.shape[1])
        coef.append(c)
        table.append(np.quantile(np.abs(ahead - x @ c), grid, method="higher"))
    if not table:
        raise DataError("The held-out runs are too short for a lag of one sample: no forecast of the error.")
    coef += [coef[-1]] * (every - len(coef))  # lags no run is long enough for repeat the last one that is
    table += [table[-1]] * (every - len(table))
    return np.array(coef), np.array(table)


def error_forecast(residuals: Sequence[NDArray], every: int, level: float) -> ErrorForecast:
    """The forecast of the module's notes from the held-out runs' signed errors ``residuals`` (one array
    per run), measured every ``every`` samples, its ``beta`` chosen at ``level``."""
    runs = [np.asarray(r, dtype=float).ravel() for r in residuals]
    every = int(every)
    at = int(np.ceil(level * (QUANTILES - 1)))
    best = None
    for beta in BETAS:
        coef, table = _fit(runs, every, beta)
        width = float(table[:, at].mean())
        if best is None or width < best[0] - 1e-12:
            best = (width, beta, coef)
    _, beta, coef = best
    run, k, lag, miss = _misses(runs, every, beta, coef)
    start = start_factor(run, k, lag, miss)
    grid, table = np.linspace(0, 1, QUANTILES), []
    for j in range(1, every + 1):
        settled = miss[lag == j] / start[k[lag == j]]
        if settled.size < 2:
            break
        table.append(np.quantile(settled, grid, method="higher"))
    table += [table[-1]] * (every - len(table))
    return ErrorForecast(beta, coef, np.array(table), start)


def _misses(runs: Sequence[NDArray], every: int, beta: float, coef: NDArray) -> tuple[NDArray, ...]:
    """``(run, k, lag, |miss|)`` of every forecast over every replay: the run's index, the measurement the
    forecast is from (0: the first), the lag and what the forecast missed."""
    out: list[list] = [[], [], [], []]
    for i, e, t, r, o in _replays(runs, every, beta):
        for j in range(1, every + 1):
            ok = t + j < e.size
            a, b = coef[j - 1]
            out[0].append(np.full(ok.sum(), i))
            out[1].append(np.nonzero(ok)[0])
            out[2].append(np.full(ok.sum(), j))
            out[3].append(np.abs(e[t[ok] + j] - a * r[ok] - b * o[ok]))
    return tuple(np.concatenate(v) for v in out)


def start_factor(run: NDArray, k: NDArray, lag: NDArray, miss: NDArray) -> NDArray[np.float64]:
    """How much larger the forecast misses are after a run's ``k + 1``-th measurement than over the run,
    for ``k = 0 .. max(k)``: each miss over its lag's mean and over its run's mean of those (so a run
    that misses more as a whole weighs nothing here, and a long run's calm end does not pass for a
    start), averaged per ``k`` over the runs that reach it (each weighs the same), then made
    non-increasing (isotonic regression weighted by those runs): a free run's start transient, and
    the offset not yet measured, only fade."""
    lags = np.arange(1, lag.max() + 1)
    per_lag = np.array([miss[lag == j].mean() if np.any(lag == j) else 1.0 for j in lags])
    x = miss / np.maximum(per_lag[lag - 1], 1e-300)
    per_run = np.bincount(run, x) / np.maximum(np.bincount(run), 1)
    x = x / np.maximum(per_run[run], 1e-300)
    if not np.any(miss > 0):
        return np.ones(k.max() + 1)
    means, weights = np.ones(k.max() + 1), np.zeros(k.max() + 1)
    for kk in range(k.max() + 1):
        at = k == kk
        runs = np.unique(run[at])
        means[kk] = np.mean([x[at & (run == i)].mean() for i in runs])
        weights[kk] = runs.size
    return np.maximum(isotonic_regression(means, weights=weights, increasing=False).x, 1e-12)


def scale_prior(residuals: Sequence[NDArray], forecast: ErrorForecast, every: int) -> float:
    """How many measurements the calibration's scale of the forecast misses counts for in a run's own
    (:class:`~hybrid.intervals.AdaptiveIntervals`' ``prior``), from the held-out runs alone: empirical
    Bayes in a one-way random-effects model of the misses at lag ``every`` over their mean and over the
    start factor (the ratio the online band's scale averages). With ``m_i`` a run's mean ratio over
    ``K_i`` measurements, ``s2`` the variance of one ratio within a run and ``tau2 = var(m_i) -
    mean(s2 / K_i)`` the variance of the runs' true scales, the best linear estimate of a run's scale
    after ``K`` measurements weighs its own mean by ``K`` and the calibration's (1) by ``s2 / tau2``:
    that is the prior. Runs that differ much (``tau2`` large) trust their own misses after a few
    measurements; runs that differ no more than their sampling noise (``tau2 <= 0``) keep the
    calibration's scale (:data:`MAX_PRIOR`). Each run is replayed from the :data:`PHASES` starts (``K_i``
    its scored measurements over their number)."""
    runs = [np.asarray(r, dtype=float).ravel() for r in residuals]
    run, k, lag, miss = _misses(runs, every, forecast.beta, forecast.coef)
    at = lag == every
    start = np.ones(k.max() + 1) if forecast.start is None else forecast.start
    ratio = miss[at] / start[np.minimum(k[at], start.size - 1)] / max(float(forecast.table[every - 1].mean()), 1e-300)
    run = run[at]
    means, within, counts = [], [], []
    for i in np.unique(run):
        x = ratio[run == i]
        if x.size >= 2:
            means.append(x.mean())
            within.append(x.var(ddof=1))
            counts.append(x.size / len(_phases(every)))
    if len(means) < 2:
        return MAX_PRIOR
    means, within, counts = np.array(means), np.array(within), np.array(counts)
    s2 = float(np.average(within, weights=counts))
    tau2 = float(means.var(ddof=1) - np.mean(s2 / counts))
    return float(min(s2 / tau2, MAX_PRIOR)) if tau2 > 0 and s2 > 0 else MAX_PRIOR
