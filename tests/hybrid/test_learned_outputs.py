"""A learned model of several outputs (issue 55): one network ends in one unit per output, saved, loaded and
exported as the model of every output; a model of one output saves as it always has."""

import json

import numpy as np
import pytest

from hybrid.learning import LearnedModel, TrainingSettings
from hybrid.networks import FNNHIBNet
from physics.data import DataError

POSE = ("Angle x", "Pos x", "Pos y")


@pytest.fixture(scope="module")
def runs(pose_runs):
    return pose_runs


@pytest.fixture(scope="module")
def pose(runs):
    training = TrainingSettings(epochs=40, progress=False, seed=0)
    return LearnedModel(FNNHIBNet(buffer=10), outputs=POSE, training=training).fit(runs[:2])


def test_one_network_predicts_every_output(pose, runs):
    """Forty epochs on two runs: each output of the third run within a few percent of its span, every output from
    the one network (its last layer has three units)."""
    from identification import output_columns

    assert pose.n_outputs_ == 3 and pose.module_.n_outputs == 3
    measured = output_columns(runs[2], POSE)
    predicted = pose.predict(runs[2])
    assert predicted.shape == (runs[2].n, 3)
    rmse = np.sqrt(np.mean((predicted - measured) ** 2, axis=0))
    assert np.all(rmse < 0.1 * np.ptp(measured, axis=0)), rmse
    state = pose.initial_state(runs[2].u[0])
    stepped = []
    for u in runs[2].u[:30]:
        state, y = pose.step(state, u)
        stepped.append(y)
    np.testing.assert_allclose(np.array(stepped), predicted[:30], rtol=1e-5, atol=1e-4)


def test_saved_loaded_and_exported_as_the_model_of_every_output(pose, runs, tmp_path):
    from hybrid.export import export_model

    path = pose.save(tmp_path / "pose.pt")
    assert json.loads(path.with_suffix(".json").read_text())["settings"]["outputs"] == list(POSE)
    again = LearnedModel.load(path)
    np.testing.assert_array_equal(again.predict(runs[2]), pose.predict(runs[2]))
    exported = export_model(again)
    assert exported.n_y == 3
    np.testing.assert_allclose(exported.simulate(runs[2].u), pose.predict(runs[2]), rtol=1e-4, atol=1e-3)


def test_one_output_saves_as_before_and_bad_outputs_are_refused(runs, tmp_path):
    training = TrainingSettings(epochs=1, progress=False)
    one = LearnedModel(FNNHIBNet(buffer=10), training=training).fit(runs[:1])
    assert one.predict(runs[2]).shape == (runs[2].n,)
    assert "outputs" not in json.loads(one.save(tmp_path / "one.pt").with_suffix(".json").read_text())["settings"]
    for kwargs, message in (({"outputs": ("Angle x", "Pos z")}, "has no output column 'Pos z'"),
                            ({"outputs": ("Angle x", "Angle x")}, "distinct column names"),
                            ({"outputs": POSE, "direction": "inverse"}, "an inverse model predicts the one input"),
                            ({"outputs": POSE, "features": ("Pos x",)}, "both an output and a feature")):
        with pytest.raises(DataError, match=message):
            LearnedModel(FNNHIBNet(buffer=10), training=training, **kwargs).fit(runs[:1])
