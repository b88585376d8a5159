"""Noise level and whiteness of a residual: what "explained down to the noise" means."""

from __future__ import annotations

from math import comb

import numpy as np

__all__ = ["noise_floor", "whiteness"]


def noise_floor(y, order: int = 4) -> float:
    """Standard deviation of white measurement noise on a smooth signal ``y``.

    From the ``order``-th difference, in which a smooth signal nearly vanishes
    and white noise of variance ``s^2`` has variance ``s^2 * C(2 order, order)``.
    The scale is the standard deviation of the differences within four robust
    (median absolute deviation) standard deviations, so steps and corners do
    not count. ``y`` may be a list of arrays: their differences are pooled.
    """
    parts = [np.asarray(v, dtype=float) for v in (y if isinstance(y, (list, tuple)) else [y])]
    d = [np.diff(v, n=order) for v in parts if v.size > order + 4]
    if not d:
        raise ValueError(f"noise_floor needs more than {order + 4} samples.")
    d = np.concatenate(d)
    d = d - np.median(d)
    mad = 1.4826 * np.median(np.abs(d))
    if mad == 0:
        return 0.0
    inner = d[np.abs(d) <= 4 * mad]
    scale = np.sqrt(sum(comb(order, k) ** 2 for k in range(order + 1)))
    return float(np.sqrt(np.mean(inner**2)) / scale)


def whiteness(residual, lags: int = 10) -> float:
    """Largest absolute autocorrelation of ``residual`` at lags 1..``lags``.

    About ``2 / sqrt(n)`` or less for white noise.
    """
    r = np.asarray(residual, dtype=float) - np.mean(residual)
    denom = float(r @ r)
    if denom == 0:
        return 0.0
    return float(max(abs(float(r[k:] @ r[:-k]) / denom) for k in range(1, min(lags, r.size - 1) + 1)))
