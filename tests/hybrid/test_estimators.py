"""Every estimator keeps scikit-learn's contract: get_params(deep)/set_params read the
``__init__`` signature, ``sklearn.base.clone`` gives an unfitted equal copy, ``score`` is R²
(higher is better) and works with sklearn's model-selection tools."""

from __future__ import annotations

import inspect

import numpy as np
import pytest

sklearn_base = pytest.importorskip("sklearn.base", reason="scikit-learn is in the [test] extra")
pytest.importorskip("torch", reason="the learned estimators need the [learning] extra")

from hybrid.control import rest_output  # noqa: E402,F401  (control imports cleanly)
from hybrid.control._inverse import ModelInverse  # noqa: E402
from hybrid.learning import LearnedModel, TrainingSettings  # noqa: E402
from hybrid.models import HybridModel, NeuralODEHybrid  # noqa: E402
from hybrid.networks import FNNHIBNet, LSTMNet  # noqa: E402
from identification import PhysicsEstimator  # noqa: E402
from physics import Series  # noqa: E402
from physics.data import DataError  # noqa: E402
from physics.virtual import DecayingSinusoid, VirtualCatheter  # noqa: E402

FAST = TrainingSettings(epochs=2, stride=4, progress=False, threads=1)
ESTIMATORS = {
    "learned": lambda: LearnedModel(FNNHIBNet(buffer=5, hidden=(8,)), training=FAST),
    "hybrid": lambda: HybridModel("linear", FNNHIBNet(buffer=5, hidden=(8,)), training=FAST),
    "neural-ode": lambda: NeuralODEHybrid("lag+linear", hidden=4, epochs=1, segment_len=20, progress=False,
                                          threads=1),
    "physics": lambda: PhysicsEstimator("lag+linear"),
    "model-inverse": lambda: ModelInverse(Series.from_spec("linear"), window=5, commit=5),
}


@pytest.fixture(scope="module")
def runs():
    cath = VirtualCatheter(effects=("backlash",), seed=0)
    return [cath.run(DecayingSinusoid(f, "mid")) for f in (0.3, 0.5)]


@pytest.mark.parametrize("name", ESTIMATORS)
def test_get_params_reads_the_signature_and_clone_copies_it(name):
    est = ESTIMATORS[name]()
    params = est.get_params(deep=False)
    assert sorted(params) == sorted(list(inspect.signature(type(est).__init__).parameters)[1:])
    twin = sklearn_base.clone(est)
    assert type(twin) is type(est) and twin is not est
    for key, value in params.items():
        other = twin.get_params(deep=False)[key]
        assert other == value or (hasattr(value, "spec") and other.spec == value.spec), key
    assert repr(twin) == repr(est)


@pytest.mark.parametrize("name", ESTIMATORS)
def test_set_params_changes_a_setting_and_refuses_unknown_ones(name):
    est = ESTIMATORS[name]()
    key = sorted(est.get_params(deep=False))[0]
    value = est.get_params(deep=False)[key]
    assert est.set_params(**{key: value}) is est
    with pytest.raises(DataError, match=rf"{type(est).__name__} has no setting 'speed'"):
        est.set_params(speed=1)


def test_set_params_reaches_into_a_nested_estimator():
    inner = PhysicsEstimator("linear")
    outer = ModelInverse(inner)
    assert outer.get_params(deep=True)["model__model"] == "linear"
    outer.set_params(model__model="lag+linear")
    assert inner.model == "lag+linear"


@pytest.mark.parametrize("name", ["learned", "hybrid", "physics"])
def test_clone_of_a_fitted_estimator_is_unfitted_and_refits_to_the_same_numbers(name, runs):
    est = ESTIMATORS[name]().fit(runs[:1])
    twin = sklearn_base.clone(est)
    fitted = [k for k in vars(est) if k.endswith("_") and not k.startswith("_")]
    assert fitted and not any(hasattr(twin, k) for k in fitted)
    np.testing.assert_allclose(twin.fit(runs[:1]).predict(runs[1]), est.predict(runs[1]), atol=1e-9)


def test_score_is_r2_higher_is_better(runs):
    est = PhysicsEstimator("backlash+linear").fit(runs[:1])
    good, bad = est.score(runs[1:]), PhysicsEstimator("linear").fit(runs[:1]).score(runs[1:])
    y, yhat = runs[1].y, est.predict(runs[1])
    assert good == pytest.approx(1 - np.sum((y - yhat) ** 2) / np.sum((y - y.mean()) ** 2), rel=1e-12)
    assert 0.99 < good <= 1 and bad < good


def test_an_inverse_estimator_is_scored_on_the_input(runs):
    est = LearnedModel(FNNHIBNet(buffer=5, hidden=(8,)), "inverse",
                       training=TrainingSettings(epochs=3, stride=2, progress=False, threads=1)).fit(runs[:1])
    u, uhat = runs[1].u, est.predict(runs[1])  # an inverse model reads the trajectory's output
    assert est.score(runs[1]) == pytest.approx(1 - np.sum((u - uhat) ** 2) / np.sum((u - u.mean()) ** 2))


def test_grid_search_runs_over_physics_specs(runs):
    from sklearn.model_selection import GridSearchCV, PredefinedSplit

    search = GridSearchCV(PhysicsEstimator(), {"model": ["linear", "backlash+linear"]},
                          cv=PredefinedSplit([-1, 0]), refit=False)
    search.fit(np.array(runs, dtype=object))  # X: the trajectories; fit and score take lists of them
    assert search.best_params_ == {"model": "backlash+linear"}


def test_physics_estimator_reads_the_rate_from_the_data():
    from physics.data import Trajectory

    dt = 1e-3  # 1 kHz: nothing assumes the seed paper's 25 Hz
    truth = Series.from_spec("lag+linear", dt=dt).set_params(**{"lag.time_constant_s": 0.01, "linear.gain": 3.0})
    t = np.arange(2000) * dt
    u = np.sin(2 * np.pi * 5 * t)
    est = PhysicsEstimator("lag+linear").fit([Trajectory(t, u, truth.simulate(u))])
    assert est.model_.dt == pytest.approx(dt)
    assert est.params_["lag.time_constant_s"] == pytest.approx(0.01, rel=1e-4)
    with pytest.raises(Exception, match="no time stamps"):
        PhysicsEstimator("linear").fit([type("Run", (), {"u": u, "y": u})()])
