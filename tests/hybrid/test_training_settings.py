"""Training settings are one frozen object (TrainingSettings, FineTuneSettings) that scikit-learn
sees field by field, the experiments' budgets are one table of them, and models saved with the
settings flat still load."""

from __future__ import annotations

import json
from dataclasses import FrozenInstanceError

import numpy as np
import pytest

sklearn_base = pytest.importorskip("sklearn.base", reason="scikit-learn is in the [test] extra")
torch = pytest.importorskip("torch", reason="the learned estimators need the [learning] extra")

from hybrid.experiments import BUDGETS, NetworkBudget  # noqa: E402
from hybrid.learning import LearnedModel, TrainingSettings  # noqa: E402
from hybrid.learning._checkpoint import write_blob  # noqa: E402
from hybrid.models import FineTuneSettings, HybridModel  # noqa: E402
from hybrid.networks import FNNHIBNet  # noqa: E402
from physics.data import DataError  # noqa: E402
from physics.virtual import CatheterTruth, DecayingSinusoid, VirtualCatheter  # noqa: E402

FAST = TrainingSettings(epochs=2, stride=4, progress=False, threads=1)


@pytest.fixture(scope="module")
def runs():
    cath = VirtualCatheter(effects=("backlash",), seed=0)
    return [cath.run(DecayingSinusoid(f, "mid")) for f in (0.3, 0.5)]


def _learned(training=FAST):
    return LearnedModel(FNNHIBNet(buffer=5, hidden=(8,)), training=training)


def test_get_params_shows_each_training_setting():
    params = HybridModel("linear", "fnn", training=FAST, fine_tune=FineTuneSettings(epochs=3)).get_params(deep=True)
    assert params["training"] is FAST
    assert {k: v for k, v in params.items() if k.startswith("training__")} == {
        f"training__{k}": v for k, v in FAST.get_params().items()}
    assert params["training__epochs"] == 2 and params["training__stride"] == 4 and params["fine_tune__epochs"] == 3
    assert "fine_tune__epochs" not in HybridModel().get_params(deep=True)  # None: no joint stage, no settings


def test_set_params_swaps_in_a_checked_copy_and_leaves_a_shared_one_alone():
    a, b = _learned(), _learned()  # one TrainingSettings, two models
    assert a.set_params(training__lr=1e-2, training__epochs=5) is a
    assert (a.training.lr, a.training.epochs, a.training.stride) == (1e-2, 5, 4)
    assert b.training is FAST and FAST.lr == 1e-3 and FAST.epochs == 2
    with pytest.raises(FrozenInstanceError):
        FAST.lr = 0.5  # type: ignore[misc]
    # changes are checked together: early stopping with the split it needs is fine in one call
    a.set_params(training__validation=0.2, training__patience=3)
    assert (a.training.validation, a.training.patience) == (0.2, 3)
    with pytest.raises(DataError, match="patience .* needs a validation split"):
        b.set_params(training__patience=3)
    with pytest.raises(DataError, match=r"The 'lr' training setting must be a number in \(0, 1\). Got 2"):
        b.set_params(training__lr=2)
    with pytest.raises(DataError, match="TrainingSettings has no setting 'speed'. Must be one of: epochs, batch_size"):
        b.set_params(training__speed=1)
    assert b.training is FAST
    with pytest.raises(DataError, match="'fine_tune' setting of HybridModel is None, which has no settings"):
        HybridModel().set_params(fine_tune__epochs=3)


def test_clone_copies_the_settings_and_refits_to_the_same_numbers(runs):
    est = HybridModel("linear", FNNHIBNet(buffer=5, hidden=(8,)), training=FAST).fit(runs[:1])
    twin = sklearn_base.clone(est)
    assert twin.training == FAST and twin.get_params()["training__epochs"] == 2
    np.testing.assert_allclose(twin.fit(runs[:1]).predict(runs[1]), est.predict(runs[1]), atol=1e-9)


def test_grid_search_over_a_training_setting_trains_with_each_value(runs):
    from sklearn.model_selection import GridSearchCV, PredefinedSplit

    grid = [1e-3, 5e-2]
    search = GridSearchCV(_learned(), {"training__lr": grid}, cv=PredefinedSplit([-1, 0]))
    search.fit(np.array(runs, dtype=object))  # X: the trajectories; fit and score take lists of them
    # each candidate's score is that of a model trained on the first run with its rate, scored on the second
    expected = [_learned(FAST.replace(lr=lr)).fit(runs[:1]).score(runs[1:]) for lr in grid]
    np.testing.assert_allclose(search.cv_results_["split0_test_score"], expected, rtol=0, atol=1e-12)
    assert expected[0] != expected[1]
    assert search.best_params_ == {"training__lr": grid[int(np.argmax(expected))]}
    assert search.best_estimator_.training.lr == search.best_params_["training__lr"]
    assert search.best_estimator_.training.stride == 4  # the other settings as given


def test_training_and_fine_tune_settings_are_checked_with_clear_errors(runs):
    for bad, match in ((dict(stride=0), r"'stride' training setting must be an integer >= 1. Got 0"),
                       (dict(threads=0), r"'threads' training setting must be None or an integer >= 1. Got 0"),
                       (dict(epochs=2.5), r"'epochs' training setting must be an integer >= 1. Got 2.5")):
        with pytest.raises(DataError, match=match):
            TrainingSettings(**bad)
    with pytest.raises(DataError, match=r"'segment_len' fine-tune setting must be an integer >= 1. Got 0"):
        FineTuneSettings(segment_len=0)
    with pytest.raises(DataError, match=r"'residual_penalty' fine-tune setting must be a number >= 0. Got -1"):
        FineTuneSettings(residual_penalty=-1)
    with pytest.raises(DataError, match=r"'training' parameter of LearnedModel must be a TrainingSettings"):
        LearnedModel(training={"epochs": 2}).fit(runs)
    with pytest.raises(DataError, match=r"'fine_tune' parameter of HybridModel must be None .* or a FineTuneSettings"):
        HybridModel("linear", "fnn", fine_tune=True, training=FAST).fit(runs)


def _rewrite(path, change):
    """Write the checkpoint at ``path`` again with its metadata changed by ``change`` (a new pair id)."""
    blob = torch.load(path, map_location="cpu", weights_only=True)
    keys = json.loads(path.with_suffix(".json").read_text())
    meta = {k: blob[k] for k in keys if k != "pair_id"}
    change(meta)
    write_blob(path, meta, {k: v for k, v in blob.items() if k not in keys})


def _flatten(settings: dict) -> None:
    settings.update(settings.pop("training"))


def test_a_learned_model_saved_with_flat_settings_loads(runs, tmp_path):
    model = _learned(FAST.replace(seed=3)).fit(runs[:1])
    path = model.save(tmp_path / "m.pt")
    assert json.loads(path.with_suffix(".json").read_text())["settings"]["training"]["seed"] == 3
    _rewrite(path, lambda meta: _flatten(meta["settings"]))
    assert "epochs" in json.loads(path.with_suffix(".json").read_text())["settings"]  # the old, flat form
    again = LearnedModel.load(path)
    assert again.training == FAST.replace(seed=3)
    np.testing.assert_array_equal(again.predict(runs[1]), model.predict(runs[1]))


def test_a_hybrid_saved_with_flat_settings_loads_with_its_fine_tuning(runs, tmp_path):
    tune = FineTuneSettings(epochs=1, physics_lr=2e-3, residual_penalty=0.2, segment_len=40)
    model = HybridModel("linear", FNNHIBNet(buffer=5, hidden=(8,)), training=FAST, fine_tune=tune).fit(runs[:1])
    path = model.save(tmp_path / "h.pt")
    again = HybridModel.load(path)
    assert (again.training, again.fine_tune) == (FAST, tune)

    def flat(meta):
        settings = meta["settings"]
        _flatten(settings)
        settings.update(fine_tune=True, fine_tune_epochs=1, physics_lr=2e-3, residual_penalty=0.2, segment_len=40)
        _flatten(meta["residual"]["settings"])

    _rewrite(path, flat)
    old = HybridModel.load(path)
    assert (old.training, old.fine_tune, old.residual_.training) == (FAST, tune, FAST)
    np.testing.assert_array_equal(old.predict(runs[1]), model.predict(runs[1]))


def test_one_budget_table_gives_each_experiment_its_settings():
    quick = BUDGETS["quick"]
    # hyst fit / hyst compare: 30 epochs, patience 6; the LSTM 20 epochs on every 6th window
    assert quick.networks.for_network("fnn") == TrainingSettings(epochs=30, stride=2, validation=0.1, patience=6,
                                                                 threads=1)
    assert quick.networks.for_network("lstm", seed=4) == TrainingSettings(epochs=20, stride=6, validation=0.1,
                                                                          patience=5, threads=1, seed=4)
    # hyst reproduce (Table I's six models): 40 epochs, patience 8; the LSTM every 4th window, patience 10
    assert quick.table.for_network("fnn-hib") == TrainingSettings(epochs=40, stride=2, validation=0.1, patience=8,
                                                                  threads=1)
    assert quick.table.for_network("lstm") == quick.table.common.replace(stride=4, patience=10)
    paper = BUDGETS["paper"]
    assert paper.networks is paper.table and paper.table.for_network("lstm") == TrainingSettings(
        epochs=500, stride=1, threads=1)
    assert set(BUDGETS) == {"quick", "paper", "tiny"}
    with pytest.raises(DataError, match="TrainingSettings has no setting 'epoch'"):
        NetworkBudget(TrainingSettings(), {"fnn": {"epoch": 3}}).for_network("fnn")


def test_the_catheter_truth_is_one_frozen_object():
    truth = CatheterTruth(boucwen_A=0.3, lag_time_constant_s=0.2)
    cath = VirtualCatheter("lag,hysteresis", input="command", truth=truth)
    params = cath.truth_model().param_dict()
    assert params["boucwen.A"] == 0.3 and params["lag.time_constant_s"] == 0.2
    assert params["boucwen.beta"] == CatheterTruth().boucwen_beta == 1.5
    meta = cath.run(DecayingSinusoid(0.5, cycles=1)).meta  # the run's meta names each parameter, as before
    assert meta["boucwen_A"] == 0.3 and meta["noise_std_deg"] == 0.15 and "truth" not in meta
    with pytest.raises(ValueError, match=r"The 'delay_s' of CatheterTruth must be >= 0 s. Got -1"):
        CatheterTruth(delay_s=-1)
    with pytest.raises(ValueError, match=r"The 'truth' of VirtualCatheter must be a CatheterTruth"):
        VirtualCatheter(truth={"boucwen_A": 0.3}).truth_model()


def test_the_device_is_a_training_setting_and_the_cpu_numbers_do_not_change(runs, tmp_path):
    """Issue 54 item 3: ``device`` names where the windows train; the model comes back to the CPU, so a
    CPU-only machine loads and exports it. On the CPU (``"cpu"``, or ``"auto"`` where torch sees no GPU)
    the weights are those of a training with no device named, bit for bit."""
    plain = _learned().fit(runs[:1])
    cpu = _learned(FAST.replace(device="cpu")).fit(runs[:1])
    np.testing.assert_array_equal(cpu.predict(runs[1]), plain.predict(runs[1]))
    if not torch.cuda.is_available():
        auto = _learned(FAST.replace(device="auto")).fit(runs[:1])
        np.testing.assert_array_equal(auto.predict(runs[1]), plain.predict(runs[1]))
        with pytest.raises(DataError, match=r"device 'cuda': torch sees 0 CUDA device\(s\).*Give --device cpu, or auto"):
            _learned(FAST.replace(device="cuda")).fit(runs[:1])
    else:  # a GPU: the same training there, back on the CPU, equal to float rounding
        gpu = _learned(FAST.replace(device="cuda")).fit(runs[:1])
        assert all(p.device.type == "cpu" for p in gpu.module_.parameters())
        np.testing.assert_allclose(gpu.predict(runs[1]), plain.predict(runs[1]), atol=1e-3)
    for bad in ("gpu", "cuda:x", 0, None):
        with pytest.raises(DataError, match="The 'device' setting must be one of cpu, auto, cuda or 'cuda:N'"):
            FAST.replace(device=bad)
    from identification import IdentificationError
    from identification.discovery import Workers

    assert Workers(n_jobs=2, device="auto").to_dict()["device"] == "auto"  # a fit's networks train there
    with pytest.raises(IdentificationError, match="The 'device' setting must be one of"):
        Workers(device="gpu")
    saved = _learned(FAST.replace(device="auto")).fit(runs[:1]).save(tmp_path / "m.pt")  # the setting is kept
    assert LearnedModel.load(saved).training.device == "auto"
    assert TrainingSettings.from_dict({k: v for k, v in FAST.to_dict().items() if k != "device"}).device == "cpu"


def test_every_command_that_trains_takes_device_and_refuses_a_bad_one(capsys):
    from hybrid.cli import main

    for command in ("fit x.csv --out m", "train x.csv --out m.pt", "compare --out c", "reproduce --out r",
                    "ablate cfg.toml --out a"):
        assert main([*command.split(), "--device", "gpu"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "argument --device: The 'device' setting must be one of" in err[0], err
