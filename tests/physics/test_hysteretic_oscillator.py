"""The hysteretic oscillator (Bouc-Wen force inside a mass-spring-damper): its step against an accurate
ODE solution and the Bouc-Wen benchmark's equations, recovered from data in any units, kept stable by
identification, inverted, the same in torch, exported, and chosen by selection where the hysteresis
acts inside the dynamics."""

import numpy as np
import pytest
import scipy.integrate

from hybrid.export import export_model
from identification import identify, select_physics
from physics import HystereticOscillator, LinearMap, Resonance, Series, resolve_effect
from physics.data import Trajectory

from _synthetic import assert_torch_paths_equal_casadi

DT = 1 / 400
TRUTH = {"hysteretic_oscillator.natural_frequency_hz": 12.0, "hysteretic_oscillator.damping_ratio": 0.08,
         "hysteretic_oscillator.A": 1.0, "hysteretic_oscillator.beta": 0.03, "hysteretic_oscillator.gamma": 0.01,
         "linear.gain": 2e-5, "linear.offset": 1e-6}


def _truth(dt=DT):
    """A stage in newtons -> metres: a 12 Hz mode (17 Hz at small motion), a Bouc-Wen force in the spring."""
    return Series.from_spec("hysteretic_oscillator+linear", dt=dt).set_params(**TRUTH)


def _u(seed, n=2400):
    """Band-limited random force (N): a sum of sines 0.5-25 Hz with random phases, up to about 100 N."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * DT
    freqs = np.linspace(0.5, 25.0, 24)
    return 30.0 * np.sum(np.sin(2 * np.pi * freqs[:, None] * t + rng.uniform(0, 2 * np.pi, (freqs.size, 1))), 0) / 5


def _runs(truth, seeds=(0, 1, 2), noise=2e-7, n=2400, noise_seed=10):
    rng = np.random.default_rng(noise_seed)
    out = []
    for s in seeds:
        u = _u(s, n)
        out.append(Trajectory(np.arange(u.size) * DT, u, truth.simulate(u) + rng.normal(0, noise, u.size),
                              source=f"run{s}"))
    return out


def test_named_under_resonance_and_its_aliases():
    assert resolve_effect("boucwen_oscillator") == "resonance"
    assert Series.from_spec("hysteretic_oscillator+linear").state_names[:3] == [
        "hysteretic_oscillator.position", "hysteretic_oscillator.velocity", "hysteretic_oscillator.z"]


def test_step_matches_an_accurate_ode_solution():
    block = HystereticOscillator(natural_frequency_hz=12.0, damping_ratio=0.08, A=1.0, beta=0.03, gamma=0.01,
                                 eps=1e-9)
    model = Series(block, dt=DT)
    u = _u(0, 800)
    t = np.arange(u.size) * DT
    w = 2 * np.pi * 12.0

    def rhs(tt, s):
        ui = np.interp(tt, t, u)  # the block's input is linear between samples
        x, v, z = s
        return [v, w * w * (ui - x - z) - 2 * 0.08 * w * v, 1.0 * v - 0.03 * abs(v) * z - 0.01 * v * abs(z)]

    ref = scipy.integrate.solve_ivp(rhs, (0, t[-1]), [u[0], 0, 0], t_eval=t, method="DOP853", rtol=1e-11,
                                    atol=1e-11, max_step=DT / 4).y[0]
    y = model.simulate(u)
    assert np.max(np.abs(y - ref)) < 1e-4 * np.ptp(ref)


def test_without_hysteresis_it_is_the_resonance():
    u = _u(1, 800)
    osc = Series(HystereticOscillator(natural_frequency_hz=20.0, damping_ratio=0.3, A=0.0, beta=0.0, gamma=0.0),
                 dt=DT).simulate(u)
    res = Series.from_spec("resonance", dt=DT).set_params(**{"resonance.natural_frequency_hz": 20.0,
                                                             "resonance.damping_ratio": 0.3}).simulate(u)
    np.testing.assert_allclose(osc, res, rtol=1e-12, atol=1e-12 * np.ptp(res))


def test_it_writes_the_boucwen_benchmark_equations():
    # m y'' + c y' + k y + z_b = F, z_b' = alpha y' - bg |y'| z_b - bd y' |z_b|, with x = k y (N), z = z_b:
    # f_n = sqrt(k/m) / 2 pi, zeta = c / (2 sqrt(k m)), A = alpha / k, beta = bg / k, gamma = bd / k, gain 1/k
    m, c, k, alpha, bg, bd = 2.0, 10.0, 5e4, 5e4, 800.0, -1100.0
    dt = 1 / 750
    model = Series.from_spec("hysteretic_oscillator+linear", dt=dt).set_params(**{
        "hysteretic_oscillator.natural_frequency_hz": np.sqrt(k / m) / (2 * np.pi),
        "hysteretic_oscillator.damping_ratio": c / (2 * np.sqrt(k * m)), "hysteretic_oscillator.A": alpha / k,
        "hysteretic_oscillator.beta": bg / k, "hysteretic_oscillator.gamma": bd / k,
        "linear.gain": 1 / k, "linear.offset": 0.0})
    rng = np.random.default_rng(3)
    force = 50 * np.convolve(rng.standard_normal(3000), np.ones(5) / 5, "same")
    y = model.simulate(force)
    t = np.arange(force.size) * dt

    def rhs(tt, s):
        f = np.interp(tt, t, force)
        yy, v, z = s
        return [v, (f - c * v - k * yy - z) / m, alpha * v - bg * abs(v) * z - bd * v * abs(z)]

    ref = scipy.integrate.solve_ivp(rhs, (0, t[-1]), [force[0] / k, 0, 0], t_eval=t, method="DOP853", rtol=1e-10,
                                    atol=1e-14, max_step=dt / 4).y[0]
    assert np.sqrt(np.mean((y - ref) ** 2)) < 2e-3 * np.sqrt(np.mean(ref ** 2))


def test_parameters_are_recovered_in_newtons_and_metres():
    truth = _truth()
    fit = identify(Series.from_spec("hysteretic_oscillator+linear", dt=DT), _runs(truth, n=1200))  # 0.1 % off
    assert fit.success
    for name, value in TRUTH.items():
        if name != "linear.offset":
            assert fit.parameters[name] == pytest.approx(value, rel=0.05), name
    assert fit.train_rmse < 1.2 * 2e-7  # the noise floor


def test_stays_stable_where_an_explicit_step_would_not():
    # a 300 Hz mode sampled at 100 Hz and a loop that saturates within a hundredth of a sample's motion
    u = np.sin(np.arange(150) * 0.3)
    fast = HystereticOscillator(natural_frequency_hz=300.0, damping_ratio=0.5, A=1.0, beta=200.0, gamma=100.0)
    y = Series(fast, dt=0.01).simulate(u)
    assert np.all(np.isfinite(y))
    # against a stiff solver (Radau) of the same equations
    t, w = np.arange(u.size) * 0.01, 2 * np.pi * 300.0

    def rhs(tt, st):
        x, v, z = st
        return [v, w * w * (np.interp(tt, t, u) - x - z) - 2 * 0.5 * w * v, v - 200 * abs(v) * z - 100 * v * abs(z)]

    ref = scipy.integrate.solve_ivp(rhs, (0, t[-1]), [u[0], 0, 0], t_eval=t, method="Radau", rtol=1e-9,
                                    atol=1e-12, max_step=0.01 / 8).y[0]
    assert np.max(np.abs(y - ref)) < 2e-3 * np.ptp(ref)


def test_inverse_is_quasi_static():
    model = _truth(dt=0.01)
    t = np.arange(0, 20, 0.01)
    u = 40 * np.sin(2 * np.pi * 0.1 * t) + 10 * np.sin(2 * np.pi * 0.23 * t)  # far below the 12 Hz mode
    back = model.inverse(model.simulate(u))
    assert np.sqrt(np.mean((back - u) ** 2)) < 0.02 * np.ptp(u)


def test_torch_paths_equal_casadi():
    pytest.importorskip("torch")
    model = _truth()
    rng = np.random.default_rng(0)
    x = np.column_stack([rng.normal(0, 30, 5), rng.normal(0, 500, 5), rng.normal(0, 10, 5), rng.normal(0, 30, 5)])
    assert_torch_paths_equal_casadi(model, x, rng.normal(0, 30, (5, 1)), _u(2, 300), rtol=1e-9, atol=1e-15)


def test_export_and_round_trip():
    model, u = _truth(), _u(4, 400)
    exported = export_model(model)
    np.testing.assert_allclose(exported.x0(u[0])[:4], [u[0], 0.0, 0.0, u[0]], atol=1e-12)
    np.testing.assert_allclose(exported.simulate(u), model.simulate(u), rtol=1e-10, atol=1e-18)
    back = Series.from_dict(model.to_dict())
    np.testing.assert_array_equal(back.simulate(u), model.simulate(u))


def test_selection_refines_a_ringing_resonance_into_it_where_the_hysteresis_acts_inside_the_dynamics():
    runs = _runs(_truth(), n=700, noise_seed=4)
    sel = select_physics(runs, blocks=("resonance", "boucwen"))  # the greedy search, then its refinements
    assert sel.spec == "hysteretic_oscillator+linear", sel.table()
    assert sel.path[-2:] == ["resonance+boucwen+linear", "hysteretic_oscillator+linear"], sel.path
    assert sel.cv_rmse[sel.spec] < 0.5 * sel.cv_rmse["resonance+boucwen+linear"]


def test_only_a_resonance_that_rings_is_refined():
    assert Resonance.shows_effect({"natural_frequency_hz": 12.0, "damping_ratio": 0.3})
    assert not Resonance.shows_effect({"natural_frequency_hz": 12.0, "damping_ratio": 3.0})
    model = Series(Resonance(natural_frequency_hz=3.0, damping_ratio=4.0), LinearMap(), dt=DT)  # two slow lags
    runs = [Trajectory(np.arange(u.size) * DT, u, model.simulate(u)) for u in (_u(0, 600), _u(1, 600))]
    sel = select_physics(runs, blocks=("resonance",))
    assert sel.spec == "resonance+linear" and not any("hysteretic_oscillator" in s for s in sel.cv_rmse), sel.table()
    ringing = Series(Resonance(natural_frequency_hz=12.0, damping_ratio=0.2), LinearMap(), dt=DT)
    runs = [Trajectory(r.time, r.u, ringing.simulate(r.u)) for r in runs]
    assert "hysteretic_oscillator+linear" in select_physics(runs, blocks=("resonance",)).cv_rmse
