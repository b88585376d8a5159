"""Min-max scaling to [0, 1]."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._checks import as_float_array, check_finite
from ._errors import DataError, NotFittedError

__all__ = ["MinMaxScaler"]


class MinMaxScaler:
    """Scale each column to [0, 1] using the minimum and maximum seen in ``fit``.

    Parameters
    ----------
    constant : {"raise", "keep"}
        A column that never varies in ``fit``: an error (the default; data that cannot be
        learned from), or kept and mapped to 0 there (a span of ``max(|value|, 1)``), for a
        column that may carry nothing, such as a physics model's output where no static map
        explains the data.

    Attributes
    ----------
    min_, max_ : ndarray, shape (k,)
        Per-column minimum and maximum (set by :meth:`fit`).

    Examples
    --------
    >>> s = MinMaxScaler().fit(np.array([[0.0, 10.0], [2.0, 20.0]]))
    >>> s.transform(np.array([[1.0, 15.0]]))
    array([[0.5, 0.5]])
    >>> MinMaxScaler.from_dict(s.to_dict()).max_
    array([ 2., 20.])
    """

    def __init__(self, constant: str = "raise"):
        if constant not in ("raise", "keep"):
            raise DataError(f"MinMaxScaler constant must be 'raise' or 'keep'. Got {constant!r} instead.")
        self.constant = constant

    def fit(self, x: ArrayLike) -> MinMaxScaler:
        """Learn per-column ``min_`` and ``max_`` from ``x`` (shape (n,) or (n, k)); returns self."""
        arr = self._as_2d(x, "x")
        if arr.shape[0] == 0:
            raise DataError("x has no samples; MinMaxScaler.fit needs at least one row.")
        check_finite(arr, "x")
        lo, hi = arr.min(axis=0), arr.max(axis=0)
        const = np.flatnonzero(hi == lo)
        if const.size and self.constant == "keep":
            hi = np.where(hi == lo, lo + np.maximum(np.abs(lo), 1.0), hi)
        elif const.size:
            j = int(const[0])
            raise DataError(
                f"column {j} of x is constant (every value is {float(lo[j])!r}), so it cannot be scaled to [0, 1]. "
                "Drop the column or fit on data where it varies."
            )
        self.min_, self.max_ = lo, hi
        return self

    def transform(self, x: ArrayLike) -> NDArray[np.float64]:
        """Map ``x`` to ``(x - min_) / (max_ - min_)``; keeps the shape of ``x``."""
        arr = self._checked(x)
        return (arr - self.min_) / (self.max_ - self.min_)

    def inverse_transform(self, x: ArrayLike) -> NDArray[np.float64]:
        """Map scaled values back: ``x * (max_ - min_) + min_``."""
        arr = self._checked(x)
        return arr * (self.max_ - self.min_) + self.min_

    def to_dict(self) -> dict[str, Any]:
        """JSON-serialisable state; :meth:`from_dict` restores it exactly."""
        self._check_fitted()
        return {"type": "MinMaxScaler", "min": self.min_.tolist(), "max": self.max_.tolist()}

    @classmethod
    def from_dict(cls, state: dict[str, Any]) -> MinMaxScaler:
        """Rebuild a fitted scaler from :meth:`to_dict` output."""
        if not isinstance(state, dict) or "min" not in state or "max" not in state:
            raise DataError("MinMaxScaler.from_dict needs a dict with 'min' and 'max' lists (from to_dict()).")
        lo = as_float_array(state["min"], "state['min']")
        hi = as_float_array(state["max"], "state['max']")
        if lo.shape != hi.shape or np.any(hi <= lo):
            raise DataError("MinMaxScaler state is inconsistent: 'min' and 'max' need equal lengths and max > min.")
        scaler = cls()
        scaler.min_, scaler.max_ = lo, hi
        return scaler

    # ------------------------------------------------------------------ helpers
    def _check_fitted(self) -> None:
        if not hasattr(self, "min_"):
            raise NotFittedError("This MinMaxScaler is not fitted yet. Call fit(x) before using it.")

    def _checked(self, x: ArrayLike) -> NDArray[np.float64]:
        self._check_fitted()
        arr = as_float_array(x, "x", ndim=(0, 1, 2))
        k = self.min_.shape[0]
        # 2-D: rows of k columns; 1-D: a series of the single feature, or one row of k features.
        width = arr.shape[1] if arr.ndim == 2 else (arr.shape[0] if arr.ndim == 1 and k > 1 else 1)
        if width != k:
            raise DataError(f"x has {width} column(s) but the scaler was fitted on {k}. Pass data with {k} column(s).")
        return arr

    @staticmethod
    def _as_2d(x: ArrayLike, name: str) -> NDArray[np.float64]:
        arr = as_float_array(x, name, ndim=(1, 2))
        return arr[:, None] if arr.ndim == 1 else arr

    def __repr__(self) -> str:
        return "MinMaxScaler()" if not hasattr(self, "min_") else f"MinMaxScaler(min_={self.min_}, max_={self.max_})"
