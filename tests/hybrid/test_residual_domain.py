"""The residual trusted only near its training data: on the data the hybrid is physics plus residual,
far from it the physics alone; predict, step, checkpoint and export agree."""

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from hybrid import HybridModel, TrainingSettings  # noqa: E402
from hybrid.export import ExportedModel, export_model  # noqa: E402
from hybrid.models import ResidualDomain  # noqa: E402
from hybrid.networks import FNNHIBNet, LSTMNet  # noqa: E402
from physics.data import DataError, Trajectory  # noqa: E402

DT = 0.1
FAST = dict(training=TrainingSettings(epochs=3, progress=False, threads=1, seed=0))


def test_weight_is_one_on_the_rows_and_exp_minus_one_at_the_radius():
    x = np.linspace(0.0, 1.0, 101)[:, None]  # spacing 0.01: every nearest-neighbour distance is 0.01
    dom = ResidualDomain(scale=2.0).fit(x)
    std = x.std()
    assert dom.radius_ == pytest.approx(2.0 * 0.01 / std, rel=1e-9)
    at_radius = 1.0 + dom.radius_ * std  # one radius beyond the last row, in physical units
    w = dom.weight([[0.37], [0.375], [at_radius], [5.0]])
    np.testing.assert_allclose(w[:3], [1.0, np.exp(-(0.005 / 0.02) ** 2), np.exp(-1.0)], rtol=1e-9)
    assert w[3] < 1e-300 or w[3] == 0.0


def test_rows_are_thinned_and_bad_settings_say_how_to_fix():
    dom = ResidualDomain(scale=0.5, max_rows=100).fit(np.random.default_rng(0).normal(size=(1000, 2)))
    assert dom.rows_.shape == (100, 2)
    with pytest.raises(DataError, match="must be a number > 0"):
        ResidualDomain(scale=0).fit(np.zeros((5, 1)))
    with pytest.raises(DataError, match="finite training rows"):
        ResidualDomain().fit(np.array([[np.nan], [1.0]]))
    with pytest.raises(DataError, match="2 features"):
        dom.weight([[1.0, 2.0, 3.0]])
    with pytest.raises(DataError, match="residual_domain"):
        HybridModel("linear", "fnn", residual_domain=-1.0, **FAST).fit(_runs(0.0, 2.0))


def _runs(lo, hi, n_runs=3):
    """Sweeps over [lo, hi]: a linear map plus a wiggle the physics ('linear') does not have."""
    out = []
    for i in range(n_runs):
        t = np.arange(300) * DT
        u = lo + (hi - lo) * (0.5 - 0.5 * np.cos(2 * np.pi * (0.1 + 0.05 * i) * t))
        out.append(Trajectory(t, u, 30 + 10 * u + 2 * np.sin(3 * u), source=f"r{i}"))
    return out


@pytest.fixture(scope="module")
def fitted():
    train = _runs(0.0, 2.0)
    gated = HybridModel("linear", FNNHIBNet(buffer=4, hidden=(8,)), residual_domain=0.5, **FAST).fit(train)
    plain = HybridModel("linear", FNNHIBNet(buffer=4, hidden=(8,)), **FAST).fit(train)
    return train, gated, plain


def test_on_the_data_the_residual_speaks_off_it_the_physics(fitted):
    train, gated, plain = fitted
    inside = train[1]
    np.testing.assert_allclose(gated.predict_physics(inside), plain.predict_physics(inside), rtol=0, atol=1e-9)
    r_gated = gated.predict(inside) - gated.predict_physics(inside)
    r_plain = plain.predict(inside) - plain.predict_physics(inside)
    w = r_gated / np.where(r_plain == 0, 1, r_plain)  # training does not depend on the domain: same residual
    assert np.median(w) > 0.95
    far = _runs(6.0, 8.0, 1)[0]  # an input range never seen: the prediction is the physics alone
    np.testing.assert_allclose(gated.predict(far), gated.predict_physics(far), rtol=0, atol=1e-9)
    assert np.max(np.abs(plain.predict(far) - plain.predict_physics(far))) > 1e-3  # the plain residual is not zero


@pytest.mark.parametrize("net", [FNNHIBNet(buffer=4, hidden=(8,)), LSTMNet(hidden=6, seq_len=8, mode="carried")],
                         ids=["fnn-hib", "lstm"])
def test_step_checkpoint_and_export_weight_the_residual_alike(net, tmp_path):
    train = _runs(0.0, 2.0)
    model = HybridModel("linear", net, residual_domain=0.5, **FAST).fit(train)
    model.residual_.module_.double()
    test = Trajectory(train[0].time, 1.0 + 1.5 * np.sin(0.4 * train[0].time), train[0].y)  # partly off the data
    expected = model.predict(test)
    w = model.domain_.weight(np.column_stack([test.u, model.predict_physics(test)]))
    assert w.min() < 0.5 < w.max()  # the test leaves the data and comes back
    back = HybridModel.load(model.save(tmp_path / "m.pt"))
    np.testing.assert_allclose(back.predict(test), expected, rtol=0, atol=1e-6)
    state, steps = model.initial_state(test.u[0]), []
    for u in test.u[:40]:
        state, y = model.step(state, u)
        steps.append(y)
    np.testing.assert_allclose(steps, expected[:40], rtol=0, atol=1e-9)
    for symbolic in ("MX", "SX"):
        exported = export_model(model, symbolic=symbolic)
        assert exported.meta["weighted"] is True
        np.testing.assert_allclose(exported.simulate(test.u), expected, rtol=0, atol=1e-9)
    again = ExportedModel.load(exported.save(tmp_path / "h.casadi"))
    np.testing.assert_allclose(again.simulate(test.u[:50]), expected[:50], rtol=0, atol=1e-9)
