"""The MPC in any units: its bounds default to the range a model was fitted on, and a model in
metres and radians is controlled as the same model in mm and deg."""

import numpy as np
import pytest

from hybrid.control import Feedback, TrackingMPC, reference_signal, rest_output, run_closed_loop
from hybrid.export import ExportError, export_model
from identification import identify
from physics import Series
from physics.data import Trajectory

SPEC = "lag+backlash+boucwen+linear"


def in_units(su: float, sy: float) -> Series:
    """The default catheter-like model for an input in units ``su`` times mm's and an output in
    ``sy`` times deg's (the same model: ``y(su u) = sy y(u)``)."""
    base = Series.from_spec(SPEC)
    unit, _ = base.signal_scales(1.0, 1.0)
    factors, _ = base.signal_scales(su, sy)
    out = base.for_scales(su, sy)
    out.params = base.params * factors / unit
    return out


@pytest.mark.parametrize("solver", ["sqp", "ipopt"])
def test_a_model_in_other_units_is_controlled_as_the_same_model(solver):
    u = 3 - 3 * np.cos(2 * np.pi * 0.2 * np.arange(0, 10, 0.04))
    runs = {}
    for su, sy in ((1.0, 1.0), (1e-6, 1e-4), (1e3, 1e3)):
        model = in_units(su, sy)
        np.testing.assert_allclose(model.simulate(su * u) / sy, Series.from_spec(SPEC).simulate(u), atol=1e-9)
        ex = export_model(model)
        mpc = TrackingMPC(ex, horizon=12, u_bounds=(0.0, 6.0 * su), solver=solver)
        assert mpc.du_max == pytest.approx(0.5 * su)  # a twelfth of the bounds by default
        first = mpc.solve(ex.x0(2.0 * su), np.full(12, 60.0 * sy), u_prev=2.0 * su) / su
        ref = reference_signal("sine", rest_output(ex, 0.5 * su), rest_output(ex, 5.5 * su), duration_s=3.0)
        loop = run_closed_loop(mpc, ex, ref, noise_std_deg=0.0, feedback=Feedback(correction="none"))
        runs[(su, sy)] = first, loop.rmse_deg / sy, loop.u / su
    (first, rmse, path), *others = runs.values()
    assert rmse < 0.1  # deg, on a reachable sine
    for first_o, rmse_o, path_o in others:
        assert first_o == pytest.approx(first, abs=1e-6)
        # the same path until rounding tells: where the sine meets the input bound a few SQP solves
        # stop unconverged, and from there the loops part (by up to 2x in RMSE, both on target)
        np.testing.assert_allclose(path_o[:20], path[:20], atol=1e-4)
        assert rmse_o < 0.1


def test_the_bounds_default_to_the_input_range_the_model_was_fitted_on():
    t = np.arange(0, 20, 1e-3)
    u = 2e-6 + 1.5e-6 * np.sin(2 * np.pi * 0.5 * t) * np.exp(-0.05 * t)  # metres, at 1 kHz
    truth = Series.from_spec("lag+linear", dt=1e-3).set_params(**{"lag.time_constant_s": 0.02, "linear.gain": 40.0,
                                                                  "linear.offset": 1e-5})
    fit = identify(Series.from_spec("lag+linear", dt=1e-3), Trajectory(t, u, truth.simulate(u)))
    fitted = fit.model()
    assert fitted.input_range == pytest.approx((u.min(), u.max()))
    assert Series.from_dict(fitted.to_dict()).input_range == fitted.input_range
    ex = export_model(fitted)
    assert ex.input_range == pytest.approx((u.min(), u.max()))
    mpc = TrackingMPC(ex, horizon=10)
    assert mpc.u_bounds == pytest.approx((u.min(), u.max()))
    assert mpc.du_max == pytest.approx((u.max() - u.min()) / 12)
    target = rest_output(ex, 3e-6)
    x, u_prev = ex.x0(2e-6), 2e-6
    for _ in range(40):  # the command settles where the rest output is the target
        u_prev = mpc.solve(x, np.full(10, target), u_prev=u_prev)
        x = np.asarray(ex.step(x, u_prev)[0], dtype=float).ravel()
    assert u_prev == pytest.approx(3e-6, rel=1e-3)


def test_a_model_that_does_not_know_its_range_needs_bounds():
    with pytest.raises(ExportError, match="u_bounds=\\(low, high\\)"):
        TrackingMPC(export_model(Series.from_spec("lag+linear")), horizon=5)
    with pytest.raises(ExportError, match="low < high"):
        TrackingMPC(export_model(Series.from_spec("lag+linear")), horizon=5, u_bounds=(1.0, np.nan))
