"""A new block is one class plus one register_block line: it simulates, is identified, exports,
is in discovery's vocabulary and is named by it, and round-trips through save/load."""

import json

import casadi as ca
import numpy as np
import pytest

from hybrid.export import export_model
from hybrid.export import load as load_model
from identification import EFFECTS, identify
from identification.discovery import ResidualTrace, diagnose
from physics import AbstractBlock, LinearMap, Parameter, Series, Signature, register_block, unregister_block


# -- the toy block: a smooth saturation (its whole definition) --------------------------------
class Saturation(AbstractBlock):
    """``y = center + limit * tanh((u - center) / limit)``: a soft end stop."""

    name = "saturation"
    parameters = (Parameter("limit", 5.0, 1e-3, 1e3, "input unit", "largest excursion from the centre"),)
    effect = "saturation"
    rank = 4
    signature = Signature(
        family="static", terms=(), scale="free", signal="static",
        grid=lambda dt, span: [{"limit": float(g)} for g in np.geomspace(0.1, 2.0, 24) * span],
        shapes=lambda v, dt, grid: np.column_stack(
            [g["limit"] * np.tanh((v - np.ptp(v) / 2 - v.min()) / g["limit"]) - (v - np.ptp(v) / 2 - v.min())
             for g in grid]),
        estimate=lambda e: (dict(e.grid), {"center": e.center}),
        describe=lambda p, s: f"limit {p['limit']:.3g}",
    )

    def __init__(self, limit: float | None = None, center: float = 0.0):
        self._init_parameters({"limit": limit})
        self.center = float(center)

    def step(self, x, u, p, dt):
        return ca.DM.zeros(0, 1), self.center + p[0] * ca.tanh((u - self.center) / p[0])


@pytest.fixture
def toy():
    register_block(Saturation)
    yield Saturation
    unregister_block("saturation")


def _u(n=600, dt=0.04, f=0.2):
    t = np.arange(n) * dt
    return 1.0 + 4.0 * np.sin(2 * np.pi * f * t) * (1 - 0.5 * t / t[-1])


def _truth():
    return Series(Saturation(limit=2.5, center=1.0), LinearMap(gain=3.0, offset=1.0), dt=0.04)


class _Run:
    def __init__(self, u, y, dt=0.04):
        self.u, self.y, self.time = u, y, np.arange(u.size) * dt


def test_toy_block_simulates_from_its_spec(toy):
    model = Series.from_spec("saturation+linear")
    y = model.simulate(np.array([0.0, 100.0, -100.0]))
    np.testing.assert_allclose(y, [30.0, 10.8 * 5.0 + 30.0, -10.8 * 5.0 + 30.0])


def test_toy_block_is_identified(toy):
    rng = np.random.default_rng(1)
    runs = [_Run(u, _truth().simulate(u) + rng.normal(0, 0.02, u.size)) for u in (_u(), _u(f=0.35))]
    fit = identify(Series(Saturation(center=1.0), LinearMap(), dt=0.04), runs)
    assert fit.success
    assert fit.parameters["saturation.limit"] == pytest.approx(2.5, rel=0.02)
    assert fit.parameters["linear.gain"] == pytest.approx(3.0, rel=0.02)


def test_toy_block_exports(toy):
    model, u = _truth(), _u(200)
    exported = export_model(model)
    np.testing.assert_allclose(exported.simulate(u), model.simulate(u), rtol=0, atol=1e-12)


def test_toy_block_is_in_discoverys_vocabulary_and_named_by_it(toy):
    assert "saturation" in EFFECTS and EFFECTS[-1] == "drift"
    u, dt = _u(), 0.04
    t = np.arange(u.size) * dt
    linear = Series(LinearMap(gain=3.0, offset=1.0), dt=dt)  # the model without the saturation
    residual = _truth().simulate(u) - linear.simulate(u) + np.random.default_rng(2).normal(0, 0.02, u.size)
    cands = diagnose(ResidualTrace(t, residual, u, gain=3.0), noise_std=0.02)
    assert cands and cands[0].effect == "saturation" and cands[0].block == "saturation"
    assert cands[0].describe().startswith("saturation, limit")


def test_toy_block_round_trips_through_save_and_load(toy, tmp_path):
    model, u = _truth(), _u(200)
    back = Series.from_dict(json.loads(json.dumps(model.to_dict())))
    assert back.blocks[0].center == 1.0 and back.param_dict() == model.param_dict()
    np.testing.assert_array_equal(back.simulate(u), model.simulate(u))
    rng = np.random.default_rng(3)
    fit = identify(Series(Saturation(limit=2.0, center=1.0), LinearMap(), dt=0.04),
                   [_Run(_u(), model.simulate(_u()) + rng.normal(0, 0.02, 600))])
    path = tmp_path / "fit.json"
    path.write_text(json.dumps(fit.to_dict()))
    loaded = load_model(str(path))
    assert loaded.blocks[0].center == 1.0 and loaded.dt == 0.04
    np.testing.assert_allclose(loaded.simulate(u), fit.model().simulate(u), rtol=0, atol=1e-12)


def test_unregistered_toy_is_gone():
    assert "saturation" not in EFFECTS


def test_toy_block_is_tried_by_the_selection_without_being_named(toy):
    """The selection's vocabulary is the registry: the toy declares nothing about selection, so it is
    tried after the built-in blocks (``selection_order`` ties in registration order), and on runs of a
    saturation truth it is the block kept."""
    from identification.discovery import SELECT_BLOCKS, SelectionSettings, select_physics
    from physics.data import Trajectory

    assert SELECT_BLOCKS[-1] == "saturation"
    rng = np.random.default_rng(4)
    truth = Series(Saturation(limit=2.5), LinearMap(gain=3.0, offset=1.0), dt=0.04)  # centred where a spec puts it
    inputs = [u - 1.0 for u in (_u(300), _u(300, f=0.35), _u(300, f=0.27), 0.5 + 0.8 * _u(300, f=0.15))]
    runs = [Trajectory(np.arange(u.size) * 0.04, u, truth.simulate(u) + rng.normal(0, 0.02, u.size),
                       source=f"run{i}") for i, u in enumerate(inputs)]
    sel = select_physics(runs, settings=SelectionSettings(max_folds=4))
    assert "saturation+linear" in sel.cv_rmse
    assert sel.spec == "saturation+linear", sel.table()
    assert sel.cv_rmse["saturation+linear"] < 0.03  # the noise's 0.02, not the line's
