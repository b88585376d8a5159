"""The physics inverse on wanted paths it cannot follow exactly: bounded inputs, and lags passed
through where inverting them would amplify the noise of a measured path."""

import numpy as np
import pytest

from hybrid import HybridModel, TrainingSettings
from hybrid.models._hybrid import inverse_form
from physics import Lag, LinearMap, PhysicsError, Series
from physics.data import Trajectory, rmse


def _lag_linear(rate=200.0, tau=0.08):
    model = Series(Lag(), LinearMap(), dt=1 / rate)
    model.params = [tau, 2e-4, 1e-3]  # time constant (s), gain (m/kPa), offset (m)
    return model


def _runs(model, noise, freqs=(0.3, 1.0, 0.6), seed=0):
    """Decaying sinusoids 0-500 kPa through ``model``, with ``noise`` metres of measurement noise."""
    rng = np.random.default_rng(seed)
    runs = []
    for f in freqs:
        t = np.arange(int(4 * 200 / f)) / 200
        u = 250 - 240 * np.cos(2 * np.pi * f * t) * np.exp(-0.1 * f * t)
        runs.append(Trajectory(t, u, model.simulate(u) + rng.normal(0, noise, t.size)))
    return runs


def test_a_bounded_inverse_stays_in_bounds_and_follows_the_path_wherever_it_can():
    model = _lag_linear()
    t = np.arange(600) / 200
    y = model.simulate(250 + 200 * np.sin(2 * np.pi * 0.5 * t))
    y[200:260] += 0.2  # a jump far beyond what 0..500 kPa reaches within the lag
    free = model.inverse(y)
    u = model.inverse(y, bounds=(0.0, 500.0))
    assert free.max() > 1000  # the exact inverse asks for an input far outside the actuator's range
    assert u.min() >= 0.0 and u.max() <= 500.0
    inside = (u > 1e-9) & (u < 500 - 1e-9)
    assert inside.sum() > 450 and (~inside).sum() > 20
    # the state is advanced by the input actually applied: wherever the input is not at a bound,
    # the model driven by it lands exactly on the wanted path again
    np.testing.assert_allclose(model.simulate(u)[inside], y[inside], rtol=0, atol=1e-12)
    # wide bounds change nothing
    np.testing.assert_allclose(model.inverse(y, bounds=(-1e9, 1e9)), free, rtol=1e-12, atol=1e-9)


def test_quasi_static_passes_the_lag_through():
    model = _lag_linear()
    y = np.linspace(1e-3, 0.1, 50)
    np.testing.assert_allclose(model.inverse(y, quasi_static=True), (y - 1e-3) / 2e-4, rtol=1e-12)


@pytest.mark.parametrize("bounds", [(1.0, 1.0), (2.0, 1.0), (np.nan, 1.0), "ab", (1.0,)])
def test_bad_bounds_are_a_clear_error(bounds):
    with pytest.raises(PhysicsError, match="bounds"):
        _lag_linear().inverse(np.ones(5), bounds=bounds)


def test_inverse_form_passes_a_long_lag_through_on_noisy_paths_and_inverts_it_on_clean_ones():
    model = _lag_linear()
    noisy, clean = _runs(model, noise=1e-3), _runs(model, noise=1e-7)
    bounds, quasi = inverse_form(model, noisy)
    u = np.concatenate([r.u for r in noisy])
    assert quasi and bounds == pytest.approx((u.min() - 0.2 * np.ptp(u), u.max() + 0.2 * np.ptp(u)), rel=1e-12)
    assert not inverse_form(model, clean)[1]
    exact = np.concatenate([model.inverse(r.y) - r.u for r in noisy])
    chosen = np.concatenate([model.inverse(r.y, bounds=bounds, quasi_static=True) - r.u for r in noisy])
    # noise 1e-3 m is 5 kPa through the gain; the exact inverse of a 16-sample lag amplifies it ~20x
    assert np.sqrt(np.mean(chosen**2)) < 0.25 * np.sqrt(np.mean(exact**2))


def test_an_inverse_hybrid_keeps_its_inverse_form_through_save_and_load(tmp_path):
    model = _lag_linear()
    runs = _runs(model, noise=1e-3)
    test = _runs(model, noise=1e-3, freqs=(0.45,), seed=5)[0]
    hyb = HybridModel(model, "fnn", "inverse", training=TrainingSettings(epochs=3, progress=False)).fit(runs)
    assert hyb.inverse_quasi_static_ and hyb.input_bounds_ == inverse_form(model, runs)[0]
    np.testing.assert_allclose(hyb.predict_physics(test), model.inverse(test.y, bounds=hyb.input_bounds_,
                                                                          quasi_static=True), rtol=1e-12)
    assert rmse(hyb.predict_physics(test), test.u) < 0.25 * rmse(model.inverse(test.y), test.u)
    hyb.save(tmp_path / "inv.pt")
    back = HybridModel.load(tmp_path / "inv.pt")
    assert back.inverse_quasi_static_ and back.input_bounds_ == pytest.approx(hyb.input_bounds_)
    np.testing.assert_allclose(back.predict(test), hyb.predict(test), rtol=1e-12, atol=1e-12)
