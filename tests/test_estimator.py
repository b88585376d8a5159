"""Moving-horizon estimation: the state and a slow output offset from sparse measurements."""

import casadi as ca
import numpy as np
import pytest

from hybrid.control import MovingHorizonEstimator, estimated_states, measurement_mask, run_closed_loop
from hybrid.control import TrackingMPC, reference_signal, rest_output
from hybrid.export import ExportError, export_model
from physics import Series


@pytest.fixture(scope="module")
def model():
    return export_model(Series.from_spec("lag+backlash+linear").set_params(**{"backlash.width": 0.5}))


def _run(n=300, seed=0):
    t = np.arange(n) * 0.04
    return 3.0 + 2.5 * np.sin(2 * np.pi * 0.3 * t) * np.exp(-0.1 * t)


def test_states_fitted_are_the_physics_ones(model):
    assert [model.state_names[i] for i in estimated_states(model)] == ["lag.position", "backlash.position"]


def test_mask_every_nth_and_irregular():
    assert measurement_mask(7, 3).tolist() == [True, False, False, True, False, False, True]
    assert measurement_mask(5, at=[1, 4]).tolist() == [False, True, False, False, True]
    with pytest.raises(ExportError, match="whole number"):
        measurement_mask(5, 0)
    with pytest.raises(ExportError, match=r"\[0, 4\]"):
        measurement_mask(5, at=[5])


def test_an_offset_and_a_wrong_start_are_removed_from_sparse_measurements(model):
    """The plant is the model started on the other side of its backlash, reading 4 units high: with a
    measurement every 10th sample the prediction error (before each measurement) falls to the noise."""
    u = _run()
    x_true = model.x0(u[0])
    x_true[model.state_names.index("backlash.position")] += 0.4
    rng = np.random.default_rng(0)
    y = model.simulate(u, x0=x_true) + 4.0 + 0.05 * rng.standard_normal(u.size)
    mhe = MovingHorizonEstimator(model, window=40, u_bounds=(0.0, 6.0), compile=False)
    open_loop = model.simulate(u) - y
    y_hat = mhe.filter(u, y, measure_every=10)
    late = slice(100, None)
    assert np.sqrt(np.mean(open_loop[late] ** 2)) > 3.5
    assert np.sqrt(np.mean((y_hat - y)[late] ** 2)) < 0.15  # noise 0.05
    assert mhe.offset_ == pytest.approx(4.0, abs=0.1)


def test_irregular_and_dropped_measurements_give_the_same_kind_of_estimate(model):
    u = _run(200)
    y = model.simulate(u) - 2.0
    at = np.sort(np.random.default_rng(1).choice(200, 20, replace=False))
    mhe = MovingHorizonEstimator(model, window=30, u_bounds=(0.0, 6.0), compile=False)
    by_index = mhe.filter(u, y, at=at)
    y_nan = np.full_like(y, np.nan)
    y_nan[at] = y[at]
    by_nan = mhe.filter(u, y_nan)  # unmeasured samples as NaN: the same estimate
    np.testing.assert_allclose(by_index, by_nan)
    assert np.abs(by_index - y)[at[3]:].max() < 0.05


def test_the_update_is_one_pure_function_that_round_trips(model, tmp_path):
    mhe = MovingHorizonEstimator(model, window=20, u_bounds=(0.0, 6.0), compile=False)
    loaded = ca.Function.load(str(mhe.save(tmp_path / "mhe.casadi")))
    args = (model.x0(3.0), 0.5, np.full((1, 20), 3.0), np.full((1, 20), 40.0), (np.arange(20) % 5 == 0)[None] * 1.0)
    for a, b in zip(mhe.function(*args), loaded(*args)):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    assert loaded.name_in() == ["x_start", "d", "U", "Y", "mask"]


def test_compiled_update_equals_the_function(model):
    from hybrid.export._codegen import has_compiler

    if not has_compiler():
        pytest.skip("gcc is not on the PATH: the compiled update is not built")
    u = _run(120)
    y = model.simulate(u) + 1.5
    plain = MovingHorizonEstimator(model, window=20, u_bounds=(0.0, 6.0), compile=False).filter(u, y, measure_every=7)
    fast = MovingHorizonEstimator(model, window=20, u_bounds=(0.0, 6.0), compile=True).filter(u, y, measure_every=7)
    np.testing.assert_allclose(fast, plain, atol=1e-9)


def test_closed_loop_with_a_measurement_every_second_tracks_through_an_offset(model):
    """The plant reads 6 units above the model: measured once a second (every 25th sample), the MPC
    on the estimator's state and offset tracks as well as with a measurement at every sample."""
    plant = Series.from_spec("lag+backlash+linear").set_params(**{"backlash.width": 0.5, "linear.offset": 36.0})
    ref = reference_signal("sine", rest_output(model, 1.5), rest_output(model, 4.5), duration_s=8.0)
    runs = {}
    for name, kw in {"none": dict(correction="none"), "every": {}, "sparse": dict(measure_every=25)}.items():
        mpc = TrackingMPC(model, u_bounds=(0.0, 6.0), horizon=10)
        runs[name] = run_closed_loop(mpc, plant, ref, noise_std_deg=0.1, seed=0, **kw)
    late = slice(75, None)  # after the first three measurements
    err = {k: float(np.sqrt(np.mean((r.y_true - ref)[late] ** 2))) for k, r in runs.items()}
    assert err["none"] > 4.0, err
    assert err["sparse"] < 0.5, err
    assert err["sparse"] < 1.5 * max(err["every"], 0.1), err


def test_bad_settings_are_reported(model):
    with pytest.raises(ExportError, match="window"):
        MovingHorizonEstimator(model, window=0, u_bounds=(0.0, 6.0))
    with pytest.raises(ExportError, match="offset_std"):
        MovingHorizonEstimator(model, offset_std=-1, u_bounds=(0.0, 6.0))
    with pytest.raises(ExportError, match="input range"):
        MovingHorizonEstimator(model)
    with pytest.raises(ExportError, match="ExportedModel"):
        MovingHorizonEstimator(Series.from_spec("linear"))
    mhe = MovingHorizonEstimator(model, window=5, u_bounds=(0.0, 6.0), compile=False)
    with pytest.raises(ExportError, match="samples but y has"):
        mhe.filter(np.ones(10), np.ones(9))
    with pytest.raises(ExportError, match="not finite"):
        mhe.filter(np.ones(10), np.r_[np.nan, np.ones(9)], measure_every=2)
