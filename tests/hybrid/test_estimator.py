"""Moving-horizon estimation: the state and a slow output offset from sparse measurements."""

import casadi as ca
import numpy as np
import pytest

from hybrid.control import MovingHorizonEstimator, estimated_states, measurement_mask, run_closed_loop
from hybrid.control import Feedback, TrackingMPC, reference_signal, rest_output
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
    for name, feedback in {"none": Feedback(correction="none"), "every": Feedback(),
                           "sparse": Feedback(measure_every=25)}.items():
        mpc = TrackingMPC(model, u_bounds=(0.0, 6.0), horizon=10)
        runs[name] = run_closed_loop(mpc, plant, ref, noise_std_deg=0.1, seed=0, feedback=feedback)
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


@pytest.fixture(scope="module")
def pose():
    """A tendon's chain read by the virtual catheter's constant-curvature arc: the tip's angle and position."""
    from hybrid.virtual import TipArc

    chain = Series.from_spec("lag+backlash+linear").set_params(
        **{"backlash.width": 0.5, "linear.gain": 10.0, "linear.offset": 20.0})
    return Series(*chain.blocks, TipArc().block(), dt=chain.dt, input_range=(0.0, 6.0))


def test_one_state_of_several_outputs_is_fitted_on_the_outputs_measured(pose):
    """Only the position is measured (the angle column NaN: a camera), and the play starts 0.4 mm from
    where the model would put it, the input held: the one state the outputs share is fitted on the
    position, so the angle, never measured, is predicted as closely as the position is. While the input is
    held, a state error and a constant offset of the position look alike: the offsets are told to be
    steady (offset_std), and the next test has them move."""
    model = export_model(pose)
    u = np.r_[np.full(100, 3.0), 3.0 + np.sin(2 * np.pi * 0.3 * np.arange(100) * 0.04)]
    x_true = model.x0(u[0])
    x_true[model.state_names.index("backlash.position")] += 0.4
    truth = np.asarray(pose.simulate(u, x0=x_true))
    seen = truth + 0.05 * np.random.default_rng(0).standard_normal(truth.shape)
    seen[:, 0] = np.nan
    mhe = MovingHorizonEstimator(model, window=40, offset_std=0.01, u_bounds=(0.0, 6.0), compile=False)
    assert mhe.y_spans.shape == (3,) and mhe.noise_std.shape == (3,)
    y_hat = mhe.filter(u, seen, measure_every=10)
    held = slice(20, 100)  # the play's error stays until the sine takes it up
    free = np.sqrt(np.mean((np.asarray(pose.simulate(u)) - truth)[held] ** 2, axis=0))
    err = np.sqrt(np.mean((y_hat - truth)[held] ** 2, axis=0))
    assert free[0] > 2.0 and np.all(free[1:] > 0.5), free  # 0.4 mm of play: 4 deg
    assert err[0] < 0.05 * free[0] and np.all(err[1:] < 0.05), err  # the angle, never measured; noise 0.05 mm


def test_each_output_has_its_own_offset_and_any_subset_is_measured(pose):
    """The position reads 3 and -2 mm off, the angle is never measured: each offset is recovered on its own
    (the angle's stays 0), and the angle is predicted as the position is. A sample may measure any subset."""
    model = export_model(pose)
    t = np.arange(300) * 0.04
    u = 3.0 + 2.5 * np.sin(2 * np.pi * 0.3 * t) * np.exp(-0.1 * t)
    truth = np.asarray(pose.simulate(u)) + [0.0, 3.0, -2.0]
    seen = truth + 0.05 * np.random.default_rng(1).standard_normal(truth.shape)
    seen[:, 0] = np.nan
    mhe = MovingHorizonEstimator(model, window=40, u_bounds=(0.0, 6.0), compile=False)
    y_hat = mhe.filter(u, seen, measure_every=10)
    late = slice(100, None)
    assert np.all(np.sqrt(np.mean((y_hat - truth)[late] ** 2, axis=0)) < [0.01, 0.05, 0.05])
    np.testing.assert_allclose(mhe.offset_, [0.0, 3.0, -2.0], atol=0.05)
    one = MovingHorizonEstimator(model, window=40, u_bounds=(0.0, 6.0), compile=False).reset(u0=u[0])
    assert one.update(u[0], [np.nan, truth[0, 1], truth[0, 2]]).shape == (3,)
    assert one.update(u[1], truth[1]).shape == (3,)
    with pytest.raises(ExportError, match="one value per output"):
        one.update(u[2], truth[2, :2])
    with pytest.raises(ExportError, match="one column per output"):
        mhe.filter(u, truth[:, :2])
    with pytest.raises(ExportError, match="one per output"):
        MovingHorizonEstimator(model, noise_std=[0.1, 0.1], u_bounds=(0.0, 6.0))
    with pytest.raises(ExportError, match="one per output"):
        one.reset(offset=[1.0, 2.0])


def test_hyst_predict_measure_every_corrects_a_model_that_reads_off(tmp_path, capsys):
    """A fit JSON 3 units below the plant: --measure-every 5 writes predictions made before each
    measurement, a 'measured' column, and an RMSE far under the free run's."""
    import json

    from hybrid.cli._main import main

    params = {"lag.time_constant_s": 0.2, "linear.gain": 11.0, "linear.offset": 30.0}
    fit = tmp_path / "fit.json"
    fit.write_text(json.dumps({"model": "lag+linear", "dt": 0.04, "parameters": params}))
    u = _run(150)
    y = export_model(Series.from_spec("lag+linear").set_params(**{**params, "linear.offset": 33.0})).simulate(u)
    data = tmp_path / "run.csv"
    np.savetxt(data, np.column_stack([np.arange(u.size) * 0.04, u, y]), delimiter=",", header="time,u,y",
               comments="")
    free, fed = tmp_path / "free.csv", tmp_path / "fed.csv"
    assert main(["predict", str(fit), str(data), "--out", str(free)]) == 0
    assert main(["predict", str(fit), str(data), "--measure-every", "5", "--warmup", "2", "--out", str(fed)]) == 0
    assert "one every 5 samples" in capsys.readouterr().out
    a = np.genfromtxt(free, delimiter=",", names=True)
    b = np.genfromtxt(fed, delimiter=",", names=True)
    assert b.size == u.size - 2 and b["measured"].tolist() == [k % 5 == 0 for k in range(b.size)]
    rmse = lambda t: float(np.sqrt(np.mean((t["y_pred"] - t["y"]) ** 2)))  # noqa: E731
    assert rmse(a) == pytest.approx(3.0, abs=0.01)
    assert rmse(b) < 0.1 * rmse(a)


def test_hyst_export_writes_the_estimator_beside_the_step_and_into_the_c_library(tmp_path, capsys):
    import json

    from hybrid.cli._main import main
    from hybrid.export import ExportedModel
    from hybrid.export._codegen import has_compiler, load_compiled

    series = Series.from_spec("lag+backlash+linear", dt=0.04)
    series.input_range = (0.0, 6.0)
    fit = tmp_path / "fit.json"
    fit.write_text(json.dumps({"model": series.spec, "series": series.to_dict(), "parameters": series.param_dict()}))
    out = tmp_path / "step.casadi"
    assert main(["export", "lag+linear", "--estimator", "20", "--out", str(out)]) == 2  # no input range: refused
    assert "records no input range" in capsys.readouterr().err and not out.exists()
    args = ["export", str(fit), "--estimator", "20", "--out", str(out)]
    assert main(args + (["--c-code", str(tmp_path / "c")] if has_compiler() else [])) == 0
    mhe = ca.Function.load(str(tmp_path / "step.mhe.casadi"))
    own = MovingHorizonEstimator(ExportedModel.load(out), window=20, compile=False).function
    x = ExportedModel.load(out).x0(2.0)
    call = (x, 0.3, np.linspace(1, 4, 20)[None], np.linspace(40, 70, 20)[None], (np.arange(20) % 4 == 0)[None] * 1.0)
    for a, b in zip(mhe(*call), own(*call)):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=0, atol=1e-12)
    if has_compiler():
        native = load_compiled(tmp_path / "c" / "libstep.so", "mhe")
        for a, b in zip(native(*call), own(*call)):
            np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-10, atol=1e-9)
