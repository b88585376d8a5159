"""The creep block: recovered from data, inverted, the same in torch, exported, and its relaxed start
honoured by simulation, export, the hybrids' prediction and MPC."""

import numpy as np
import pytest

from hybrid.export import export_model
from identification import EFFECTS, identify
from physics import Creep, LinearMap, Series, resolve_effect
from physics.data import Trajectory

from _synthetic import assert_torch_paths_equal_casadi

DT = 0.1
TRUTH = {"creep.gain_1": 0.15, "creep.gain_2": 0.35, "linear.gain": 10.0, "linear.offset": 30.0}


def _truth(start="relaxed"):
    return Series(Creep(gains=[0.15, 0.35], time_constants_s=(3.0, 40.0), start=start), LinearMap(), dt=DT
                  ).set_params(**{"linear.gain": 10.0, "linear.offset": 30.0})


def _u(f, n=900, mean=2.5):
    t = np.arange(n) * DT
    return mean - mean * np.cos(2 * np.pi * f * t) * np.exp(-t / t[-1])


def _runs(truth, noise=0.05, seed=0):
    rng = np.random.default_rng(seed)
    out = []
    for i, f in enumerate((0.1, 0.2, 0.4)):
        u = _u(f)
        out.append(Trajectory(np.arange(u.size) * DT, u, truth.simulate(u) + rng.normal(0, noise, u.size),
                              source=f"run{i}"))
    return out


def test_creep_is_a_named_effect():
    assert "creep" in EFFECTS and resolve_effect("creep") == "creep" and resolve_effect("relaxation") == "creep"
    assert Series.from_spec("lag+creep+linear").param_names[1:3] == ["creep.gain_1", "creep.gain_2"]


def test_creep_output_sits_higher_after_large_cycles():
    # the catheter's signature: the output at zero input rises after cycling and stays
    model = _truth()
    u = np.concatenate([np.zeros(20), _u(0.2, 400), np.zeros(50)])
    y = model.simulate(u)
    assert y[0] == pytest.approx(30.0, abs=1e-12)  # relaxed start at zero input: the rest output
    assert y[-1] - y[0] > 5.0  # deg above the start at the same (zero) input
    # the steady start puts the modes at the first input: the same run from u=2 differs only at the start
    u2 = u + 2.0
    gap = _truth("steady").simulate(u2) - _truth("relaxed").simulate(u2)
    a1, a2 = np.exp(-DT / 3.0), np.exp(-DT / 40.0)  # one sample of relaxation towards u0 = 2
    assert gap[0] == pytest.approx(10.0 * 2.0 * (0.15 * a1 + 0.35 * a2), rel=1e-9) and abs(gap[-1]) < abs(gap[0])


def test_creep_parameters_are_recovered():
    truth = _truth()
    fit = identify(Series(Creep(time_constants_s=(3.0, 40.0)), LinearMap(), dt=DT), _runs(truth))
    assert fit.success, fit.status
    for name, value in TRUTH.items():
        assert fit.parameters[name] == pytest.approx(value, rel=0.05, abs=0.01), name
    assert fit.train_rmse == pytest.approx(0.05, rel=0.1)  # the noise floor


def test_inverse_of_forward_is_the_identity_on_a_held_out_path():
    model = Series.from_spec("lag+creep+linear", dt=DT).set_params(
        **{"creep.gain_1": 0.2, "creep.gain_3": 0.4, "linear.gain": 10.0})
    u = 2 + 2 * np.sin(2 * np.pi * 0.13 * np.arange(700) * DT) + 0.3 * np.sin(np.arange(700) * 0.9)
    np.testing.assert_allclose(model.inverse(model.simulate(u)), u, atol=1e-9)


def test_torch_paths_equal_casadi():
    pytest.importorskip("torch")
    model = Series.from_spec("lag+creep+linear", dt=DT).set_params(**{"creep.gain_2": 0.3, "creep.gain_3": -0.2})
    rng = np.random.default_rng(0)
    assert_torch_paths_equal_casadi(model, rng.uniform(0, 3, (5, model.n_x)), rng.uniform(0, 6, (5, 1)),
                                    _u(0.2, 60), rtol=0, atol=1e-12)


def test_export_and_its_x0_honour_the_relaxed_start():
    model, u = _truth(), _u(0.3, 300) + 1.0
    exported = export_model(model)
    np.testing.assert_allclose(exported.x0(u[0]), [0.0, 0.0, u[0]], atol=1e-12)  # modes relaxed, not at u0
    np.testing.assert_allclose(exported.simulate(u), model.simulate(u), rtol=0, atol=1e-9)
    back = Series.from_dict(model.to_dict())
    assert back.blocks[0].start == "relaxed" and back.blocks[0].time_constants_s == (3.0, 40.0)
    np.testing.assert_array_equal(back.simulate(u), model.simulate(u))


def test_mpc_tracks_on_the_creep_model():
    from hybrid.control import TrackingMPC, reference_signal, rest_output, run_closed_loop

    model = export_model(_truth())
    ref = reference_signal("sine", rest_output(model, 0.5), rest_output(model, 4.5), duration_s=6.0)
    result = run_closed_loop(TrackingMPC(model, u_bounds=(0.0, 6.0), horizon=10, solver="sqp"), model, ref, noise_std_deg=0.0)
    assert result.rmse_deg < 0.5  # deg, over 40 deg of travel


def test_hybrid_prediction_starts_relaxed():
    pytest.importorskip("torch")
    from hybrid import HybridModel, TrainingSettings

    truth = _truth()
    runs = _runs(truth, noise=0.05)
    hybrid = HybridModel(truth, "fnn", training=TrainingSettings(epochs=1, progress=False, seed=0)).fit(runs)
    u = _u(0.25, 200) + 1.0
    test = Trajectory(np.arange(u.size) * DT, u, truth.simulate(u))
    np.testing.assert_allclose(hybrid.physics_.simulate(u), truth.simulate(u), atol=1e-12)
    # the prediction is the relaxed physics plus a residual that is small after one epoch on a perfect physics
    assert np.sqrt(np.mean((hybrid.predict(test) - test.y) ** 2)) < 1.0


def test_bad_settings_are_clear_errors():
    with pytest.raises(ValueError, match="start must be one of"):
        Creep(start="cold")
    with pytest.raises(ValueError, match="time_constants_s"):
        Creep(time_constants_s=(0.0,))
