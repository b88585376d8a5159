"""The resonance block (second-order dynamics): exact discretisation, recovered from data in any units,
inverted, the same in torch, exported, integrated as an ODE, and named by discovery and selection."""

import casadi as ca
import numpy as np
import pytest
import scipy.linalg

from hybrid.export import export_model
from identification import EFFECTS, SelectionSettings, SolverSettings, identify, select_physics
from physics import Resonance, Series, resolve_effect
from physics._resonance import transition
from physics.data import Trajectory

from _synthetic import assert_torch_paths_equal_casadi

DT = 1 / 500
TRUTH = {"resonance.natural_frequency_hz": 40.0, "resonance.damping_ratio": 0.15, "boucwen.A": 0.5,
         "boucwen.beta": 2.0, "boucwen.gamma": 1.0, "linear.gain": 2e-6, "linear.offset": 1e-7}


def _truth():
    """A piezo-like stack: volts -> metres (micrometre strokes), a 40 Hz first mode, hysteresis."""
    return Series.from_spec("resonance+boucwen+linear", dt=DT).set_params(**TRUTH)


def _u(f, n=3000):
    t = np.arange(n) * DT
    return 1.0 + np.exp(-t) * np.sin(2 * np.pi * f * t) + 0.3 * np.sin(2 * np.pi * 0.37 * f * t)


def _runs(truth, freqs=(3, 11, 27), noise=1e-8, seed=0, n=3000):
    rng = np.random.default_rng(seed)
    return [Trajectory(np.arange(n) * DT, _u(f, n), truth.simulate(_u(f, n)) + rng.normal(0, noise, n),
                       source=f"f{f}") for f in freqs]


def _expm_transition(fn, zeta, dt):
    """Phi, G0, G1 from the matrix exponential of the system augmented with the input and its slope."""
    w = 2 * np.pi * fn
    m = np.zeros((4, 4))
    m[:2, :2] = [[0, 1], [-w * w, -2 * zeta * w]]
    m[1, 2] = w * w
    m[2, 3] = 1 / dt
    e = scipy.linalg.expm(m * dt)
    return np.r_[e[:2, :2].ravel(), e[:2, 2], e[:2, 3]]


def test_resonance_is_a_named_effect():
    assert "resonance" in EFFECTS and resolve_effect("mass_spring_damper") == "resonance"
    assert Series.from_spec("resonance+linear").state_names[:2] == ["resonance.position", "resonance.velocity"]


@pytest.mark.parametrize("fn, zeta, dt", [
    (2.0, 0.1, 0.01), (2.0, 1.0, 0.01), (2.0, 1.0 + 1e-7, 0.01), (2.0, 3.0, 0.01), (30.0, 0.05, 1 / 750),
    (5.0, 10.0, 0.04), (300.0, 0.99999, 1 / 5000), (9.0, 0.3, 0.04),  # 9 Hz at 25 Hz: above a third of the rate
])
def test_transition_is_the_exact_matrix_exponential(fn, zeta, dt):
    # under-, over- and critically damped, and at the series' switch either side of critical
    phi, g0, g1 = transition(ca.DM([fn, zeta]), dt)
    ours = np.array([float(v) for v in (*phi[0], *phi[1], *g0, *g1)])
    np.testing.assert_allclose(ours, _expm_transition(fn, zeta, dt), rtol=1e-9, atol=1e-12)


def test_a_step_overshoots_and_rings_at_the_damped_frequency():
    fn, zeta, dt = 2.0, 0.1, 0.001
    y = Series(Resonance(natural_frequency_hz=fn, damping_ratio=zeta), dt=dt).simulate(np.r_[0.0, np.ones(10000)])
    assert y.max() - 1 == pytest.approx(np.exp(-np.pi * zeta / np.sqrt(1 - zeta**2)), rel=1e-3)
    peaks = np.flatnonzero((y[1:-1] > y[:-2]) & (y[1:-1] >= y[2:])) + 1
    assert 1 / (np.diff(peaks).mean() * dt) == pytest.approx(fn * np.sqrt(1 - zeta**2), rel=1e-2)
    assert y[-1] == pytest.approx(1.0, abs=1e-4)  # unit static gain


def test_parameters_are_recovered_in_volts_and_metres():
    fit = identify(Series.from_spec("resonance+boucwen+linear", dt=DT), _runs(_truth()))
    assert fit.success, fit.status
    for name, value in TRUTH.items():
        assert fit.parameters[name] == pytest.approx(value, rel=0.02), name
    assert fit.train_rmse == pytest.approx(1e-8, rel=0.05)  # the noise floor
    # a first-order lag cannot ring: on the same data it stays far above the noise
    lag = identify(Series.from_spec("lag+boucwen+linear", dt=DT), _runs(_truth()), solver=SolverSettings(max_iter=100), starts=1,
                   allow_failure=True)
    assert lag.train_rmse > 5 * fit.train_rmse


def test_inverse_is_quasi_static_and_the_model_inverse_is_exact():
    from hybrid import ModelInverse

    model = Series.from_spec("resonance+linear", dt=0.01).set_params(
        **{"resonance.natural_frequency_hz": 3.0, "resonance.damping_ratio": 0.4, "linear.gain": 10.0})
    t = np.arange(700) * 0.01
    slow = 2 + 2 * np.sin(2 * np.pi * 0.05 * t)
    # the step inverse treats the resonance at its static gain: off by the phase lag it leaves out,
    # about 2 zeta f / f_n of the motion (here 2.7e-2 mm of a 2 mm swing)
    err = np.max(np.abs(model.inverse(model.simulate(slow)) - slow))
    assert err < 2 * (2 * 0.4 * 0.05 / 3.0) * 2
    fast = 2 + 2 * np.sin(2 * np.pi * 0.3 * t) + 0.3 * np.sin(2 * np.pi * 1.1 * t)
    y = model.simulate(fast)
    assert np.sqrt(np.mean((model.inverse(y) - fast) ** 2)) > 0.02  # the dynamics it leaves out
    u = ModelInverse(model, window=40, commit=20, w_du=1e-9).fit().predict(y)
    # measured 1.9e-8 mm before the path's last window (whose last inputs barely reach the output)
    assert np.sqrt(np.mean((u - fast)[:-40] ** 2)) < 1e-6
    assert np.sqrt(np.mean((model.simulate(u) - y) ** 2)) < 1e-5  # deg: the output follows throughout


def test_torch_paths_equal_casadi():
    pytest.importorskip("torch")
    model = _truth()
    rng = np.random.default_rng(0)
    assert_torch_paths_equal_casadi(model, rng.uniform(0, 2, (5, model.n_x)), rng.uniform(0, 2, (5, 1)),
                                    _u(11, 200), atol=1e-20)


def test_export_and_round_trip():
    model, u = _truth(), _u(7, 400)
    exported = export_model(model)
    np.testing.assert_allclose(exported.x0(u[0])[:3], [u[0], 0.0, u[0]], atol=1e-12)
    np.testing.assert_allclose(exported.simulate(u), model.simulate(u), rtol=1e-10, atol=1e-18)
    back = Series.from_dict(model.to_dict())
    np.testing.assert_array_equal(back.simulate(u), model.simulate(u))


def test_continuous_form_integrates_to_the_discrete_step():
    # the neural-ODE path: the block's ODE, integrated finely with the input linear between
    # samples, lands on the exact discrete step
    block = Resonance(natural_frequency_hz=4.0, damping_ratio=0.2)
    p, dt, sub = ca.DM(block.param_values()), 0.02, 200
    x, u_prev, u = ca.DM([0.3, -1.0]), 0.5, 1.2
    h, udot = dt / sub, (u - u_prev) / dt

    def f(xc, uu):
        return block.derivative(xc, uu, udot, p)[0]

    for k in range(sub):
        u0 = u_prev + udot * k * h
        k1 = f(x, u0)
        k2 = f(x + h / 2 * k1, u0 + udot * h / 2)
        k3 = f(x + h / 2 * k2, u0 + udot * h / 2)
        k4 = f(x + h * k3, u0 + udot * h)
        x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    xn, y = block.step(ca.vertcat(0.3, -1.0, u_prev), u, p, dt)
    np.testing.assert_allclose(np.asarray(x).ravel(), np.asarray(xn).ravel()[:2], rtol=1e-9)
    assert float(y) == pytest.approx(float(x[0]), rel=1e-9)


def test_selection_prefers_resonance_where_the_data_rings():
    truth = Series.from_spec("resonance+linear", dt=DT).set_params(
        **{"resonance.natural_frequency_hz": 25.0, "resonance.damping_ratio": 0.1, "linear.gain": 3e-6})
    runs = _runs(truth, freqs=(6, 14, 22, 30, 45), noise=1e-9, n=800)  # each fold keeps a run near 25 Hz
    sel = select_physics(runs, blocks=("lag", "resonance"), settings=SelectionSettings(max_folds=3))  # three folds: each keeps 22 or 30 Hz
    assert sel.spec == "resonance+linear", sel.table()
    assert sel.cv_rmse["resonance+linear"] < 0.1 * sel.cv_rmse["lag+linear"]
