"""A Series saved and loaded keeps dt, every structural setting and its parameters; so does a fit JSON."""

import json

import numpy as np
import pytest

from hybrid.cli._main import main
from hybrid.export import ExportedModel, export_model
from hybrid.export import load as load_model
from identification import identify
from physics import (AbstractBlock, Backlash, BoucWen, Delay, Drift, Lag, LinearMap, PhysicsError, Poly,
                     Preisach, Series)


class _Run:
    def __init__(self, u, y, dt):
        self.u, self.y, self.time = u, y, np.arange(u.size) * dt


def _path(n=400, dt=0.01):
    t = np.arange(n) * dt
    return 3 - 2.5 * np.cos(2 * np.pi * 0.7 * t) + 0.3 * np.sin(2 * np.pi * 2.3 * t)


def test_series_round_trips_with_dt_settings_and_parameters():
    model = Series(Lag(time_constant_s=0.07), Delay(samples=3), Backlash(width=0.2, smoothing=0.003),
                   BoucWen(A=0.3, beta=1.2, gamma=0.4, substeps=5), Poly(c2=0.01, c3=-0.02, center=2.5),
                   LinearMap(gain=9.0, offset=12.0), Drift(rate=0.1), dt=0.01)
    state = json.loads(json.dumps(model.to_dict()))
    back = Series.from_dict(state)
    assert back.dt == 0.01 and back.spec == model.spec and repr(back) == repr(model)
    assert [b.get_settings() for b in back.blocks] == [b.get_settings() for b in model.blocks]
    assert back.blocks[1].samples == 3 and back.blocks[3].substeps == 5 and back.blocks[4].center == 2.5
    u = _path()
    np.testing.assert_allclose(back.simulate(u), model.simulate(u), rtol=0, atol=1e-12)


def test_preisach_keeps_its_grid_and_weights():
    pre = Preisach(levels=4, lower=-1.0, upper=5.0, weights=np.arange(1, 11) / 55.0)
    model = Series(pre, LinearMap(gain=2.0), dt=0.02)
    back = Series.from_dict(json.loads(json.dumps(model.to_dict())))
    assert (back.blocks[0].levels, back.blocks[0].lower, back.blocks[0].upper) == (4, -1.0, 5.0)
    np.testing.assert_array_equal(back.params, model.params)


def test_old_dictionaries_with_a_params_list_still_load():
    state = {"blocks": [{"name": "delay", "settings": {"samples": 2}}, {"name": "linear", "settings": {}}],
             "dt": 0.05, "params": [3.0, 1.0]}
    model = Series.from_dict(state)
    assert model.dt == 0.05 and model.blocks[0].samples == 2 and model.param_dict()["linear.gain"] == 3.0


def test_a_setting_that_is_not_json_ready_is_an_error_not_dropped():
    class Odd(AbstractBlock):
        name = "odd"

        def __init__(self, table=None):
            self.table = {"a": 1} if table is None else table

        def step(self, x, u, p, dt):
            return x, u

    with pytest.raises(PhysicsError, match="setting 'table' of Odd"):
        Odd().get_settings()


@pytest.fixture(scope="module")
def delay_fit(tmp_path_factory):
    """A fit of delay(4 samples) + linear at 100 Hz, written as `hyst identify` writes it."""
    truth = Series(Delay(samples=4), LinearMap(gain=2.0, offset=1.0), dt=0.01)
    u = _path()
    rng = np.random.default_rng(0)
    fit = identify(Series(Delay(samples=4), LinearMap(), dt=0.01),
                   [_Run(u, truth.simulate(u) + rng.normal(0, 0.01, u.size), 0.01)])
    path = tmp_path_factory.mktemp("fit") / "fit.json"
    path.write_text(json.dumps(fit.to_dict()))
    return fit, path, truth


def test_fit_json_export_keeps_dt_and_delay(delay_fit, tmp_path, capsys):
    fit, path, truth = delay_fit
    assert fit.parameters["linear.gain"] == pytest.approx(2.0, rel=1e-2)
    model = load_model(str(path), rate_hz=25.0)  # the rate given does not override the fit's own
    assert model.dt == 0.01 and model.blocks[0].samples == 4
    out = tmp_path / "step.casadi"
    assert main(["export", str(path), "--out", str(out)]) == 0
    exported = ExportedModel.load(out)
    assert exported.dt == 0.01 and exported.n_x == 4
    u = _path(200)
    np.testing.assert_allclose(exported.simulate(u), fit.model().simulate(u), rtol=0, atol=1e-9)


def test_old_fit_json_without_dt_uses_the_rate_given(delay_fit, tmp_path):
    _, path, _ = delay_fit
    info = json.loads(path.read_text())
    old = {k: v for k, v in info.items() if k not in ("series", "dt")}
    (tmp_path / "old.json").write_text(json.dumps(old))
    model = load_model(str(tmp_path / "old.json"), rate_hz=50.0)
    assert model.dt == 0.02 and model.spec == "delay+linear"
    assert export_model(model).dt == 0.02
