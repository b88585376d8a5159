"""The generalized Prandtl-Ishlinskii block: loops, recovery from data, inverse, torch path, export."""

import casadi as ca
import numpy as np
import pytest

from hybrid.export import export_model
from identification import identify
from physics import GPI, Backlash, LinearMap, Series, resolve_effect, torch_expression
from physics.data import Trajectory

DT = 0.04
WIDTHS = (0.2, 0.6, 1.5)
TRUTH = {"gpi.w_1": 0.1, "gpi.w_2": 0.25, "gpi.w_3": 0.3, "gpi.center": 3.0, "gpi.saturation": 0.25,
         "linear.gain": 10.0, "linear.offset": 30.0}


def _truth():
    return Series(GPI(widths=WIDTHS, smoothing=0.01), LinearMap(), dt=DT).set_params(**TRUTH)


def _u(f, n=1200, mean=3.0):
    t = np.arange(n) * DT
    return mean - 2.8 * np.cos(2 * np.pi * f * t) * (1 - 0.7 * t / t[-1])


def test_gpi_is_a_hysteresis_block():
    assert resolve_effect("gpi") == "hysteresis" and resolve_effect("prandtl-ishlinskii") == "hysteresis"


def test_one_play_without_envelope_is_a_weighted_backlash():
    u = _u(0.3, 400)
    gpi = Series(GPI(weights=[0.4], widths=(0.8,), smoothing=0.0), dt=DT)
    play = Series(Backlash(width=0.8, smoothing=0.0), dt=DT)
    np.testing.assert_allclose(gpi.simulate(u), 0.6 * u + 0.4 * play.simulate(u), atol=1e-12)


def test_envelope_narrows_the_loop_at_the_ends():
    # a saturating envelope: the same swing of the input moves the output less far from the centre
    u = _u(0.3, 800)
    y = _truth().simulate(u)
    flat = Series(GPI(widths=WIDTHS, smoothing=0.01), LinearMap(), dt=DT).set_params(
        **{**TRUTH, "gpi.saturation": 0.0}).simulate(u)
    assert np.ptp(y) < 0.9 * np.ptp(flat)


def test_gpi_parameters_are_recovered():
    rng = np.random.default_rng(0)
    truth = _truth()
    runs = [Trajectory(np.arange(1200) * DT, u, truth.simulate(u) + rng.normal(0, 0.05, u.size))
            for u in (_u(0.1), _u(0.25), _u(0.4, mean=2.6))]
    fit = identify(Series(GPI(widths=WIDTHS, smoothing=0.01), LinearMap(), dt=DT), runs)
    assert fit.success, fit.status
    for name, value in TRUTH.items():
        assert fit.parameters[name] == pytest.approx(value, rel=0.05, abs=0.01), name
    assert fit.train_rmse == pytest.approx(0.05, rel=0.1)


def test_inverse_of_forward_follows_the_wanted_path():
    model = _truth()
    u = _u(0.2, 600) + 0.2 * np.sin(np.arange(600) * 0.7)
    y = model.simulate(u)
    np.testing.assert_allclose(model.simulate(model.inverse(y)), y, atol=1e-8)
    np.testing.assert_allclose(model.inverse(y), u, atol=1e-6)


def test_torch_expression_equals_casadi():
    torch = pytest.importorskip("torch")
    model = Series.from_spec("lag+gpi+linear").set_params(**{"gpi.saturation": 0.3, "gpi.center": 2.0})
    step, tstep = model.step_function(), torch_expression(model.step_function())
    rng = np.random.default_rng(1)
    x, u = rng.uniform(0, 5, (6, model.n_x)), rng.uniform(0, 6, (6, 1))
    pt = torch.tensor(model.params, requires_grad=True)
    xn, y = tstep(torch.tensor(x), torch.tensor(u), pt)
    for i in range(6):
        xr, yr = step(x[i], u[i], model.params)
        np.testing.assert_allclose(xn[i].detach().numpy(), np.asarray(xr).ravel(), atol=1e-12)
        np.testing.assert_allclose(y[i].detach().numpy(), np.asarray(yr).ravel(), atol=1e-12)
    y[0].sum().backward()
    xs, us, ps = ca.SX.sym("x", model.n_x), ca.SX.sym("u"), ca.SX.sym("p", model.n_p)
    jac = ca.Function("j", [xs, us, ps], [ca.jacobian(model.step_expr(xs, us, ps)[1], ps)])
    np.testing.assert_allclose(pt.grad.numpy(), np.asarray(jac(x[0], u[0], model.params)).ravel(), atol=1e-10)


def test_export_and_save_round_trip():
    model, u = _truth(), _u(0.3, 300)
    exported = export_model(model)
    np.testing.assert_allclose(exported.x0(u[0]), model.steady_state(u[0]), atol=1e-12)
    np.testing.assert_allclose(exported.simulate(u), model.simulate(u), rtol=0, atol=1e-9)
    back = Series.from_dict(model.to_dict())
    assert back.blocks[0].widths == WIDTHS
    np.testing.assert_array_equal(back.simulate(u), model.simulate(u))


def test_widths_follow_the_data_scale_and_bad_settings_are_clear():
    assert GPI().for_scale(10.0).widths == pytest.approx((1.0, 2.5, 5.0, 10.0, 20.0))
    with pytest.raises(ValueError, match="widths"):
        GPI(widths=(0.5, -1.0))
