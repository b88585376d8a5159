"""Resampling of irregular, possibly duplicated time stamps onto a uniform grid."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import signal

from ._checks import as_float_array, check_finite, check_rate
from ._errors import DataError

__all__ = ["resample", "raw_rate"]

#: Butterworth cut-off as a fraction of the target rate (0.4 x rate = 0.8 x Nyquist).
CUTOFF_FRACTION = 0.4
#: Order of the anti-aliasing Butterworth filter (applied forwards and backwards).
FILTER_ORDER = 4
#: The fine grid runs at least this many times faster than the target rate.
MIN_OVERSAMPLING = 4
#: ...and at most this many times (bounds memory for very fast raw data).
MAX_OVERSAMPLING = 256


#: Fewest and most significant digits of a file's own rate (:func:`raw_rate`): a tidy rate for jittery
#: stamps, every digit of a regular one but none of the float noise of its steps.
RATE_DIGITS = (3, 9)

#: Most samples a resampled trajectory may have (about 1 GB of float64 columns): beyond it a rate is a typo.
MAX_SAMPLES = 10**8


def resample(
    time: ArrayLike, values: ArrayLike, rate_hz: float = 25.0
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Resample irregularly sampled data onto a uniform time grid.

    Duplicate time stamps are merged (their values averaged). When the raw
    rate (1 / median step) is at least twice ``rate_hz`` the data are
    down-sampled with anti-aliasing: linear interpolation onto a fine uniform
    grid at ``m * rate_hz`` (``m`` an integer, at least the raw rate and at
    least 4x the target, at most 256x), a zero-phase 4th-order Butterworth
    low-pass at ``0.4 * rate_hz`` (``scipy.signal.sosfiltfilt``, odd
    extension at the ends, so linear trends survive) and then every ``m``-th
    fine sample. Otherwise (up-sampling, or raw rate below twice the target)
    the data are linearly interpolated, with no filter.

    Parameters
    ----------
    time : array_like, shape (n,)
        Raw time stamps in seconds; non-decreasing (duplicates allowed).
    values : array_like, shape (n,) or (n, k)
        Raw samples, one row per time stamp.
    rate_hz : float, default 25.0
        Target sampling rate in Hz.

    Returns
    -------
    new_time : ndarray, shape (m,)
        ``time[0] + k / rate_hz`` for every ``k`` with the result inside the
        raw span ``[time[0], time[-1]]``.
    new_values : ndarray, shape (m,) or (m, k)
        Resampled values, same number of dimensions as ``values``.

    Raises
    ------
    DataError
        Time decreasing (the index is named), NaN or inf, fewer than two
        distinct time stamps, a span shorter than one output step, or
        ``rate_hz <= 0``.

    Examples
    --------
    >>> t = np.array([0.0, 0.01, 0.01, 0.03, 0.05, 0.08, 0.1])
    >>> new_t, new_v = resample(t, 2 * t, rate_hz=50.0)
    >>> new_t
    array([0.  , 0.02, 0.04, 0.06, 0.08, 0.1 ])
    """
    rate = check_rate(rate_hz)
    t, v = _validate(time, values)
    t, v = merge_duplicates(t, v)
    if t.size < 2:
        raise DataError(
            "time has fewer than 2 distinct stamps (all samples share one time). "
            "Resampling needs at least two different times."
        )
    span = t[-1] - t[0]
    n_out = int(np.floor(span * rate + 1e-9)) + 1
    if n_out < 2:
        raise DataError(
            f"the raw span ({span:g} s) is shorter than one output step (1/{rate:g} Hz = {1 / rate:g} s), "
            "so the output would have a single sample. Use a higher rate (--rate, rate_hz=) or a longer recording."
        )
    if n_out > MAX_SAMPLES:
        raise DataError(f"resampling {span:g} s at {rate:g} Hz would give {n_out:.3g} samples (the limit is "
                        f"{MAX_SAMPLES:.0e}); use a lower rate (--rate, rate_hz=).")
    new_t = t[0] + np.arange(n_out) / rate
    raw_rate = 1.0 / float(np.median(np.diff(t)))
    squeeze = v.ndim == 1
    v2 = v[:, None] if squeeze else v
    if raw_rate >= 2.0 * rate:
        out = _filtered(t, v2, rate, raw_rate, n_out)
    else:
        out = _interp_columns(new_t, t, v2)
    return new_t, (out[:, 0] if squeeze else out)


def raw_rate(times) -> float:
    """The rate the raw stamps of one or several runs were taken at, Hz, to the digits they carry.

    The median of the positive steps pooled over all runs (repeated stamps are ignored), so
    jitter and a few gaps do not move it, and every run of a data set gets the same rate. It keeps
    as many significant digits as the steps agree to (their interquartile spread, or the float64
    resolution of the stamps when that is wider: unix-time stamps), from
    :data:`RATE_DIGITS` ``[0]`` for jittery stamps (a logger's ~500 Hz is 500) to ``[1]`` for
    regular ones, so a file written at 500.8 Hz is read at 500.8 Hz, not 501.

    >>> raw_rate([np.arange(0, 1, 0.002), np.array([0.0, 0.0021, 0.0040, 0.0061])])
    500.0
    >>> raw_rate([np.arange(3000) / 500.8])
    500.8
    >>> raw_rate([1.7e9 + np.arange(400) * 0.04])  # unix time: steps rounded to 2.4e-7 s
    25.0
    """
    times = [as_float_array(t, "time") for t in times]
    steps = np.concatenate([np.diff(t) for t in times] or [np.zeros(0)])
    steps = steps[np.isfinite(steps) & (steps > 0)]
    if steps.size == 0:
        raise DataError("the time stamps never increase, so they have no rate; check the time column.")
    median = float(np.median(steps))
    q1, q3 = np.percentile(steps, [25, 75])
    # a step is known to about two float64 spacings of the stamps: unix-time stamps (1.7e9 s) step by
    # 0.04 +/- 2.4e-7 s, which are 25 Hz, not the 25.0000238 Hz of their rounded differences
    resolution = 2.0 * max(float(np.spacing(np.max(np.abs(t[np.isfinite(t)]), initial=0.0))) for t in times)
    spread = max(float(q3 - q1), resolution) / median
    low, high = RATE_DIGITS
    digits = high if spread <= 0 else int(np.clip(np.floor(-np.log10(spread)), low, high))
    return float(f"{1.0 / median:.{digits}g}")


def _validate(time: ArrayLike, values: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    t = as_float_array(time, "time")
    v = as_float_array(values, "values", ndim=(1, 2))
    if v.shape[0] != t.shape[0]:
        raise DataError(
            f"time has {t.shape[0]} samples but values has {v.shape[0]} rows. "
            "Pass one row of values per time stamp."
        )
    if t.size < 2:
        raise DataError(f"resampling needs at least 2 samples; got {t.size}.")
    check_finite(t, "time")
    check_finite(v, "values")
    dec = np.flatnonzero(np.diff(t) < 0)
    if dec.size:
        i = int(dec[0]) + 1
        raise DataError(
            f"time decreases at index {i} ({float(t[i - 1])!r} -> {float(t[i])!r}). Raw time may repeat but must not "
            "go backwards; sort the samples or cut the file where the clock restarts."
        )
    return t, v


def merge_duplicates(
    t: NDArray[np.float64], v: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Average the rows of ``v`` that share a time stamp (``t`` non-decreasing)."""
    new = np.empty(t.size, dtype=bool)
    new[0] = True
    np.not_equal(t[1:], t[:-1], out=new[1:])
    if new.all():
        return t, v
    group = np.cumsum(new) - 1
    counts = np.bincount(group).astype(np.float64)
    flat = v.reshape(v.shape[0], -1)
    sums = np.zeros((counts.size, flat.shape[1]))
    np.add.at(sums, group, flat)
    merged = (sums / counts[:, None]).reshape((counts.size,) + v.shape[1:])
    return t[new], merged


def _interp_columns(
    new_t: NDArray[np.float64], t: NDArray[np.float64], v: NDArray[np.float64]
) -> NDArray[np.float64]:
    out = np.empty((new_t.size, v.shape[1]))
    for j in range(v.shape[1]):
        out[:, j] = np.interp(new_t, t, v[:, j])
    return out


def _filtered(
    t: NDArray[np.float64], v: NDArray[np.float64], rate: float, raw_rate: float, n_out: int
) -> NDArray[np.float64]:
    m = int(np.clip(np.ceil(raw_rate / rate), MIN_OVERSAMPLING, MAX_OVERSAMPLING))
    fine_rate = m * rate
    n_fine = int(np.floor((t[-1] - t[0]) * fine_rate + 1e-9)) + 1
    fine_t = t[0] + np.arange(n_fine) / fine_rate
    fine = _interp_columns(fine_t, t, v)
    sos = signal.butter(FILTER_ORDER, CUTOFF_FRACTION * rate, fs=fine_rate, output="sos")
    # sosfiltfilt needs more samples than its pad length; short records get a shorter pad.
    # Pad by a few cut-off periods so the odd extension absorbs the edge transient.
    padlen = min(int(np.ceil(4 * fine_rate / (CUTOFF_FRACTION * rate))), n_fine - 1)
    filtered = signal.sosfiltfilt(sos, fine, axis=0, padtype="odd", padlen=padlen)
    return filtered[: (n_out - 1) * m + 1 : m]
