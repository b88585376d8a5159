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

    The slope of a least-squares line of the stamps on the sample index, one slope shared by every run
    (each run, and each stretch between gaps, keeps its own offset), so stamps rounded to a few digits,
    jitter and gaps do not move it and every run of a data set gets the same rate. The sample index counts
    distinct stamps (a repeated stamp is one sample logged twice). The typical step is the median of the
    positive steps pooled over all runs (the lower one of an even count: runs at two rates in equal numbers
    are read at the faster one, not between them); a step more than :data:`STEP_BAND` times it is a gap (samples were
    lost there, so the line starts again after it), and a run whose median step is :data:`STEP_BAND` times
    above or below it was taken at another rate and is left out. The rate keeps as many significant digits
    as the fit supports: its last digit is at least ten times the slope's standard error (from the residuals,
    which are at least the stamps' float64 resolution, and inflated by their lag-one correlation when the
    steps themselves jitter), from :data:`RATE_DIGITS` ``[0]`` to ``[1]``. So a 500.8 Hz file is read at
    500.8 Hz, not 501, even with stamps written to 7 significant digits.

    >>> raw_rate([np.arange(0, 1, 0.002), np.array([0.0, 0.0021, 0.0040, 0.0061])])
    500.0
    >>> raw_rate([np.arange(3000) / 500.8])
    500.8
    >>> raw_rate([np.array([float(f"{k / 500.8:.7g}") for k in range(3000)])])  # stamps rounded to 1e-6 s
    500.8
    >>> raw_rate([1.7e9 + np.arange(400) * 0.04])  # unix time: steps rounded to 2.4e-7 s
    25.0
    """
    runs = [_distinct(as_float_array(t, "time")) for t in times]
    steps = np.concatenate([np.diff(t) for t in runs] or [np.zeros(0)])
    steps = steps[steps > 0]
    if steps.size == 0:
        raise DataError("the time stamps never increase, so they have no rate; check the time column.")
    typical = float(np.percentile(steps, 50, method="lower"))  # a step of some run: a tie of two rates is not their mean
    pieces = [piece for t in runs if t.size > 1 and _same_rate(np.diff(t), typical)
              for piece in np.split(t, np.flatnonzero(np.diff(t) > STEP_BAND * typical) + 1) if piece.size > 1]
    if not pieces:  # every run at its own rate, none at the typical one: the typical step, to few digits
        return float(f"{1.0 / typical:.{RATE_DIGITS[0]}g}")
    slope, error = _shared_slope(pieces)
    low, high = RATE_DIGITS
    rate = 1.0 / slope
    # the last digit kept is ten times the rate's standard error or more, so rounding lands on the true rate
    digits = high if error <= 0 else int(np.clip(np.floor(np.log10(rate) - np.log10(10 * rate * error / slope)) + 1,
                                                 low, high))
    return float(f"{rate:.{digits}g}")


#: A step more than this many times the typical step is a gap (:func:`raw_rate`), and a run whose median step
#: is this many times above or below the typical step was taken at another rate.
STEP_BAND = 2.0


def _distinct(t: NDArray[np.float64]) -> NDArray[np.float64]:
    """A run's finite stamps with each repeated stamp kept once (its sample index counts distinct stamps)."""
    t = t[np.isfinite(t)]
    return t[np.r_[True, np.diff(t) != 0]] if t.size else t


def _same_rate(steps: NDArray[np.float64], typical: float) -> bool:
    positive = steps[steps > 0]
    return positive.size > 0 and 1 / STEP_BAND <= float(np.median(positive)) / typical <= STEP_BAND


def _shared_slope(pieces: list[NDArray[np.float64]]) -> tuple[float, float]:
    """Least-squares step of stamps on their index, one slope and one offset a piece, and its standard error."""
    k = [np.arange(p.size) - (p.size - 1) / 2 for p in pieces]
    t = [p - p[0] for p in pieces]  # exact for nearby stamps: unix time keeps its steps' digits
    t = [ti - ti.mean() for ti in t]
    sxx = sum(float(ki @ ki) for ki in k)
    slope = sum(float(ki @ ti) for ki, ti in zip(k, t)) / sxx
    resid = [ti - slope * ki for ki, ti in zip(k, t)]
    n = sum(p.size for p in pieces)
    dof = n - len(pieces) - 1
    resolution = max(float(np.spacing(np.max(np.abs(p)))) for p in pieces)
    sigma2 = max(sum(float(r @ r) for r in resid) / dof if dof > 0 else 0.0, resolution**2 / 12)
    # residuals that wander (the steps, not the stamps, jitter) are worth fewer samples: AR(1) inflation
    lag = sum(float(r[1:] @ r[:-1]) for r in resid)
    power = sum(float(r @ r) for r in resid)
    rho = min(max(lag / power, 0.0), 0.999) if power > 0 else 0.0
    return slope, float(np.sqrt(sigma2 / sxx * (1 + rho) / (1 - rho)))


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
