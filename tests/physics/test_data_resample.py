"""Resampler: unit checks and hypothesis properties on irregular stamps with duplicates."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from physics.data import DataError, resample

RATE = 25.0


@st.composite
def raw_stamps(draw, fast=True):
    """Irregular increasing stamps (steps 0.4-4 ms, or 10-100 ms when slow) with some duplicates."""
    seed = draw(st.integers(0, 2**32 - 1))
    n = draw(st.integers(800, 3000) if fast else st.integers(20, 200))
    rng = np.random.default_rng(seed)
    lo, hi = (0.0004, 0.004) if fast else (0.01, 0.1)
    steps = rng.uniform(lo, hi, n)
    steps[rng.random(n) < 0.05] = 0.0  # duplicate stamps
    t0 = draw(st.floats(-10.0, 10.0))
    return t0 + np.concatenate([[0.0], np.cumsum(steps)])


def _check_grid(t, new_t, rate):
    assert new_t[0] == t[0]
    np.testing.assert_allclose(np.diff(new_t), 1.0 / rate, rtol=1e-9, atol=1e-9)
    assert new_t[-1] <= t[-1] + 1e-9
    assert t[-1] - new_t[-1] < 1.0 / rate  # the grid covers the span


@settings(max_examples=25, deadline=None)
@given(t=raw_stamps(), slope=st.floats(-5, 5), offset=st.floats(-100, 100))
def test_downsampling_grid_and_linear_signal(t, slope, offset):
    values = slope * (t - t[0]) + offset
    new_t, new_v = resample(t, values, RATE)
    _check_grid(t, new_t, RATE)
    np.testing.assert_allclose(new_v, slope * (new_t - t[0]) + offset, atol=1e-3 * (1 + abs(slope)))


@settings(max_examples=25, deadline=None)
@given(t=raw_stamps(fast=False), slope=st.floats(-5, 5))
def test_upsampling_is_linear_interpolation(t, slope):
    new_t, new_v = resample(t, np.column_stack([slope * t, np.ones_like(t)]), 50.0)
    _check_grid(t, new_t, 50.0)
    np.testing.assert_allclose(new_v[:, 0], slope * new_t, atol=1e-7 * (1 + abs(slope)))
    np.testing.assert_allclose(new_v[:, 1], 1.0, rtol=1e-12)


@settings(max_examples=25, deadline=None)
@given(t=raw_stamps(), c=st.floats(-1e3, 1e3))
def test_constant_stays_constant(t, c):
    _, new_v = resample(t, np.full_like(t, c), RATE)
    np.testing.assert_allclose(new_v, c, atol=1e-9 * (1 + abs(c)))


@settings(max_examples=20, deadline=None)
@given(t=raw_stamps(), f_low=st.floats(0.2, 2.0), f_high=st.floats(30.0, 60.0))
def test_low_sine_kept_high_tone_attenuated(t, f_low, f_high):
    low = np.sin(2 * np.pi * f_low * t)
    high = np.sin(2 * np.pi * f_high * t)
    new_t, new_v = resample(t, np.column_stack([low, high]), RATE)
    inner = slice(10, -10)  # away from the ends where the filter pads
    np.testing.assert_allclose(new_v[inner, 0], np.sin(2 * np.pi * f_low * new_t[inner]), atol=0.01)
    assert np.abs(new_v[inner, 1]).max() < 0.1  # tone above the new Nyquist (12.5 Hz)


def test_duplicates_are_averaged_when_upsampling():
    t = np.array([0.0, 1.0, 1.0, 2.0])
    v = np.array([0.0, 1.0, 3.0, 2.0])  # the duplicate at t=1 averages to 2
    new_t, new_v = resample(t, v, 1.0)
    np.testing.assert_array_equal(new_t, [0.0, 1.0, 2.0])
    np.testing.assert_allclose(new_v, [0.0, 2.0, 2.0])


@pytest.mark.parametrize(
    ("time", "values", "rate", "match"),
    [
        ([0.0, 1.0, 0.5], [0.0, 1.0, 2.0], 10.0, r"time decreases at index 2"),
        ([0.0, 1.0, 2.0], [0.0, np.nan, 2.0], 10.0, r"values has a non-finite value .* at index 1"),
        ([0.0], [0.0], 10.0, r"at least 2 samples"),
        ([1.0, 1.0], [0.0, 1.0], 10.0, r"fewer than 2 distinct"),
        ([0.0, 1.0], [0.0, 1.0], 0.0, r"rate_hz must be a finite number > 0"),
        ([0.0, 1.0], [0.0, 1.0], -5.0, r"rate_hz must be a finite number > 0"),
        ([0.0, 0.01], [0.0, 1.0], 10.0, r"shorter than one output step"),
        ([0.0, 1.0, 2.0], [0.0, 1.0], 10.0, r"time has 3 samples but values has 2 rows"),
    ],
)
def test_errors(time, values, rate, match):
    with pytest.raises(DataError, match=match):
        resample(np.array(time), np.array(values), rate)
