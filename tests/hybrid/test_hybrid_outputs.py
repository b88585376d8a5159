"""A hybrid of several outputs (issue 55): one physics chain whose maps read one state, one residual network ending
in one unit per output; stepped, saved, loaded and exported as the model of every output. A hybrid of one output
saves as it always has."""

import json

import numpy as np
import pytest

from hybrid.learning import TrainingSettings
from hybrid.models import FineTuneSettings, HybridModel
from hybrid.networks import FNNHIBNet
from identification import identify_outputs, output_columns
from physics import Series
from physics.data import DataError, warmup_split

POSE = ("Angle x", "Pos x", "Pos y")


@pytest.fixture(scope="module")
def runs(pose_runs):
    return pose_runs


@pytest.fixture(scope="module")
def pose(runs):
    training = TrainingSettings(epochs=40, progress=False, seed=0)
    return HybridModel("lag+linear", FNNHIBNet(buffer=10), outputs=POSE, residual_domain=3.0,
                       identify_options={"warmup": 10}, training=training).fit(runs[:2])


def test_one_residual_corrects_every_output_of_one_chain(pose, runs):
    """A chain without the catheter's hysteresis (``lag+linear``: a cubic map per output) and one FNN-HIB of three
    units: each output of the third run closer than the physics alone, from a warm-up window as from rest; stepping
    sample by sample gives the prediction."""
    assert pose.physics_.n_y == 3 and pose.residual_.module_.n_outputs == 3 and pose.n_outputs_ == 3
    assert pose.physics_fit_.outputs == POSE  # the chain fitted to every output (identify_outputs)
    measured = output_columns(runs[2], POSE)
    predicted, physics = pose.predict(runs[2]), pose.predict_physics(runs[2])
    assert predicted.shape == physics.shape == (runs[2].n, 3)
    err = np.sqrt(np.mean((predicted - measured) ** 2, axis=0))
    alone = np.sqrt(np.mean((physics - measured) ** 2, axis=0))
    assert np.all(err < 0.8 * alone), (err, alone)
    window, rest = warmup_split(runs[2], 10)
    warm = pose.predict(rest, warmup=window)
    assert warm.shape == (rest.n, 3)
    assert np.all(np.sqrt(np.mean((warm - measured[10:]) ** 2, axis=0)) < 0.8 * alone)
    state, stepped = pose.initial_state(runs[2].u[0]), []
    for u in runs[2].u[:40]:
        state, y = pose.step(state, u)
        stepped.append(y)
    np.testing.assert_allclose(np.array(stepped), predicted[:40], rtol=1e-6, atol=1e-6)


def test_saved_loaded_and_exported_as_the_model_of_every_output(pose, runs, tmp_path):
    from hybrid.export import export_model

    path = pose.save(tmp_path / "pose.pt")
    assert json.loads(path.with_suffix(".json").read_text())["settings"]["outputs"] == list(POSE)
    again = HybridModel.load(path)
    assert again.outputs == POSE
    np.testing.assert_array_equal(again.predict(runs[2]), pose.predict(runs[2]))
    exported = export_model(again, warmup=10)
    assert exported.n_y == 3 and exported.meta["init_output"] == 0
    np.testing.assert_allclose(exported.simulate(runs[2].u), pose.predict(runs[2]), rtol=1e-6, atol=1e-6)
    window, rest = warmup_split(runs[2], 10)
    from_window = exported.simulate(rest.u, warmup=(window.u, output_columns(window, POSE).T))
    np.testing.assert_allclose(from_window, pose.predict(rest, warmup=window), rtol=1e-4, atol=1e-3)


def test_a_fitted_chain_is_taken_as_given_and_what_does_not_fit_is_refused(runs, tmp_path):
    training = TrainingSettings(epochs=1, progress=False)
    fit = identify_outputs("lag+linear", runs[:2], POSE)
    given = HybridModel(fit, FNNHIBNet(buffer=10), outputs=POSE, training=training).fit(runs[:2])
    assert given.physics_ is fit.series and given.predict(runs[2]).shape == (runs[2].n, 3)
    one = HybridModel(Series.from_spec("lag+linear", dt=runs[0].dt), FNNHIBNet(buffer=10), training=training)
    one.fit(runs[:1])
    assert one.predict(runs[2]).shape == (runs[2].n,)
    assert "outputs" not in json.loads(one.save(tmp_path / "one.pt").with_suffix(".json").read_text())["settings"]
    for kwargs, message in (({"physics": fit.series, "outputs": POSE[:2]}, "one output per name"),
                            ({"physics": "lag+linear", "outputs": ("Angle x", "Pos q")}, "no output column 'Pos q'"),
                            ({"physics": fit, "outputs": POSE, "direction": "inverse"}, "forward hybrid"),
                            ({"physics": fit, "outputs": POSE, "fine_tune": FineTuneSettings()}, "no fine-tuning")):
        with pytest.raises(DataError, match=message):
            HybridModel(residual=FNNHIBNet(buffer=10), training=training, **kwargs).fit(runs[:1])


def test_the_inverse_of_a_hybrid_pose_follows_the_output_named(pose, runs):
    """One tendon, three outputs: ``ModelInverse(hybrid, output=2)`` follows the tip's y (the others go where its
    path takes them) and recovers the command that made it."""
    from hybrid import ModelInverse

    plain = HybridModel(pose.physics_, FNNHIBNet(buffer=10), outputs=POSE,  # no domain weight: a cheaper export
                        training=TrainingSettings(epochs=40, progress=False, seed=0)).fit(runs[:2])
    inverse = ModelInverse(plain, output=2).fit(runs[:2])
    part = runs[2].segment(0, 150)  # the first cycle and a half
    wanted = output_columns(part, POSE)[:, 2]
    u = inverse.predict(wanted)
    followed = plain.predict(u)[:, 2]
    assert np.sqrt(np.mean((followed - wanted) ** 2)) < 0.02 * np.ptp(wanted)
    assert np.sqrt(np.mean((u - part.u) ** 2)) < 0.1 * np.ptp(part.u)
