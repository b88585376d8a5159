"""Conformal intervals (``hybrid.intervals``): coverage on exchangeable runs, flags off the data, bad input."""

import numpy as np
import pytest

from hybrid.intervals import ConformalIntervals, ConformalModel, DataDistance, HeldOut, coverage, input_rows
from identification import PhysicsEstimator
from physics import Series
from physics.data import DataError, NotFittedError, Trajectory, warmup_split

DT = 0.04


def _run(rng, seed_bias: float, n: int = 400, amplitude: float = 3.0, source: str = "",
         f: float | None = None) -> tuple[Trajectory, np.ndarray]:
    """A run of a sinusoid-like input, its 'prediction' (the truth) and a measurement with a run
    offset and autocorrelated noise: errors that are exchangeable across runs, not within one."""
    t = np.arange(n) * DT
    f = rng.uniform(0.1, 0.5) if f is None else f
    u = amplitude * (1 - np.cos(2 * np.pi * f * t)) / 2
    y_hat = 10 * u
    noise = np.convolve(rng.normal(0, 1, n + 20), np.ones(20) / np.sqrt(20), mode="valid")[:n]
    return Trajectory(t, u, y_hat + seed_bias + noise, source=source), y_hat


def _held_out(rng, k: int, train):
    out = []
    for i in range(k):
        run, y_hat = _run(rng, rng.normal(0, 1.0), source=f"held{i}")
        out.append(HeldOut(run, y_hat, train))
    return out


@pytest.fixture(scope="module")
def train():
    rng = np.random.default_rng(1)
    return [_run(rng, 0.0, source=f"train{i}")[0] for i in range(4)]


@pytest.mark.parametrize("k, low, groups", [(40, 0.89, 40), (12, 0.89, 48), (4, 0.85, 40)])
def test_coverage_on_new_exchangeable_runs_is_near_the_level(train, k, low, groups):
    """Averaged over many calibrations, the share of a new run's samples inside the 90 % interval.
    With 40 held-out runs, the runs are the groups: at least 90 % (the conformal guarantee, runs
    exchangeable; 0.01 for the 60 draws' own spread). With fewer, segments of them are: a weaker
    assumption; here, where each run carries its own offset, 4 runs cover somewhat less (0.88)."""
    rng = np.random.default_rng(k)
    covered = []
    for _ in range(60):
        intervals = ConformalIntervals(0.9).fit(train, _held_out(rng, k, train))
        run, y_hat = _run(rng, rng.normal(0, 1.0), f=0.3)
        band = intervals.interval(y_hat, run.u, run.dt)
        covered.append(coverage(run.y, band.lo, band.hi))
    assert low <= np.mean(covered) <= 0.99, np.mean(covered)
    assert len(intervals.groups()) == groups


def test_width_grows_and_samples_are_flagged_outside_the_data(train):
    rng = np.random.default_rng(3)
    intervals = ConformalIntervals(0.9).fit(train, _held_out(rng, 6, train))
    inside, y_in = _run(rng, 0.0, f=0.3)
    far, y_far = _run(rng, 0.0, amplitude=9.0, f=0.3)  # three times the training stroke
    band_in, band_far = intervals.interval(y_in, inside.u, DT), intervals.interval(y_far, far.u, DT)
    assert not band_in.outside.any()
    assert band_far.outside.mean() > 0.3
    assert band_far.half_width[band_far.outside].mean() > 2 * band_in.half_width.mean()
    assert np.allclose(band_in.half_width, intervals.quantile())  # sigma = 1 inside the data


def test_the_distance_is_one_casadi_function_and_survives_a_round_trip(train):
    rows = np.vstack([input_rows(t.u, t.dt, t.y) for t in train])
    dist = DataDistance().fit(rows)
    probe = rows[::37] * 1.3
    symbolic = [dist.function()(r) for r in probe]  # (d, outside, spacings) of each row
    assert np.allclose([float(d) for d, _, _ in symbolic], dist.distance(probe), rtol=1e-9)
    assert np.allclose([float(s) for _, _, s in symbolic], dist.spacings(probe), rtol=1e-9)
    assert np.array_equal([bool(o) for _, o, _ in symbolic], dist.outside(probe)) and dist.outside(probe).any()
    rng = np.random.default_rng(4)
    intervals = ConformalIntervals(0.8, spread=2.0).fit(train, _held_out(rng, 5, train))
    again = ConformalIntervals.from_dict(intervals.to_dict())
    run, y_hat = _run(rng, 0.0, amplitude=5.0)
    a, b = intervals.interval(y_hat, run.u, DT), again.interval(y_hat, run.u, DT)
    assert np.allclose(a.lo, b.lo, rtol=1e-5, atol=1e-4) and np.array_equal(a.outside, b.outside)  # 6-7 digits kept


def test_conformal_model_wraps_a_physics_estimator():
    """Runs of a lag+backlash+linear truth with noise: the wrapped estimator's 90 % band covers
    85-97 % of unseen runs' samples, and the runs' first samples set the state."""
    truth = Series.from_spec("lag+backlash+linear", dt=DT)
    rng = np.random.default_rng(0)

    def run(i):
        t = np.arange(500) * DT
        f, base = 0.1 + 0.05 * i, rng.uniform(0, 2)
        u = base + 2 * (1 - np.cos(2 * np.pi * f * t)) / 2 * np.exp(-0.05 * t)
        return Trajectory(t, u, truth.simulate(u) + 0.05 * rng.normal(size=t.size), source=f"r{i}")

    runs = [run(i) for i in range(8)]
    model = ConformalModel(PhysicsEstimator("lag+backlash+linear", max_iter=100), warmup=10).fit(runs[:5])
    assert len(model.intervals_.runs_) == 5 and model.model_.params_
    ys, bands = [], []
    for r in runs[5:]:
        window, rest = warmup_split(r, 10)
        band = model.predict(rest, warmup=window, interval=0.9)
        assert np.allclose(band.y, model.predict(rest, warmup=window))
        ys.append(rest.y)
        bands.append(band)
    cov = coverage(np.concatenate(ys), np.concatenate([b.lo for b in bands]), np.concatenate([b.hi for b in bands]))
    assert 0.85 <= cov <= 0.99, cov


@pytest.mark.parametrize("level", [0, 1, 1.5, -0.1, True, "0.9", float("nan")])
def test_a_level_outside_0_1_is_refused(train, level):
    rng = np.random.default_rng(5)
    intervals = ConformalIntervals().fit(train, _held_out(rng, 3, train))
    run, y_hat = _run(rng, 0.0)
    with pytest.raises(DataError, match="between 0 and 1"):
        intervals.interval(y_hat, run.u, DT, level)
    with pytest.raises(DataError, match="between 0 and 1"):
        ConformalIntervals(level).fit(train, _held_out(rng, 3, train))


def test_too_few_held_out_runs_or_samples_say_how_many_are_needed(train):
    rng = np.random.default_rng(6)
    with pytest.raises(DataError, match="at least 2 runs held out"):
        ConformalIntervals().fit(train, _held_out(rng, 1, train))
    short = [HeldOut(r.segment(0, 30), y[:30], train) for r, y in
             (_run(rng, 0.0) for _ in range(2))]  # 2 runs x 3 segments of 10 samples
    with pytest.raises(DataError, match="needs at least 9 groups"):
        ConformalIntervals(0.9).fit(train, short).quantile()
    assert np.isfinite(ConformalIntervals(0.8).fit(train, short).quantile())  # 4 groups suffice at 80 %
    with pytest.raises(NotFittedError):
        ConformalIntervals().quantile()
    with pytest.raises(DataError, match="as long as the run"):
        ConformalIntervals().fit(train, [HeldOut(train[0], train[0].y[:-1], train)] * 2)


def test_the_half_width_as_a_casadi_function_equals_the_interval(train):
    rng = np.random.default_rng(7)
    intervals = ConformalIntervals(0.9).fit(train, _held_out(rng, 5, train))
    run, y_hat = _run(rng, 0.0, amplitude=6.0, f=0.3)
    band = intervals.interval(y_hat, run.u, DT, 0.8, whole_run=False)  # a step sees one sample at a time
    fn = intervals.function(0.8)
    u_prev = np.r_[run.u[0] - (run.u[1] - run.u[0]), run.u[:-1]]  # the first row's rate is the second's
    half, out = (np.asarray(v, dtype=float).ravel() for v in fn.map(run.n)(run.u[None, :], u_prev[None, :],
                                                                               y_hat[None, :]))
    np.testing.assert_allclose(half, band.half_width, rtol=1e-9)
    assert np.array_equal(out.astype(bool), band.outside) and band.outside.any() and not band.outside.all()
    whole = intervals.interval(y_hat, run.u, DT, 0.8)  # twice the trained amplitude: the run as a whole is outside
    assert "amplitude" in intervals.run_outside(run.u, DT) and whole.outside.all()
    assert np.all(whole.half_width >= band.half_width) and intervals.run_factor(run.u, DT) > 1


def test_a_run_that_starts_unlike_the_training_runs_is_flagged_outside_throughout():
    """The warm-up window's measured rows: a start the training runs never show (the output 40 above
    theirs at the same input) flags every sample, although the predicted path lies inside the data."""
    t = np.arange(0, 20, DT)
    inputs = [(1.5 + 0.1 * i) * (1 - np.cos(2 * np.pi * (0.3 + 0.02 * i) * t)) for i in range(3)]
    runs = [Trajectory(t, u, 10 * u, source=f"r{i}") for i, u in enumerate(inputs)]
    held = [HeldOut(r, r.y + 0.05, runs) for r in runs]
    intervals = ConformalIntervals(0.9).fit(runs, held)
    window, rest = warmup_split(runs[0], 10)
    assert not intervals.start_outside(window) and not intervals.start_outside(None)
    plain = intervals.interval(rest.y, rest.u, DT).outside
    assert plain.mean() < 0.05  # the path itself lies in the data
    np.testing.assert_array_equal(intervals.interval(rest.y, rest.u, DT, window=window).outside, plain)
    odd = Trajectory(window.time, window.u, window.y + 40.0)
    assert intervals.start_outside(odd)
    assert intervals.interval(rest.y, rest.u, DT, window=odd).outside.all()


def test_a_run_between_two_trained_amplitudes_is_inside_the_data_and_one_beyond_them_is_not():
    # a tracked sine at 50 and 70 deg trained on; the next run at 60 deg lies between them. Measured by
    # the training rows' own spacing along each run, every one of its rows was "outside" (100 %);
    # measured by how far the training runs lie from each other, it is inside, and 90 deg is not
    t = np.arange(0, 16, 0.02)

    def run(amp, name):
        return Trajectory(t, amp * np.sin(t), -0.9 * amp * np.sin(t - 0.2), source=name)

    train = [run(50, "a50"), run(70, "a70")]
    rows = np.vstack([input_rows(r.u, r.dt, r.y) for r in train])
    dist = DataDistance().fit(rows, np.repeat([0, 1], t.size))
    middle, beyond = run(60, "a60"), run(90, "a90")
    assert dist.outside(input_rows(middle.u, middle.dt, middle.y)).mean() <= 0.1
    assert dist.outside(input_rows(beyond.u, beyond.dt, beyond.y)).mean() > 0.5
    assert DataDistance().fit(rows).outside(input_rows(middle.u, middle.dt, middle.y)).mean() > 0.9  # no runs given
    fn = dist.function()  # the export flags the same rows
    flags = [bool(float(fn(r)[1])) for r in input_rows(middle.u, middle.dt, middle.y)[::25]]
    assert flags == list(dist.outside(input_rows(middle.u, middle.dt, middle.y)[::25]))
    again = DataDistance.from_dict(dist.to_dict())
    assert again.spacing_ == pytest.approx(dist.spacing_)
    assert again.spacings(rows[:5]) == pytest.approx(dist.spacings(rows[:5]), rel=1e-4, abs=1e-4)  # rows kept to 7 digits


def test_a_run_outside_the_training_rates_gets_the_band_the_held_out_run_outside_needed():
    """A loop that widens at slow rates (a piezo's): a held-out run ten times slower than the runs its
    model saw misses by the loop's width; a new run slower still is calibrated on that run's errors
    (its own group), not on those of the runs inside. The inside runs' band stays as it was."""
    rng = np.random.default_rng(11)

    def loop_run(f, width, source, n=2000):
        run, y_hat = _run(rng, 0.0, n=n, f=f, source=source)
        wider = width * np.sign(np.gradient(run.u))  # the loop's half-width, along the branch
        return Trajectory(run.time, run.u, run.y + wider, source=source), y_hat

    fast = [loop_run(f, 0.0, f"fast{i}")[0] for i, f in enumerate((0.3, 0.4, 0.5))]
    slow, slow_hat = loop_run(0.05, 5.0, "slow")
    train = [*fast, slow]
    held = [HeldOut(*_run(rng, rng.normal(0, 1.0), n=2000, f=0.4, source=f"held{i}"), train) for i in range(4)]
    held.append(HeldOut(slow, slow_hat, fast))  # predicted by a fit on the fast runs alone
    intervals = ConformalIntervals(0.9).fit(train, held)
    assert intervals.reaches_[-1] > 0 and intervals.reaches_[:-1] == [0.0] * 4
    floor = np.quantile(np.abs(slow.y - slow_hat), 0.9)
    covered, alone = [], []
    for i in range(10):  # new runs slower still, each with its own noise
        new, new_hat = loop_run(0.02, 5.0, f"slower{i}")
        assert "rate" in intervals.run_outside(new.u, DT)
        assert intervals.run_floor(new.u, DT) == pytest.approx(floor, rel=0.01)
        band = intervals.interval(new_hat, new.u, DT)
        assert np.all(band.half_width >= intervals.run_floor(new.u, DT) * (1 - 1e-9))
        covered.append(coverage(new.y, band.lo, band.hi))
        plain = intervals.interval(new_hat, new.u, DT, whole_run=False)  # each sample judged alone: no floor
        alone.append(coverage(new.y, plain.lo, plain.hi))
    # one held-out run outside is one calibration group: near the level (0.83 here), not a guarantee
    assert np.mean(covered) >= 0.8 and np.mean(alone) < 0.5, (np.mean(covered), np.mean(alone))
    inside, inside_hat = _run(rng, 0.0, n=2000, f=0.4)
    assert intervals.run_floor(inside.u, DT) == 0.0 and intervals.run_outside(inside.u, DT) is None
    np.testing.assert_array_equal(intervals.interval(inside_hat, inside.u, DT).half_width,
                                  intervals.interval(inside_hat, inside.u, DT, whole_run=False).half_width)
    again = ConformalIntervals.from_dict(intervals.to_dict())  # saved with the model folder
    assert again.run_floor(new.u, DT) == pytest.approx(intervals.run_floor(new.u, DT), rel=1e-5)
