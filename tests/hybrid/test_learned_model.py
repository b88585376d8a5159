"""LearnedModel: fit/predict contract, forward and inverse, checkpoints, repeatability, errors."""

import json

import numpy as np
import pytest
import torch

from hybrid import FNNHIBNet, FNNNet, LearnedModel, LSTMNet, TrainingSettings
from physics.data import DataError, NotFittedError, Trajectory, rmse
from physics.virtual import paper_protocol

FAST = TrainingSettings(epochs=2, stride=3, progress=False, threads=1)


@pytest.fixture(scope="module")
def split():
    return paper_protocol(frequencies=(0.4, 0.5), tests=(0.45,), baselines=("mid",))


@pytest.mark.parametrize("direction", ["forward", "inverse"])
@pytest.mark.parametrize("net", [FNNNet(), FNNHIBNet(buffer=20), LSTMNet(hidden=16, seq_len=20)], ids=repr)
def test_fit_predict_step_and_checkpoint_round_trip(split, net, direction, tmp_path):
    model = LearnedModel(net, direction, training=FAST)
    assert model.fit(split.train) is model
    test = split.test[0]
    yhat = model.predict(test)
    truth = test.swap().y if direction == "inverse" else test.y
    assert yhat.shape == (test.n,) and np.all(np.isfinite(yhat))
    assert rmse(truth, yhat) < 0.5 * (truth.max() - truth.min())  # learned something on the right scale
    # controller view: step by step with explicit state equals the batched prediction
    u = test.swap().u if direction == "inverse" else test.u
    state = model.initial_state(u[0])
    steps = []
    for value in u[:80]:
        state, y = model.step(state, value)
        steps.append(y)
    np.testing.assert_allclose(steps, yhat[:80], rtol=0, atol=1e-4 * np.ptp(truth))
    # checkpoint: identical predictions, readable metadata with provenance
    path = model.save(tmp_path / "m.pt")
    again = LearnedModel.load(path)
    np.testing.assert_array_equal(again.predict(test), yhat)
    meta = json.loads(path.with_suffix(".json").read_text())
    assert meta["settings"]["direction"] == direction and meta["settings"]["network"]["name"] == net.name
    assert [p["source"] for p in meta["provenance"]] == list(split.train.names)
    assert len(meta["provenance"][0]["sha256"]) == 64


def test_same_seed_same_weights_other_seed_not(split):
    def weights(seed):
        m = LearnedModel(LSTMNet(hidden=8, seq_len=10), training=FAST.replace(seed=seed, validation=0.2))
        m.fit(split.train)
        return [p.detach().clone() for p in m.module_.parameters()]

    a, b, c = weights(3), weights(3), weights(4)
    assert all(torch.equal(x, y) for x, y in zip(a, b))
    assert not all(torch.equal(x, y) for x, y in zip(a, c))


def test_early_stopping_keeps_the_best_validation_epoch(split):
    m = LearnedModel(FNNNet(hidden=(4,)), training=TrainingSettings(epochs=200, validation=0.2, patience=2, stride=5,
                                                                     lr=0.05, progress=False)).fit(split.train)
    h = m.history_
    assert h.stopped_early and h.epochs_run < 200
    assert h.val_loss[h.best_epoch] == min(h.val_loss) and h.n_val > 0


def test_clear_errors(split):
    short = Trajectory(np.arange(30) * 0.04, np.linspace(0, 1, 30), np.linspace(0, 2, 30), source="short")
    with pytest.raises(DataError, match="'short' has 30 samples but FNNHIBNet.*needs at least 50"):
        LearnedModel(FNNHIBNet(buffer=50), training=FAST).fit(short)
    with pytest.raises(NotFittedError, match="not fitted yet"):
        LearnedModel(FNNNet()).predict(split.test[0])
    with pytest.raises(DataError, match="direction"):
        LearnedModel(FNNNet(), "sideways").fit(split.train)
    with pytest.raises(DataError, match="network must be"):
        LearnedModel("lstm").fit(split.train)
    with pytest.raises(DataError, match="non-finite"):
        Trajectory(np.arange(3.0), [0.0, np.nan, 1.0], [0.0, 1.0, 2.0])
    model = LearnedModel(FNNNet(hidden=(4,)), training=FAST).fit(split.train)
    with pytest.raises(DataError, match="non-finite value .* at sample 1"):
        model.predict(np.array([1.0, np.nan, 2.0]))
    with pytest.raises(DataError, match="mode"):
        model.predict(split.test[0], mode="carried")
    with pytest.raises(DataError, match="patience .* needs a validation split"):
        LearnedModel(FNNNet(), training=FAST.replace(patience=3)).fit(split.train)
    with pytest.raises(DataError, match="lacks the feature column"):
        LearnedModel(FNNNet(), features=("nope",), training=FAST).fit(split.train)


def test_extra_features_are_fed_to_the_network(split):
    model = LearnedModel(FNNHIBNet(buffer=10), features=("q_actual",), training=FAST).fit(split.train)
    assert model.n_features_in_ == 2
    assert model.predict(split.test[0]).shape == (split.test[0].n,)


def test_training_logs_a_line_per_tenth_of_the_epochs_when_stderr_is_not_a_terminal(capsys):
    """progress=True without a terminal (a log, CI): plain lines, not a bar's carriage returns."""
    import torch

    from hybrid.learning._training import TrainingSettings, train

    torch.manual_seed(0)
    x = np.random.default_rng(0).normal(size=(64, 3)).astype(np.float32)
    train(torch.nn.Linear(3, 1), x, 2 * x[:, :1], TrainingSettings(epochs=20, progress=True, validation=0.25),
          desc="fit")
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 10 and "\r" not in err
    assert lines[0].startswith("fit: epoch 2/20, loss ") and lines[-1].startswith("fit: epoch 20/20")
