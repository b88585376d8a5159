"""Error metrics for predicted trajectories."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from ._checks import as_float_array, check_finite
from ._errors import DataError

__all__ = ["rmse", "nrmse"]


def _pair(y: ArrayLike, yhat: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    a = as_float_array(y, "y", ndim=(1, 2))
    b = as_float_array(yhat, "yhat", ndim=(1, 2))
    if a.shape != b.shape:
        raise DataError(f"y has shape {a.shape} but yhat has shape {b.shape}; they must match.")
    if a.size == 0:
        raise DataError("y and yhat are empty; metrics need at least one sample.")
    check_finite(a, "y")
    check_finite(b, "yhat")
    return a, b


def rmse(y: ArrayLike, yhat: ArrayLike) -> float:
    """Root-mean-square error over all samples.

    >>> rmse([0.0, 1.0], [0.0, 3.0])
    1.4142135623730951
    """
    a, b = _pair(y, yhat)
    return float(np.sqrt(np.mean((a - b) ** 2)))


def nrmse(y: ArrayLike, yhat: ArrayLike) -> float:
    """RMSE divided by the range of the measured output, ``max(y) - min(y)``.

    >>> nrmse([0.0, 2.0], [0.0, 3.0])
    0.3535533905932738
    """
    a, b = _pair(y, yhat)
    span = float(a.max() - a.min())
    if span == 0:
        raise DataError("y is constant, so its range is 0 and the normalised RMSE is undefined; use rmse().")
    return float(np.sqrt(np.mean((a - b) ** 2))) / span
