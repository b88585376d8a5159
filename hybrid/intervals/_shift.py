"""The half-width a new run needs when runs are offset from each other, and a check of it on the runs seen.

A model's error on a held-out run is its own offset plus what varies within the run,

    e = m_run + eps,

(a random effect per run, not per sample: a recording made on another day, from another start or
after another history sits higher or lower as a whole). Pooling the held-out samples treats the
few offsets seen as all there are; with five runs, the next run's offset is often beyond them. The
offset of a new run is predicted as in a one-way random-effects model: the runs' mean offset plus
Student's t with ``G - 1`` degrees of freedom scaled by the offsets' standard deviation times
``sqrt(1 + 1/G)``, ``G`` the number of runs. The half-width ``h`` is the smallest at which

    E_M [ P(|M + eps| <= h) ] >= level,

with ``eps`` the within-run errors pooled so that each run weighs the same. Unlike the conformal
quantile, this rests on a model of the offsets (normal across runs); its merit is that the few runs
widen it through ``t`` rather than pretend they are all the ways runs differ.

:func:`nested_coverage` checks the whole rule on the training data alone: each held-out run in turn is
left out of the calibration and scored on the half-width the others give (each condition's runs
together, where the runs carry conditions). Where that falls short of
the level, new recordings will too, and the card says so before anyone meets them.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray
from scipy import stats

__all__ = ["offset_quantile", "pooled_quantile", "nested_coverage", "nested_shares", "nested_folds", "GRID"]

#: Points of the predicted offset's distribution the expectation is taken over.
GRID = 401
#: Bisection steps on the half-width (the bracket shrinks 2**-60: below any float's precision).
BISECTIONS = 60


def pooled_quantile(groups: Sequence[NDArray], level: float, unseen: bool = True) -> float:
    """The conformal quantile of ``|scores|`` pooled over groups (each weighs the same, and the unseen
    group is a point mass at +inf): +inf where there are too few groups for ``level``. ``unseen=False``:
    the plain ``level`` quantile of the groups pooled so (no mass at +inf)."""
    values = np.concatenate([np.abs(g) for g in groups])
    weights = np.concatenate([np.full(g.size, 1.0 / ((len(groups) + unseen) * g.size)) for g in groups])
    order = np.argsort(values, kind="stable")
    reached = np.cumsum(weights[order]) >= level - 1e-12
    return float(values[order][np.argmax(reached)]) if reached.any() else math.inf


def offset_quantile(residuals: Sequence[NDArray], level: float) -> float:
    """The half-width that covers ``level`` of a new run's samples under the random-effects model of
    the module's notes, from the signed ``residuals`` (one array per held-out run; at least 2)."""
    runs = [np.asarray(r, dtype=float).ravel() for r in residuals if np.size(r)]
    if len(runs) < 2:
        raise ValueError(f"offset_quantile needs at least 2 runs' residuals; got {len(runs)}.")
    offsets = np.array([r.mean() for r in runs])
    g = len(runs)
    eps = np.concatenate([r - m for r, m in zip(runs, offsets)])
    weights = np.concatenate([np.full(r.size, 1.0 / (g * r.size)) for r in runs])
    order = np.argsort(eps, kind="stable")
    eps, cdf = eps[order], np.cumsum(weights[order])

    def below(x):  # P(eps <= x), elementwise
        i = np.searchsorted(eps, x, side="right")
        return np.where(i > 0, cdf[np.maximum(i - 1, 0)], 0.0)

    def strictly_below(x):  # P(eps < x)
        i = np.searchsorted(eps, x, side="left")
        return np.where(i > 0, cdf[np.maximum(i - 1, 0)], 0.0)

    spread = offsets.std(ddof=1) * math.sqrt(1 + 1 / g)
    m = offsets.mean() + spread * stats.t.ppf((np.arange(GRID) + 0.5) / GRID, g - 1)
    lo, hi = 0.0, float(np.abs(m).max() + np.abs(eps).max()) + 1e-12
    for _ in range(BISECTIONS):
        h = (lo + hi) / 2
        if np.mean(below(h - m) - strictly_below(-h - m)) >= level:
            hi = h
        else:
            lo = h
    return hi


def nested_coverage(residuals: Sequence[NDArray], level: float, quantile,
                    conditions: Sequence[str | None] | None = None) -> float | None:
    """Mean over the runs of the share of a run's samples inside the half-width ``quantile(others,
    level)`` calibrated without it: what the calibration covers of a run it has not seen, from the
    training runs alone. Where the runs carry ``conditions`` (two or more), each condition's runs are
    left out together, as a recording under a new condition would be; a condition whose leaving
    leaves fewer than 2 runs is scored on none. None with fewer than 3 runs (two would leave one to
    calibrate on)."""
    shares = nested_shares(residuals, level, quantile, conditions)
    return float(np.mean(shares)) if shares else None


def nested_shares(residuals: Sequence[NDArray], level: float, quantile,
                  conditions: Sequence[str | None] | None = None) -> list[float]:
    """Each scored run's share of samples inside the half-width calibrated without it (its condition),
    as in :func:`nested_coverage` (empty with fewer than 3 runs). The runs that fall short say, from
    the training data alone, how often a new recording may: the runs are exchangeable, so a new one
    falls below the worst ``n`` of ``G`` with a chance of about ``(n + 1) / (G + 1)``."""
    runs = [np.asarray(r, dtype=float).ravel() for r in residuals]
    shares = []
    for others, held in nested_folds(len(runs), conditions):
        q = quantile([runs[i] for i in others], level)
        shares += [float(np.mean(np.abs(runs[i]) <= q)) for i in held]
    return shares


def nested_folds(runs: int, conditions: Sequence[str | None] | None = None) -> list[tuple[list[int], list[int]]]:
    """``(others, held)`` run indices of the nested check: each run left out in turn, or each condition's
    runs together where two or more conditions are named; folds that leave fewer than 2 runs are
    dropped, and there are none with fewer than 3 runs."""
    if runs < 3:
        return []
    labels: list = list(range(runs))
    if conditions is not None and len({c for c in conditions if c is not None}) >= 2:
        labels = [c if c is not None else f"run {i}" for i, c in enumerate(conditions)]
    folds = []
    for label in dict.fromkeys(labels):
        others = [i for i, k in enumerate(labels) if k != label]
        if len(others) >= 2:
            folds.append((others, [i for i, k in enumerate(labels) if k == label]))
    return folds
