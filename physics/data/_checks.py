"""Small validation helpers shared by the data modules (private)."""

from __future__ import annotations

import math
from numbers import Integral, Real

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._errors import DataError


def as_float_array(x: ArrayLike, name: str, *, ndim: tuple[int, ...] = (1,)) -> NDArray[np.float64]:
    """Convert ``x`` to a float64 array with one of the allowed numbers of dimensions."""
    try:
        arr = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise DataError(
            f"{name} must be numeric (convertible to float64); got {type(x).__name__} "
            f"that numpy could not convert ({exc}). Pass a numeric array."
        ) from None
    if arr.ndim not in ndim:
        allowed = " or ".join(f"{d}-D" for d in ndim)
        raise DataError(
            f"{name} must be {allowed}; got an array of shape {arr.shape}. "
            "Pass one value per sample (use np.ravel or select a column)."
        )
    return arr


def first_nonfinite(arr: NDArray[np.float64]) -> int | None:
    """Index (along the first axis) of the first row holding NaN or inf, or None."""
    bad = ~np.isfinite(arr)
    if bad.ndim > 1:
        bad = bad.reshape(bad.shape[0], -1).any(axis=1)
    idx = np.flatnonzero(bad)
    return int(idx[0]) if idx.size else None


def check_finite(arr: NDArray[np.float64], name: str) -> None:
    """Raise a :class:`DataError` naming the first non-finite sample of ``arr``."""
    i = first_nonfinite(arr)
    if i is not None:
        row = np.ravel(arr[i])
        value = float(row[~np.isfinite(row)][0])
        raise DataError(
            f"{name} has a non-finite value ({value!r}) at index {i}. "
            "Remove or interpolate NaN/inf samples before building the data."
        )


def check_rate(rate_hz: object, name: str = "rate_hz") -> float:
    """Validate a sampling rate in Hz (a finite number > 0)."""
    if isinstance(rate_hz, bool) or not isinstance(rate_hz, Real):
        raise DataError(f"{name} must be a number in Hz; got {rate_hz!r}. Pass e.g. {name}=25.0.")
    rate = float(rate_hz)
    if not math.isfinite(rate) or rate <= 0:
        raise DataError(f"{name} must be a finite number > 0 (Hz); got {rate_hz!r}. Pass e.g. {name}=25.0.")
    return rate


def check_positive_int(value: object, name: str) -> int:
    """Validate an integer >= 1 (bools rejected)."""
    if isinstance(value, bool) or not isinstance(value, Integral) or value < 1:
        raise DataError(f"{name} must be an integer >= 1; got {value!r}.")
    return int(value)


#: A sample is an outlier when it lies this many times the spread of the bulk of the samples away
#: from their median: no measured signal does that, a glitch (1e30, a unit slip by 1e6) does.
OUTLIER_FACTOR = 1e3


def find_outlier(x: NDArray[np.float64], factor: float = OUTLIER_FACTOR) -> int | None:
    """Index of the sample farthest from the median when it is more than ``factor`` times the
    spread of the bulk of the samples away from it (None when there is none, or fewer than 20
    samples to judge by).

    The bulk is the samples left when the ``max(2, n // 100)`` lowest and highest are set aside;
    its spread is their range, or the median's magnitude when that is larger (a signal resting
    at 1 that steps to 3 for a sample or two is not a glitch; one at 1e30 is). A signal that
    steps is never flagged, a spike far beyond it is.

    >>> x = np.sin(np.linspace(0, 6, 100)); x[40] = 1e30
    >>> find_outlier(x)
    40
    >>> find_outlier(np.r_[np.zeros(50), np.ones(50) * 1e6]) is None
    True
    >>> find_outlier(np.r_[3.0, np.ones(30)]) is None
    True
    """
    x = np.asarray(x, dtype=np.float64)
    if x.size < 20 or not np.all(np.isfinite(x)):
        return None
    k = max(2, x.size // 100)
    bulk = np.sort(x)[k:-k]
    median = float(np.median(x))
    spread = max(float(bulk[-1] - bulk[0]), abs(median))
    if spread == 0.0:
        return None
    far = np.abs(x - median)
    i = int(np.argmax(far))
    return i if far[i] > factor * spread else None


def is_constant(x: ArrayLike) -> bool:
    """True when ``x`` does not move beyond rounding (a signal no dynamics can be identified from).

    >>> is_constant([2.0, 2.0, 2.0 + 1e-15]), is_constant([0.0, 0.1])
    (True, False)
    """
    x = np.asarray(x, dtype=np.float64)
    return x.size == 0 or float(np.ptp(x)) <= 1e-12 * max(1.0, float(np.max(np.abs(x))))


#: The largest magnitude a sample may have: no measurement comes near it, and a fit squares and sums
#: samples (1e150 squared is 1e300, near float64's 1.8e308), so beyond it the solver sees inf or NaN.
MAX_MAGNITUDE = 1e150

#: A step of the time stamps this many times their median step is a gap in the recording.
GAP_FACTOR = 100.0


def time_notes(time: ArrayLike) -> list[str]:
    """What looks wrong in a file's raw time stamps (s), each as a sentence for a warning: a gap (a step
    more than :data:`GAP_FACTOR` times the median, which resampling bridges with a straight line), and
    stamps that look like milliseconds (a median step of 10 s or more, or of 1 s or more with whole-number
    or large stamps), which would make a model run 1000 times too slow.

    >>> time_notes(np.arange(100) * 0.04)
    []
    >>> time_notes(np.r_[np.arange(50) * 0.04, 1000 + np.arange(50) * 0.04])[0][:54]
    'the time stamps jump by 998 s (from 1.96 s to 1000 s),'
    >>> time_notes(np.arange(100) * 40.0)[0][:45]
    'the time stamps step by 40 (median), a rate o'
    """
    t = np.asarray(time, dtype=np.float64)
    steps = np.diff(t)
    positive = steps[steps > 0]
    if positive.size == 0 or not np.all(np.isfinite(t)):
        return []
    median = float(np.median(positive))
    notes = []
    i = int(np.argmax(steps))
    if steps[i] > GAP_FACTOR * median:
        notes.append(f"the time stamps jump by {steps[i]:.4g} s (from {t[i]:.6g} s to {t[i + 1]:.6g} s), "
                     f"{steps[i] / median:.3g} times their median step of {median:.3g} s; resampling draws a "
                     "straight line across the gap: split the file there, or check the time column.")
    whole = bool(np.all(t == np.round(t)))
    if median >= 10.0 or (median >= 1.0 and (whole or float(np.max(np.abs(t))) >= 1e4)):
        notes.append(f"the time stamps step by {median:.4g} (median), a rate of {1 / median:.3g} Hz; if they are "
                     f"milliseconds, divide the time column by 1000 (the data would then be {1000 / median:.4g} Hz); "
                     "the time column is read in seconds.")
    return notes


#: Where networks train: the CPU, a CUDA GPU where torch sees one (``auto``), or CUDA (``cuda:N``: GPU N).
DEVICES = ("cpu", "auto", "cuda")


def check_device(device, error: type[Exception] = DataError) -> str:
    """``device`` if it names one of :data:`DEVICES` or ``"cuda:N"``, else ``error`` saying so."""
    if isinstance(device, str) and (device in DEVICES or (device.startswith("cuda:") and device[5:].isdigit())):
        return device
    raise error(f"The 'device' setting must be one of {', '.join(DEVICES)} or 'cuda:N' (N a GPU's index). "
                f"Got {device!r} instead.")
