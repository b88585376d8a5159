"""A model's state from measured samples: the window fit recovers a start the rest rule cannot, in any
units; every model kind takes a window the same way; the export's ``init`` equals ``predict``."""

from dataclasses import replace

import numpy as np
import pytest

from physics import Series
from physics.data import DataError, Trajectory, as_warmup, warmup_split
from physics._errors import PhysicsError

DT = 0.04
T = np.arange(0, 16, DT)
U = 3 - 3 * np.cos(2 * np.pi * 0.2 * T)


def _model(s_u=1.0, s_y=1.0):
    """lag + play + Bouc-Wen + line for an input s_u times and an output s_y times the base's (about the
    base model in other units; the blocks' absolute smoothing makes it not exactly that)."""
    m = Series.from_spec("lag+backlash+boucwen+linear", dt=DT)
    base = m.param_dict()
    m.set_params(**{"backlash.width": base["backlash.width"] * s_u, "linear.gain": base["linear.gain"] * s_y / s_u,
                    "linear.offset": base["linear.offset"] * s_y, "boucwen.A": base["boucwen.A"],
                    "boucwen.beta": base["boucwen.beta"] / s_u, "boucwen.gamma": base["boucwen.gamma"] / s_u})
    m.input_range = (0.0, 6.0 * s_u)
    return m


def _away_from_rest(m, s_u=1.0):
    """The state at U[0] after a history that leaves the play and the hysteresis off their rest."""
    pre = s_u * np.concatenate([np.linspace(0, 5, 50), np.linspace(5, U[0], 50)])
    _, xs = m.simulate(np.concatenate([pre, s_u * U]), return_states=True)
    return xs[pre.size]


@pytest.mark.parametrize("s_u,s_y", [(1.0, 1.0), (1e-3, 1e-4), (1e3, 1e5)])
def test_window_fit_recovers_a_start_the_rest_rule_misses_in_any_units(s_u, s_y):
    m = _model(s_u, s_y)
    u = s_u * U
    truth = m.simulate(u, x0=_away_from_rest(m, s_u))
    k = 10
    from_rest = m.simulate(u[k:])
    warm = m.simulate(u[k:], warmup=(u[:k], truth[:k]))
    err_rest = np.sqrt(np.mean((from_rest - truth[k:]) ** 2)) / s_y
    err_warm = np.sqrt(np.mean((warm - truth[k:]) ** 2)) / s_y
    assert err_rest > 0.3  # deg in the base units: the rest rule is off (measured 0.36-4.4)
    assert err_warm < 0.15 * err_rest  # measured 0.002-0.12 of it: ten samples at a slow cosine's bottom


def test_a_window_that_shows_nothing_new_keeps_the_rest_state():
    m = _model()
    y = m.simulate(U)
    state = m.estimate_state(U[:10], y[:10])
    np.testing.assert_allclose(state.x0, m.steady_state(U[0]), atol=1e-6)
    np.testing.assert_allclose(m.simulate(U[10:], warmup=(U[:10], y[:10])), y[10:], atol=1e-6)
    np.testing.assert_array_equal(m.simulate(U[10:], warmup=Trajectory(T[:10], U[:10], y[:10])),
                                  m.simulate(U[10:], warmup=(U[:10], y[:10])))  # a Trajectory is the same window


def test_output_offset_is_estimated_when_asked():
    """Where no state can hold it (a lag's start decays within the window), a shifted output is an offset."""
    m = Series.from_spec("lag+linear", dt=DT)
    m.input_range = (0.0, 6.0)
    y = m.simulate(U) + 2.5
    assert m.estimate_state(U[:10], y[:10], offset=True).offset == pytest.approx(2.5, abs=0.05)
    assert m.estimate_state(U[:10], y[:10]).offset == 0.0


def test_inverse_from_a_window_starts_where_the_play_is():
    m = Series.from_spec("backlash+linear", dt=DT)
    m.input_range = (0.0, 6.0)
    truth = m.simulate(U, x0=_away_from_rest(m))  # the play 0.155 mm off its rest
    k = 10
    rest = m.inverse(truth[k:])
    warm = m.inverse(truth[k:], warmup=(U[:k], truth[:k]))
    assert abs(warm[0] - U[k]) < 0.1 * abs(rest[0] - U[k])  # measured 0.005 against 0.155 mm


def test_bad_windows_are_refused_with_what_to_fix():
    m = _model()
    with pytest.raises(PhysicsError, match="same samples"):
        m.simulate(U[10:], warmup=(U[:10], U[:9]))
    with pytest.raises(PhysicsError, match="non-finite"):
        m.simulate(U[10:], warmup=(U[:10], np.r_[U[:9], np.nan]))
    with pytest.raises(PhysicsError, match="not both"):
        m.simulate(U[10:], x0=m.steady_state(0.0), warmup=(U[:10], U[:10]))
    traj = Trajectory(T, U, U)
    with pytest.raises(DataError, match="leaves nothing to predict"):
        warmup_split(traj, traj.n)
    with pytest.raises(DataError, match="integer number of samples >= 0"):
        warmup_split(traj, -1)
    with pytest.raises(DataError, match="same number"):
        as_warmup((U[:10], U[:8]))
    with pytest.raises(DataError, match="non-finite"):
        as_warmup((np.r_[U[:9], np.inf], U[:10]))


def test_segment_and_split_keep_every_column():
    traj = Trajectory(T, U, 2 * U, extra={"current": U ** 2}, source="run.csv")
    window, rest = warmup_split(traj, 10)
    assert (window.n, rest.n) == (10, traj.n - 10)
    np.testing.assert_array_equal(rest.extra["current"], U[10:] ** 2)
    assert rest.time[0] == T[10] and rest.source == "run.csv"


def test_init_is_exported_and_compiled_beside_step(tmp_path):
    from hybrid.export import export_model
    from hybrid.export._codegen import has_compiler, load_compiled

    m = _model()
    truth = m.simulate(U, x0=_away_from_rest(m))
    exported = export_model(m, warmup=10)
    x = exported.warm_state(U[:10], truth[:10])
    np.testing.assert_allclose(x, m.estimate_state(U[:10], truth[:10]).x, rtol=0, atol=1e-12)
    np.testing.assert_allclose(exported.simulate(U[10:], warmup=(U[:10], truth[:10])),
                               m.simulate(U[10:], warmup=(U[:10], truth[:10])), rtol=0, atol=1e-9)
    if not has_compiler():
        pytest.skip("no gcc: the C library is not built")
    init = load_compiled(exported.codegen(tmp_path), "init")
    np.testing.assert_allclose(np.asarray(init(U[None, :10], truth[None, :10])).ravel(), x, rtol=0, atol=1e-9)


# ---------------------------------------------------------------------- every model kind
torch = pytest.importorskip("torch")


@pytest.fixture(scope="module")
def fitted():
    from hybrid import HybridModel, NeuralODEHybrid, TrainingSettings
    from hybrid.learning._learned import LearnedModel
    from hybrid.networks import make_network
    from physics.virtual import paper_protocol

    split = paper_protocol(frequencies=(0.3, 0.5), tests=(0.45,), baselines=("mid",))
    fast = dict(training=TrainingSettings(epochs=1, progress=False, stride=4))
    return split, {
        "hybrid-fnn-hib": HybridModel("lag+backlash+linear", "fnn-hib", **fast).fit(split.train),
        "hybrid-lstm": HybridModel("lag+backlash+linear", "lstm", **fast).fit(split.train),
        "neural-ode": NeuralODEHybrid("backlash+boucwen+linear", hidden=8, epochs=1, progress=False).fit(split.train),
        "fnn-hib": LearnedModel(make_network("fnn-hib"), **fast).fit(split.train),
    }


@pytest.mark.parametrize("name", ["hybrid-fnn-hib", "hybrid-lstm", "neural-ode", "fnn-hib"])
def test_every_model_takes_a_window_and_its_export_init_equals_predict(fitted, name, tmp_path):
    from hybrid.export import ExportedModel, export_model

    split, models = fitted
    model = models[name]
    window, rest = warmup_split(split.test[0], 10)
    warm = model.predict(rest, warmup=window)
    assert warm.shape == (rest.n,) and np.all(np.isfinite(warm))
    np.testing.assert_array_equal(model.predict(rest.u, warmup=(window.u, window.y)), warm)  # both forms
    exported = export_model(model, warmup=10)
    np.testing.assert_allclose(exported.simulate(rest.u, warmup=(window.u, window.y)), warm, rtol=0, atol=1e-5)
    loaded = ExportedModel.load(exported.save(tmp_path / "step.casadi"))
    assert loaded.meta["warmup"] == 10
    np.testing.assert_allclose(loaded.warm_state(window.u, window.y), exported.warm_state(window.u, window.y),
                               rtol=0, atol=1e-12)


def test_a_network_alone_runs_through_the_window(fitted):
    split, models = fitted
    model, test = models["fnn-hib"], split.test[0]
    window, rest = warmup_split(test, 10)
    np.testing.assert_allclose(model.predict(rest, warmup=window), model.predict(test)[10:], rtol=0, atol=1e-12)


def test_the_hybrid_fits_its_physics_to_the_window(fitted):
    """A window at rest whose angle sits above the rest output: the play's state moves up its band."""
    split, models = fitted
    model, test = models["hybrid-lstm"], split.test[0]
    window, rest = warmup_split(test, 10)
    still = replace(window, u=np.full(10, rest.u[0]), y=np.full(10, model.predict_physics(rest)[0]))
    higher = replace(still, y=still.y + 1.0)  # a catheter resting 1 deg higher, inside its play
    moved = model.predict_physics(rest, warmup=higher)[0] - model.predict_physics(rest, warmup=still)[0]
    assert 0.5 < moved < 1.5


def test_score_model_scores_every_model_after_the_same_window(fitted):
    from hybrid.experiments._scoring import score_model

    split, models = fitted
    scores = score_model(models["hybrid-fnn-hib"], split.test, "h", warmup=10)
    assert [s.n for s in scores[:-1]] == [t.n - 10 for t in split.test]
    assert scores[-1].n == sum(t.n - 10 for t in split.test)


def test_selection_scores_held_out_runs_after_the_same_window():
    """Runs that start off rest: from rest the true structure looks wrong; after the window it fits."""
    from identification import SelectionSettings, select_physics

    truth = Series.from_spec("backlash+linear", dt=DT)
    truth.set_params(**{"backlash.width": 1.0})
    runs = []
    for k, f in enumerate((0.15, 0.2, 0.25)):
        u = 3 - 3 * np.cos(2 * np.pi * f * T)
        x0 = truth.steady_state(u[0]) + 0.45  # the play at the top of its band
        runs.append(Trajectory(T, u, truth.simulate(u, x0=x0), source=f"r{k}"))
    cold = select_physics(runs, candidates=["backlash+linear"], settings=SelectionSettings(max_samples=None))
    warm = select_physics(runs, candidates=["backlash+linear"], settings=SelectionSettings(max_samples=None), warmup=10)
    # measured 0.33 against 0.85: the folds' fits themselves still start from rest (identify's rule)
    assert warm.cv_rmse["backlash+linear"] < 0.5 * cold.cv_rmse["backlash+linear"]
