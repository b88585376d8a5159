"""The rate of raw stamps is the slope of a line through them, not their median step (issue 53, item 1)."""

import numpy as np
import pytest

from physics.data import load_csvs, raw_rate


def _rounded(stamps, digits):
    """Stamps as a logger writes them: to a fixed number of significant digits."""
    return np.array([float(f"{t:.{digits}g}") for t in stamps])


def _ms_runs(seed, sizes=(6543, 6296, 6439)):
    """Whole-millisecond stamps of a 100 Hz clock, each 0-7 ms late (steps of 3-17 ms), with three gaps of
    70-280 ms (7-28 samples lost) in every run."""
    rng = np.random.default_rng(seed)
    runs = []
    for n in sizes:
        t = np.round(10.0 * np.arange(n) + rng.uniform(0.0, 7.0, n))
        keep = np.ones(n, dtype=bool)
        for start in rng.choice(np.arange(100, n - 100, 200), 3, replace=False):
            keep[start : start + rng.integers(7, 29)] = False
        runs.append(t[keep] / 1000.0)
    return runs


def test_stamps_written_to_seven_digits_keep_their_rate():
    stamps = _rounded(np.arange(3000) / 500.8, 7)  # steps of 1.996, 1.997 or 1.998 ms: the median read 501 Hz
    assert raw_rate([stamps]) == 500.8
    assert raw_rate([_rounded(np.arange(5000) / 1234.5, 6)]) == 1234.5


def test_repeated_stamps_are_one_sample_each():
    """A tracker that logs a sample 1-3 times: the index is of distinct stamps, not of rows."""
    rng = np.random.default_rng(1)
    stamps = np.repeat(_rounded(np.arange(3000) / 500.8, 7), rng.integers(1, 4, 3000))
    assert raw_rate([stamps]) == 500.8


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_whole_millisecond_stamps_with_jitter_and_gaps_read_at_the_clocks_rate(seed):
    runs = _ms_runs(seed)
    assert raw_rate(runs) == 100.0
    assert [raw_rate([run]) for run in runs] == [100.0] * 3
    # through the gaps the line would run slower: ~49 lost samples in ~6400 read 99.2 Hz
    joined = np.concatenate([r + 100.0 * i for i, r in enumerate(runs)])
    assert 1.0 / np.polyfit(np.arange(joined.size), joined, 1)[0] < 99.5


def test_runs_at_other_rates_are_left_out_of_the_shared_slope():
    slow, fast = np.arange(401) * 0.025, np.arange(401) * 0.0025  # 400 samples a period at 0.1 and 1 Hz
    assert raw_rate([slow, fast, fast, fast, fast]) == 400.0  # the rate most steps are taken at, as before
    assert raw_rate([slow, slow, slow, fast, fast]) == 40.0
    assert raw_rate([slow]) == 40.0 and raw_rate([fast]) == 400.0
    # as many steps at each of two rates: the faster one (the median of the steps was between them, 7.92 Hz)
    assert raw_rate([np.arange(401) * 0.25, fast]) == 400.0


def test_load_csvs_resamples_seven_digit_stamps_at_their_own_rate(tmp_path):
    n = 3000
    t = _rounded(np.arange(n) / 500.8, 7)
    u = np.sin(2 * np.pi * 3.0 * t)
    path = tmp_path / "run.csv"
    path.write_text("time,u,y\n" + "".join(f"{ti:.7g},{float(ui)!r},{2 * float(ui)!r}\n" for ti, ui in zip(t, u)))
    (run,) = load_csvs([path])
    assert run.meta["rate_hz"] == 500.8
    assert run.n == n  # at 501 Hz the same span gives 3001 rows
    np.testing.assert_allclose(np.diff(run.time), 1 / 500.8, rtol=1e-9)
