"""History windows (tapped delay lines) and LSTM subsequences."""

from __future__ import annotations

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from numpy.typing import ArrayLike, NDArray

from ._checks import as_float_array, check_positive_int
from ._errors import DataError

__all__ = ["history_windows", "lstm_subsequences"]


def history_windows(x: ArrayLike, length: int, pad: float | str | None = None) -> NDArray[np.float64]:
    """Rows of the last ``length`` samples, oldest first and newest last.

    Row ``i`` of the result ends at sample ``n = i + length - 1`` (without
    padding) or ``n = i`` (with padding) and holds ``x[n-length+1 .. n]``.

    Parameters
    ----------
    x : array_like, shape (n,) or (n, d)
        A series (one row per sample).
    length : int
        Number of samples per window (the history buffer length).
    pad : None, float or "edge"
        ``None``: only complete windows (``n - length + 1`` rows). A float:
        ``length - 1`` copies of it are prepended, giving one window per
        sample. ``"edge"``: like a float, repeating ``x[0]``.

    Returns
    -------
    ndarray, shape (rows, length) or (rows, length, d)
        A fresh array, safe to modify.

    Examples
    --------
    >>> history_windows([1.0, 2.0, 3.0, 4.0], 3)
    array([[1., 2., 3.],
           [2., 3., 4.]])
    >>> history_windows([1.0, 2.0, 3.0, 4.0], 3, pad=-1.0)
    array([[-1., -1.,  1.],
           [-1.,  1.,  2.],
           [ 1.,  2.,  3.],
           [ 2.,  3.,  4.]])
    """
    arr = as_float_array(x, "x", ndim=(1, 2))
    length = check_positive_int(length, "length")
    if arr.shape[0] == 0:
        raise DataError("x has no samples; windows need at least one.")
    if pad is not None:
        arr = np.concatenate([_padding(arr, pad, length - 1), arr], axis=0)
    elif arr.shape[0] < length:
        raise DataError(
            f"the trajectory has {arr.shape[0]} samples but the history buffer needs {length}. "
            "Use a shorter buffer (length), a longer trajectory, or pad=... to pad the start."
        )
    # sliding_window_view puts the window axis last; move it next to the row axis for (rows, length, d).
    view = sliding_window_view(arr, length, axis=0)
    if arr.ndim == 2:
        view = np.moveaxis(view, -1, 1)
    return np.array(view, copy=True)


def lstm_subsequences(x: ArrayLike, length: int = 50, flag: float = -1.0) -> NDArray[np.float64]:
    """One subsequence of ``length`` samples ending at every sample, start padded with ``flag``.

    This is the seed paper's LSTM training scheme: each sequence is
    prefixed by ``length - 1`` flag values so that the first samples also get
    a full-length input, and the flag tells the network that no history
    exists there. Equivalent to ``history_windows(x, length, pad=flag)`` with
    a trailing feature axis.

    Returns
    -------
    ndarray, shape (n, length, 1) for 1-D ``x`` or (n, length, d) for 2-D ``x``.

    Examples
    --------
    >>> lstm_subsequences([1.0, 2.0], length=3)[:, :, 0]
    array([[-1., -1.,  1.],
           [-1.,  1.,  2.]])
    """
    if isinstance(flag, (bool, str)) or not np.isfinite(_as_scalar(flag)):
        raise DataError(f"flag must be a finite number; got {flag!r}.")
    windows = history_windows(x, length, pad=float(flag))
    return windows[:, :, None] if windows.ndim == 2 else windows


def _as_scalar(value: object) -> float:
    try:
        return float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return float("nan")


def _padding(arr: NDArray[np.float64], pad: float | str, count: int) -> NDArray[np.float64]:
    if isinstance(pad, str):
        if pad != "edge":
            raise DataError(f"pad must be None, a number or 'edge'; got {pad!r}.")
        return np.repeat(arr[:1], count, axis=0)
    value = _as_scalar(pad)
    if isinstance(pad, bool) or not np.isfinite(value):
        raise DataError(f"pad must be None, a finite number or 'edge'; got {pad!r}.")
    return np.full((count,) + arr.shape[1:], value)
