"""Online intervals from measurements (issue 45): ``AdaptiveIntervals`` (adaptive conformal inference)."""

import numpy as np
import pytest

from hybrid.intervals import AdaptiveIntervals, AdaptiveState, ConformalIntervals, HeldOut, coverage
from hybrid.intervals._forecast import (BETAS, MAX_PRIOR, PHASES, QUANTILES, error_forecast, running_offsets, scale_prior,
                                        start_factor)
from physics.data import DataError, NotFittedError, Trajectory

DT = 0.04


def _run(rng, offset: float, n: int = 600, drift: float = 0.05, source: str = ""):
    """A run whose error is an offset plus a random walk (the drift a free run builds up)."""
    t = np.arange(n) * DT
    u = 1.5 * (1 - np.cos(2 * np.pi * 0.3 * t))
    y_hat = 10 * u
    return Trajectory(t, u, y_hat + offset + np.cumsum(rng.normal(0, drift, n)), source=source), y_hat


@pytest.fixture(scope="module")
def calibrated():
    rng = np.random.default_rng(0)
    train = [_run(rng, 0.0, source=f"t{i}")[0] for i in range(4)]
    held = [HeldOut(*_run(rng, rng.normal(0, 0.5), source=f"h{i}"), train) for i in range(6)]
    return ConformalIntervals(0.9).fit(train, held)


def test_the_running_offset_is_a_start_corrected_moving_mean():
    """Weights beta / (1 - (1 - beta)^k): the first residual whole, then the plain mean of the first
    few (the bias-corrected exponential mean: with beta 0.5, m_k = (m_{k-1} + r_k) / 2 over 1 - 0.5^k)."""
    np.testing.assert_allclose(running_offsets(np.array([2.0, 4.0, 6.0]), 0.5), [2.0, 10 / 3, 34 / 7])
    np.testing.assert_allclose(running_offsets(np.array([2.0, 4.0, 6.0]), 1.0), [2.0, 4.0, 6.0])
    assert running_offsets(np.full(400, 3.0), 0.05)[-1] == pytest.approx(3.0)


def test_the_error_forecast_measures_out_an_offset_and_leaves_white_noise_alone():
    rng = np.random.default_rng(0)
    white = list(rng.normal(0, 1, (4, 2000)))
    fc = error_forecast(white, 5, 0.9)
    assert fc.table.shape == (5, QUANTILES) and fc.coef.shape == (5, 2) and fc.beta in BETAS
    # a measurement says nothing of the next sample (the running offset of white noise is near 0 whatever its weight)
    assert np.all(np.abs(fc.coef[:, 0]) < 0.05) and np.all(np.abs(fc.coef[:, 1]) < 0.2)
    assert fc.table[0, 900] == pytest.approx(1.645, rel=0.05)  # and the band is the noise's own
    offsets = rng.normal(0, 5, 8)
    shifted = [m + rng.normal(0, 1, 2000) for m in offsets]
    fc = error_forecast(shifted, 25, 0.9)
    assert fc.beta < 0.5 and np.all(fc.coef[:, 1] > 0.9)  # the running offset carries the forecast
    assert fc.table[-1, 900] < 1.2 * 1.645  # what is left is the noise (and the offset's estimation error)
    short = [np.array([0.0, 1.0, 3.0])]
    fc = error_forecast(short, 4, 0.9)  # lags 1 and 2 only: longer ones repeat lag 2's
    np.testing.assert_array_equal(fc.table[3], fc.table[1])
    with pytest.raises(DataError, match="too short"):
        error_forecast([np.array([1.0])], 3, 0.9)


def test_online_band_covers_a_run_far_from_the_calibration_and_narrows(calibrated):
    """A long run offset by 8 (the held-out runs by ~0.5) and drifting: the offline band misses most of
    it; measured every 25 samples, the online band covers 85-95 % of all its samples, and is narrower
    than the offline band on a run the calibration fits."""
    rng = np.random.default_rng(1)
    online = AdaptiveIntervals(every=25).fit(calibrated)
    far, y_hat = _run(rng, 8.0, n=3000)
    offline = calibrated.interval(y_hat, far.u, far.dt)
    band = online.run(y_hat, far.u, far.dt, far.y)
    assert coverage(far.y, offline.lo, offline.hi) < 0.2
    assert 0.85 <= coverage(far.y, band.lo, band.hi) <= 0.95
    like, y_hat = _run(rng, 0.3, n=3000)
    band = online.run(y_hat, like.u, like.dt, like.y)
    assert np.mean(band.hi - band.lo) < 0.7 * np.mean(offline.hi - offline.lo)
    assert 0.85 <= coverage(like.y, band.lo, band.hi) <= 0.97


def test_aci_holds_the_miss_rate_where_the_calibration_is_far_too_narrow(calibrated):
    """Drift 8 times the calibration's: the misses at the measured samples tend to 10 % (ACI's bound
    after K measurements, (L_max + gamma) / (gamma K), is loose; 0.05 here)."""
    rng = np.random.default_rng(2)
    online = AdaptiveIntervals(every=10, gamma=0.05).fit(calibrated)
    run, y_hat = _run(rng, 0.0, n=20000, drift=0.4)
    state, misses = online.initial(), []
    for t in range(run.n):
        state = online.advance(state) if t else state
        if t % 10 == 0:
            if state.measured:
                misses.append(abs(run.y[t] - y_hat[t] - online.centre(state)) > online.half_width(state))
            state = online.update(state, run.y[t] - y_hat[t])
    assert abs(np.mean(misses) - 0.1) < 0.05, np.mean(misses)


def test_the_state_is_explicit_and_the_band_widens_with_the_samples_since_a_measurement(calibrated):
    online = AdaptiveIntervals(every=25).fit(calibrated)
    s0 = online.initial()
    assert s0 == AdaptiveState(0.9, 0.0, 0.0, 1.0, 0, 0) and online.half_width(s0) == pytest.approx(calibrated.quantile())
    s1 = online.update(s0, 2.0)
    assert (s1.offset, s1.residual, s1.since, s1.measured, s0.measured) == (2.0, 2.0, 0, 1, 0)  # s0 untouched
    a, b = online.forecast_.coef[2]
    assert online.centre(online.advance(s1, 3)) == pytest.approx(2.0 * (a + b)) and a + b > 0.9  # a drift stays
    s2 = online.update(online.advance(s1, 25), 4.0)
    w = online.forecast_.beta / (1 - (1 - online.forecast_.beta) ** 2)
    assert (s2.offset, s2.residual, s2.since, s2.measured) == pytest.approx((2.0 + w * 2.0, 4.0, 0, 2))
    assert online.half_width(online.advance(s1, 1)) < online.half_width(online.advance(s1, 20))
    assert online.half_width(s1, ahead=20) == online.half_width(online.advance(s1, 20))
    missed = online.update(online.advance(s1, 25), 2.0 + 10 * online.half_width(online.advance(s1, 25)))
    assert missed.level == pytest.approx(0.9 + 0.05 * 0.9)


def test_clear_errors(calibrated):
    with pytest.raises(DataError, match="every must be a whole number"):
        AdaptiveIntervals(every=0).fit(calibrated)
    with pytest.raises(DataError, match="gamma must be"):
        AdaptiveIntervals(gamma=1.5).fit(calibrated)
    with pytest.raises(DataError, match="prior must be a number of measurements > 0"):
        AdaptiveIntervals(prior=0).fit(calibrated)
    assert AdaptiveIntervals(prior=20).fit(calibrated).prior_ == 20.0  # a number fixes it, as before
    with pytest.raises(DataError, match="needs calibrated ConformalIntervals"):
        AdaptiveIntervals().fit(ConformalIntervals())
    with pytest.raises(NotFittedError, match="Call fit"):
        AdaptiveIntervals().initial()
    online = AdaptiveIntervals().fit(calibrated)
    with pytest.raises(DataError, match="must be finite"):
        online.update(online.initial(), float("nan"))
    with pytest.raises(DataError, match="boolean mask as long as the run"):
        online.run(np.zeros(10), np.zeros(10), DT, np.zeros(10), measured=np.ones(3, bool))


def test_hyst_predict_measure_every_adapts_the_band(fitted_linear, tmp_path, capsys):
    """A folder fitted on one simulated run (intervals from its pieces): with --measure-every the band is
    online, and on the run it was fitted on it is narrower than the offline band."""
    from hybrid.cli import main

    run, model = fitted_linear / "run.csv", fitted_linear / "model"
    widths = {}
    for extra in ([], ["--measure-every", "25"]):
        out = tmp_path / f"p{len(extra)}.csv"
        assert main(["predict", str(model), str(run), "--warmup", "10", "--interval", "0.9", "--out", str(out),
                     *extra]) == 0
        data = np.genfromtxt(out, delimiter=",", names=True)
        widths[bool(extra)] = float(np.mean(data["y_hi"] - data["y_lo"]))
    printed = capsys.readouterr().out
    assert "interval (online: adapted at each measurement)" in printed
    assert widths[True] < widths[False]


def test_the_casadi_band_matches_the_python_one(calibrated):
    """``function()`` and ``update_function()`` (for an export or a C controller) against ``centre``,
    ``half_width`` and ``update``: exact at the table's levels, within the table's spacing between."""
    online = AdaptiveIntervals(every=25).fit(calibrated)
    band, step = online.function(), online.update_function()
    state = online.update(online.advance(online.update(online.initial(), 1.5), 25), 0.7)
    assert state.scale != 1.0
    for level, measured in zip((0.0, 0.5, 0.9, 0.95, 1.0, 1.04), (1, 2, 3, 7, 2, 10 ** 5)):
        for since in (1, 7, 25, 40):
            s = state._replace(level=level, since=since, measured=measured)  # the start factor of each
            centre, half = (float(v) for v in band(level, s.offset, s.residual, s.scale, since, s.measured))
            assert centre == pytest.approx(online.centre(s), abs=1e-12)
            assert half == pytest.approx(float(online.half_width(s)), rel=1e-9, abs=1e-12)
    for s in (online.advance(state, 25), online.advance(state, 7), online.initial()):
        for residual in (1.5, 1.5 + 10 * float(online.half_width(s))):
            for sigma in (1.0, 1.7):
                expected = online.update(s, residual, sigma)
                got = step(*s, residual, sigma)
                assert [float(v) for v in got] == pytest.approx([expected.level, expected.offset, expected.scale],
                                                                abs=1e-12)


def test_the_prior_is_the_held_out_runs_noise_over_their_spread_of_scales():
    """Empirical Bayes (``scale_prior``): white-noise runs of standard deviations 0.5, 1, 2 and 4 miss a
    forecast of ~0 by ``|e|``, whose mean is ``sigma sqrt(2/pi)`` and variance ``sigma^2 (1 - 2/pi)``:
    the within-run variance of the ratios over the mean is ``(pi/2 - 1) mean(sigma^2) / mean(sigma)^2``,
    the runs' mean ratios are ``sigma / mean(sigma)``, and the prior their quotient (1.27 measurements).
    Runs of one scale differ by no more than their noise: the calibration's scale stands."""
    rng = np.random.default_rng(0)
    sigma = np.array([0.5, 1.0, 2.0, 4.0])
    runs = [s * rng.normal(0, 1, 5000) for s in sigma]
    fc = error_forecast(runs, 25, 0.9)
    within = (np.pi / 2 - 1) * np.mean(sigma ** 2) / sigma.mean() ** 2
    assert scale_prior(runs, fc, 25) == pytest.approx(within / np.var(sigma / sigma.mean(), ddof=1), rel=0.1)
    same = [rng.normal(0, 1, 5000) for _ in range(4)]
    assert scale_prior(same, error_forecast(same, 25, 0.9), 25) == MAX_PRIOR
    assert scale_prior(runs[:1], fc, 25) == MAX_PRIOR  # one run shows no spread


def test_the_start_factor_follows_a_fading_start_transient():
    """Runs whose noise is ``1 + 2 exp(-t / 100)`` times white: the misses after the first measurement
    over the settled ones (1) are the amplitude's mean over the 25 samples after it, averaged over the
    replays' starts (2.57); the factor never grows, and white noise of one amplitude has none (1
    within 5 %)."""
    rng = np.random.default_rng(0)
    amp = 1 + 2 * np.exp(-np.arange(3000) / 100)
    fc = error_forecast([amp * rng.normal(0, 1, 3000) for _ in range(12)], 25, 0.9)
    first = np.mean([amp[p + 1:p + 26].mean() for p in np.linspace(0, 24, PHASES).astype(int)])
    assert fc.start[0] / np.median(fc.start[40:]) == pytest.approx(first, rel=0.1)
    assert np.all(np.diff(fc.start) <= 0) and fc.factor(1) == fc.start[0] and fc.factor(10 ** 6) == fc.start[-1]
    flat = error_forecast([rng.normal(0, 1, 3000) for _ in range(6)], 25, 0.9)
    np.testing.assert_allclose(flat.start, 1.0, atol=0.05)
    run, k, lag, miss = (np.array([0, 0, 1, 1]), np.array([0, 1, 0, 1]), np.array([1, 1, 1, 1]), np.zeros(4))
    np.testing.assert_array_equal(start_factor(run, k, lag, miss), [1.0, 1.0])  # no misses: no transient


def test_the_nested_replay_is_the_band_fitted_without_each_run(calibrated):
    """``nested_coverage`` against the same replay through the public API: each held-out run's errors
    measured every 25 samples on a band fitted on the other five runs; the share of the samples after
    each run's first inside (ACI aims at 90 %)."""
    online = AdaptiveIntervals(every=25).fit(calibrated)
    hits = []
    for i, e in enumerate(calibrated.errors_):
        others = ConformalIntervals(0.9)
        others.__dict__.update(calibrated.__dict__)
        keep = [j for j in range(len(calibrated.errors_)) if j != i]
        others.errors_, others.residuals_ = [calibrated.errors_[j] for j in keep], [calibrated.residuals_[j] for j in keep]
        others.runs_, others.conditions_, others._cache = [calibrated.runs_[j] for j in keep], [None] * 5, {}
        fold = AdaptiveIntervals(every=25).fit(others)
        state = fold.update(fold.initial(), e[0])
        for t in range(1, e.size):
            state = fold.advance(state)
            hits.append(abs(e[t] - fold.centre(state)) <= fold.half_width(state))
            state = fold.update(state, e[t]) if t % 25 == 0 else state
    assert online.nested_coverage() == pytest.approx(np.mean(hits), abs=1e-12)
    assert 0.85 <= online.nested_coverage() <= 0.95
    two = ConformalIntervals(0.9)
    two.__dict__.update(calibrated.__dict__)
    two.errors_, two.residuals_, two.conditions_ = calibrated.errors_[:2], calibrated.residuals_[:2], [None, None]
    two.runs_, two._cache = calibrated.runs_[:2], {}
    assert AdaptiveIntervals(every=25).fit(two).nested_coverage() is None  # 2 runs: a fold would keep 1
