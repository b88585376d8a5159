"""Where a play starts in its band (``start`` of Backlash and GPI): a rest state, recovered from data, exported."""

import numpy as np
import pytest

from hybrid.export import export_model
from identification import identify
from physics import GPI, Backlash, LinearMap, Series
from physics.data import Trajectory

DT = 0.04


def _rising(n=900, f=0.15, mean=3.0):
    """Decaying cycles that start at rest at 0 and rise first, as the catheter's runs do."""
    t = np.arange(n) * DT
    return mean - mean * np.cos(2 * np.pi * f * t) * np.exp(-0.3 * f * t)


@pytest.mark.parametrize("block", [Backlash(width=0.8, smoothing=0.0), GPI(weights=[0.3, 0.4], widths=(0.4, 1.2),
                                                                         smoothing=0.0)])
@pytest.mark.parametrize("start", [-1.0, 0.0, 1.0])
def test_any_start_is_a_rest_state_inside_the_band(block, start):
    model = Series(block.with_settings(), dt=DT).set_params(**{f"{block.name}.start": start})
    x0 = model.steady_state(2.0)
    widths = [0.8] if block.name == "backlash" else [0.4, 1.2]
    np.testing.assert_allclose(x0, [2.0 - start * w / 2 for w in widths], atol=1e-12)
    y = model.simulate(np.full(50, 2.0))
    np.testing.assert_allclose(y, y[0], atol=1e-12)  # a held input holds the output


def test_start_is_held_at_its_value_unless_freed():
    model = Series(Backlash(start=1.0), LinearMap(), dt=DT)
    assert not model.fit_mask[model.param_names.index("backlash.start")]


def test_a_play_at_its_rising_edge_follows_a_rise_at_once():
    u = np.linspace(0.0, 0.6, 13)
    at_edge = Series(Backlash(width=0.8, smoothing=0.0, start=1.0), dt=DT).simulate(u)
    centred = Series(Backlash(width=0.8, smoothing=0.0), dt=DT).simulate(u)
    np.testing.assert_allclose(at_edge, u - 0.4, atol=1e-12)  # follows from the first sample
    np.testing.assert_allclose(centred[u <= 0.4], 0.0, atol=1e-12)  # takes up half the play first


@pytest.mark.parametrize("spec, truth", [
    ("backlash+linear", {"backlash.width": 0.8, "backlash.start": 1.0, "linear.gain": 11.0, "linear.offset": 30.0}),
    ("gpi+linear", {"gpi.w_1": 0.2, "gpi.w_2": 0.2, "gpi.w_3": 0.3, "gpi.w_4": 0.1, "gpi.w_5": 0.0,
                    "gpi.center": 3.0, "gpi.saturation": 0.0, "gpi.start": 0.7,
                    "linear.gain": 11.0, "linear.offset": 30.0}),
])
def test_start_is_recovered_from_runs_that_start_at_rest(spec, truth):
    rng = np.random.default_rng(0)
    model = Series.from_spec(spec, dt=DT)
    model = Series(*[b.for_scale(1.0) for b in model.blocks], dt=DT).set_params(**truth)
    runs = [Trajectory(np.arange(900) * DT, u, model.simulate(u) + rng.normal(0, 0.05, u.size))
            for u in (_rising(f=0.1), _rising(f=0.2), _rising(f=0.3, mean=2.5))]
    name = spec.split("+")[0]
    fit = identify(Series(*[b.for_scale(1.0) for b in Series.from_spec(spec, dt=DT).blocks], dt=DT), runs,
                   free=[f"{name}.start"])
    assert fit.success, fit.status
    assert fit.parameters[f"{name}.start"] == pytest.approx(truth[f"{name}.start"], abs=0.05)
    assert fit.train_rmse == pytest.approx(0.05, rel=0.15)
    if name == "backlash":
        assert fit.parameters["backlash.width"] == pytest.approx(0.8, rel=0.02)


def test_export_starts_where_simulate_does():
    model = Series(Backlash(width=0.8, smoothing=0.01, start=1.0), GPI(weights=[0.3], widths=(0.5,), start=-0.5),
                   LinearMap(gain=11.0, offset=30.0), dt=DT)
    u = _rising(200)
    exported = export_model(model)
    np.testing.assert_allclose(exported.x0(u[0]), model.steady_state(u[0]), atol=1e-12)
    np.testing.assert_allclose(exported.simulate(u), model.simulate(u), atol=1e-9)
