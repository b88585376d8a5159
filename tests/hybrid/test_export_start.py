"""One initial-state rule: an exported model equals the fitted model's predict from sample 0.

Before this rule, an exported network rested at the first input for a warm-up before the
run, while ``predict`` started from the training's start state: the two differed at the
start of every run (0.037 deg at sample 0 for an LSTM hybrid). Here every model kind runs
in float64 and must agree to 1e-9 from the first sample, also after a save/load round trip.
"""

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from hybrid import HybridModel, LearnedModel, TrainingSettings  # noqa: E402
from hybrid.export import ExportedModel, export_model  # noqa: E402
from hybrid.networks import FNNHIBNet, FNNNet, LSTMNet  # noqa: E402
from physics import Series  # noqa: E402
from physics.virtual import VirtualCatheter, paper_protocol  # noqa: E402

FAST = dict(training=TrainingSettings(epochs=1, progress=False, threads=1, seed=0))
NETWORKS = {
    "fnn": lambda: FNNNet(hidden=(8, 8)),
    "fnn-hib-edge": lambda: FNNHIBNet(buffer=6, hidden=(8,)),
    "fnn-hib-pad": lambda: FNNHIBNet(buffer=6, hidden=(8,), pad=-1.0),
    "lstm-carried": lambda: LSTMNet(hidden=6, layers=2, seq_len=8, mode="carried"),
    "lstm-window": lambda: LSTMNet(hidden=4, layers=1, seq_len=6, mode="window"),
}


@pytest.fixture(scope="module")
def split():
    return paper_protocol(VirtualCatheter(seed=0), frequencies=(0.5,), tests=(0.45,), baselines=("mid",))


def _check(model, exported, u, tmp_path):
    expected = model.predict(u)
    np.testing.assert_allclose(exported.simulate(u), expected, rtol=0, atol=1e-9)
    back = ExportedModel.load(exported.save(tmp_path / "m.casadi"))
    np.testing.assert_allclose(back.simulate(u[:60]), expected[:60], rtol=0, atol=1e-9)


@pytest.mark.parametrize("name", list(NETWORKS))
def test_learned_export_equals_predict_from_sample_0(name, split, tmp_path):
    model = LearnedModel(NETWORKS[name](), **FAST).fit(split.train)
    model.module_.double()
    _check(model, export_model(model), split.test[0].u[:300], tmp_path)


@pytest.mark.parametrize("name", ["fnn-hib-pad", "lstm-carried", "lstm-window"])
def test_hybrid_export_equals_predict_and_steps_from_sample_0(name, split, tmp_path):
    model = HybridModel("lag+boucwen+linear", NETWORKS[name](), **FAST).fit(split.train)
    model.residual_.module_.double()
    u = split.test[0].u[:300]
    exported = export_model(model)
    _check(model, exported, u, tmp_path)
    train_u = np.concatenate([t.u for t in split.train])  # the MPC's default bounds
    assert exported.input_range == pytest.approx((train_u.min(), train_u.max()), rel=1e-12)
    assert model.physics_.input_range == pytest.approx(exported.input_range, rel=1e-12)
    state, steps = model.initial_state(u[0]), []
    for v in u[:40]:
        state, y = model.step(state, v)
        steps.append(y)
    np.testing.assert_allclose(steps, model.predict(u)[:40], rtol=0, atol=1e-9)


def test_physics_export_starts_where_simulate_does(split):
    series = Series.from_spec("lag+backlash+boucwen+linear")
    u = split.test[0].u[:200]
    np.testing.assert_allclose(export_model(series).simulate(u), series.simulate(u), rtol=0, atol=1e-9)


def test_sidecar_states_the_rule_and_old_warmup_files_load_as_written(split, tmp_path):
    import json

    model = LearnedModel(NETWORKS["lstm-carried"](), **FAST).fit(split.train)
    exported = export_model(model)
    path = exported.save(tmp_path / "lstm.casadi")
    side = path.with_name(path.name + ".json")
    info = json.loads(side.read_text())
    assert info["x0"]["rule"].startswith("x0 = base(u0)") and "warmup_steps" not in info["x0"]
    # a file written before the rule: base then 5 steps resting at u0
    info["x0"]["warmup_steps"] = 5
    side.write_text(json.dumps(info))
    old = ExportedModel.load(path)
    x = exported.x0(2.0)
    for _ in range(5):
        x = np.asarray(exported.step(x, 2.0)[0]).ravel()
    np.testing.assert_allclose(old.x0(2.0), x, rtol=0, atol=1e-12)
