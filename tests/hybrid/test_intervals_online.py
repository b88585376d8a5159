"""Online intervals from measurements (issue 45): ``AdaptiveIntervals`` (adaptive conformal inference)."""

import numpy as np
import pytest

from hybrid.intervals import AdaptiveIntervals, AdaptiveState, ConformalIntervals, HeldOut, coverage
from hybrid.intervals._adaptive import QUANTILES, lag_scores
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


def test_lag_scores_are_the_quantiles_of_what_the_forecast_misses_at_each_lag():
    e = np.array([0.0, 1.0, 3.0, 6.0])
    table, rho = lag_scores([e], 3)
    assert table.shape == (3, QUANTILES) and rho.shape == (3,)
    assert rho[0] == 1.0  # (0*1 + 1*3 + 3*6) / (0 + 1 + 9) = 2.1, kept to 1: a drift, not a growth
    assert (table[0, 0], table[0, -1]) == (1.0, 3.0)  # |1-0|, |3-1|, |6-3|
    assert (table[1, 0], table[1, -1]) == (3.0, 5.0)  # |3-0|, |6-1|
    np.testing.assert_array_equal(table[2], table[1])  # one pair only at lag 3: the last lag with two repeats
    white = np.random.default_rng(0).normal(0, 1, (4, 2000))
    table, rho = lag_scores(list(white), 5)
    assert np.all(np.abs(rho) < 0.03)  # white noise: a measurement says nothing of the next sample
    assert table[0, 900] == pytest.approx(1.645, rel=0.05)  # and the band is the noise's own


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
    assert s0 == AdaptiveState(0.9, 0.0, 0, 0) and online.half_width(s0) == pytest.approx(calibrated.quantile())
    s1 = online.update(s0, 2.0)
    assert (s1.offset, s1.since, s1.measured, s0.measured) == (2.0, 0, 1, 0)  # s0 untouched
    assert online.centre(online.advance(s1, 3)) == pytest.approx(2.0 * online.rho_[2]) and online.rho_[2] > 0.9
    assert online.half_width(online.advance(s1, 1)) < online.half_width(online.advance(s1, 20))
    assert online.half_width(s1, ahead=20) == online.half_width(online.advance(s1, 20))
    missed = online.update(online.advance(s1, 25), 2.0 + 10 * online.half_width(online.advance(s1, 25)))
    assert missed.level == pytest.approx(0.9 + 0.05 * 0.9)


def test_clear_errors(calibrated):
    with pytest.raises(DataError, match="every must be a whole number"):
        AdaptiveIntervals(every=0).fit(calibrated)
    with pytest.raises(DataError, match="gamma must be"):
        AdaptiveIntervals(gamma=1.5).fit(calibrated)
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
    state = online.update(online.initial(), 1.5)
    for level in (0.0, 0.5, 0.9, 0.95, 1.0, 1.04):
        for since in (1, 7, 25, 40):
            s = state._replace(level=level, since=since)
            centre, half = (float(v) for v in band(level, s.offset, since))
            assert centre == pytest.approx(online.centre(s), abs=1e-12)
            assert half == pytest.approx(float(online.half_width(s)), rel=1e-9, abs=1e-12)
    s = online.advance(state, 25)
    for residual in (1.5, 1.5 + 10 * float(online.half_width(s))):
        expected = online.update(s, residual).level
        got = float(step(s.level, residual, online.centre(s), online.half_width(s)))
        assert got == pytest.approx(expected, abs=1e-12)
