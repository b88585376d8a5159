"""HybridModel: physics plus a residual network, forward and inverse."""

import copy

import numpy as np
import pytest

from hybrid import FineTuneSettings, HybridModel, ModelInverse, TrainingSettings
from hybrid.export import export_model
from physics.data import DataError, NotFittedError, rmse
from hybrid.networks import FNNHIBNet, LSTMNet
from physics.virtual import VirtualCatheter, paper_protocol

NOISE = 0.15
SMALL = dict(training=TrainingSettings(epochs=4, progress=False, threads=1, seed=0))


@pytest.fixture(scope="module")
def cath():
    return VirtualCatheter(seed=0, noise_std_deg=NOISE)


@pytest.fixture(scope="module")
def split(cath):
    return paper_protocol(cath, frequencies=(0.4, 0.5), tests=(0.45,), baselines=("mid", "end"))


@pytest.fixture(scope="module")
def truth(cath):
    return cath.truth_model()


@pytest.fixture(scope="module")
def forward(split, truth):
    return HybridModel(truth, FNNHIBNet(buffer=10, hidden=(16, 16)), **SMALL).fit(split.train)


def test_residual_stays_near_zero_when_the_physics_explains_the_data(forward, split):
    for traj in split.test:
        physics = forward.predict_physics(traj)
        hybrid = forward.predict(traj)
        # the residual learns noise only: it moves the prediction by far less than the noise
        assert rmse(physics, hybrid) < 0.5 * NOISE
        assert rmse(traj.extra["y_true"], hybrid) < 0.5 * NOISE


def test_fine_tuning_moves_a_perturbed_parameter_towards_the_truth(truth):
    cath = VirtualCatheter(seed=1, noise_std_deg=0.05)
    data = paper_protocol(cath, frequencies=(0.3, 0.5), tests=(0.45,), baselines=("mid",))
    wrong = copy.deepcopy(truth).set_params(**{"linear.gain": 10.0})
    model = HybridModel(wrong, FNNHIBNet(buffer=10, hidden=(16, 16)),
                        fine_tune=FineTuneSettings(epochs=3, segment_len=50, physics_lr=1e-2),
                        training=TrainingSettings(batch_size=4, epochs=2, progress=False, threads=1))
    model.fit(data.train)
    gain = model.physics_.param_dict()["linear.gain"]
    assert abs(gain - 11.4) < 0.8 * abs(10.0 - 11.4), gain
    assert len(model.fine_tune_loss_) == 3


@pytest.mark.parametrize("direction,net", [("forward", LSTMNet(hidden=8, layers=1, seq_len=12)),
                                           ("inverse", FNNHIBNet(buffer=8, hidden=(8,)))])
def test_sequential_steps_equal_the_batched_prediction(split, truth, direction, net):
    model = HybridModel(truth, net, direction, physics_states=True,
                        training=TrainingSettings(epochs=1, progress=False, threads=1))
    model.fit(split.train)
    traj = split.test[0]
    path = traj.u if direction == "forward" else traj.y
    state = model.initial_state(path[0])
    steps = []
    for v in path[:120]:
        state, out = model.step(state, v)
        steps.append(out)
    np.testing.assert_allclose(steps, model.predict(traj)[:120], atol=1e-5)


def test_save_and_load_give_identical_predictions(forward, split, tmp_path):
    path = forward.save(tmp_path / "hybrid.pt")
    assert path.with_suffix(".json").is_file()
    again = HybridModel.load(path)
    np.testing.assert_array_equal(again.predict(split.test[0]), forward.predict(split.test[0]))
    assert again.physics_.param_dict() == forward.physics_.param_dict()


def test_hybrid_inverse_of_hybrid_forward_returns_the_input_on_held_out_paths(forward, split, truth):
    inverse = HybridModel(truth, FNNHIBNet(buffer=10, hidden=(16, 16)), "inverse", **SMALL).fit(split.train)
    for traj in split.test:  # held out: 0.45 Hz, never trained on
        u_back = inverse.predict(forward.predict(traj.u))
        # measured: 0.03-0.04 mm (the backlash's dead band makes the inverse ambiguous by up to 0.1 mm)
        assert rmse(traj.u, u_back) < 0.08


def test_model_inverse_of_the_exported_hybrid_returns_the_input(forward, split):
    exported = export_model(forward)
    traj = split.test[0]
    np.testing.assert_allclose(exported.simulate(traj.u), forward.predict(traj), atol=1e-4)
    inverse = ModelInverse(forward, window=15, commit=10).fit()
    wanted = forward.predict(traj.u)[:150]
    u = inverse.predict(wanted)
    assert rmse(forward.predict(u), wanted) < 0.05  # follows the wanted path (deg)
    assert rmse(traj.u[:150], u) < 0.08


def test_model_inverse_ends_a_stalled_window_early_with_the_same_tracking(forward, split, monkeypatch):
    """Through a backlash the Gauss-Newton steps can cycle between two points a hair apart up to the
    iteration limit; a window whose best cost has stopped dropping ends there instead."""
    from hybrid.control import _inverse

    wanted = forward.predict(split.test[0].u)[:200]

    def run():
        inverse = ModelInverse(forward, window=15, commit=10).fit()
        solve, iterations = inverse._solver, []

        def counted(**kwargs):
            out = solve(**kwargs)
            iterations.append(solve.stats()["iter_count"])
            return out

        inverse._solver = counted
        u = inverse.predict(wanted)
        return rmse(forward.predict(u), wanted), sum(iterations)

    stalled, n_stalled = run()
    monkeypatch.setattr(_inverse, "STALL_WINDOW", 10**6)  # never stalls: the iteration limit alone
    full, n_full = run()
    print(f"tracking {stalled:.4f} deg in {n_stalled} iterations; without the stall stop {full:.4f} in {n_full}")
    assert n_stalled < 0.7 * n_full
    assert stalled < 1.05 * full + 1e-3


def test_model_inverse_keeps_its_first_guess_where_a_solve_returns_no_finite_cost(truth, split):
    """A diverged solve can end with finite but huge inputs and a NaN cost (NaN > cost is False):
    such a window keeps its first guess, the physics inverse, instead of the diverged inputs."""
    inverse = ModelInverse(truth, window=15, commit=10).fit()
    inverse._solver = lambda **kwargs: {"x": np.full(15, 1e15), "f": np.nan}
    wanted = truth.simulate(split.test[0].u[:60])
    np.testing.assert_allclose(inverse.predict(wanted), truth.inverse(wanted), rtol=0, atol=1e-12)


def test_clear_errors(split, truth):
    with pytest.raises(DataError, match="Must be one of"):
        HybridModel(truth, "gru").fit(split.train)
    with pytest.raises(NotFittedError, match="not fitted"):
        HybridModel(truth, "fnn").predict(split.test[0])
    with pytest.raises(DataError, match="fine_tune"):
        HybridModel(truth, "fnn", "inverse", fine_tune=FineTuneSettings()).fit(split.train)
    with pytest.raises(DataError, match="direction"):
        HybridModel(truth, "fnn", "sideways").fit(split.train)


def test_a_physics_spec_that_does_not_fit_is_listed_and_the_next_one_is_used(split):
    model = HybridModel(["poly", "backlash+linear"], FNNHIBNet(buffer=5, hidden=(8,)),
                        training=TrainingSettings(epochs=1, progress=False, threads=1, seed=0)).fit(split.train)
    assert model.physics_.spec == "backlash+linear" and model.physics_fit_.success
    assert list(model.physics_failed_) == ["poly"] and "no output map" in model.physics_failed_["poly"]
    # the physics in use is the fitted backlash+linear: the hybrid predicts near it
    assert rmse(split.test[0].y, model.predict_physics(split.test[0])) < 5.0


@pytest.mark.parametrize("u_unit, y_unit", [(1e3, 1e-6), (1e-3, 1e2)])
def test_model_inverse_gives_the_same_input_path_in_any_units(u_unit, y_unit):
    """The same backlash catheter in volts and metres (or any other units): the input path found is
    the same one, in the new units. Before the cost and the input were scaled, its input-change
    weight swamped an output in metres and the input did not move (61 V RMSE on a 0-150 V piezo)."""
    from physics import Backlash, LinearMap, Series

    def model(su, sy):  # in the data's units, as a fit leaves it (the play's smoothing too: for_scale)
        m = Series(Backlash(smoothing=0.01 * su), LinearMap(), dt=0.04)
        m.params = [0.6 * su, 0.0, 10.0 * sy / su, 30.0 * sy]  # width, start, gain, offset
        return m

    u = 3.0 - 2.5 * np.cos(np.linspace(0, 4 * np.pi, 200))
    wanted = model(1.0, 1.0).simulate(u)
    reference = ModelInverse(model(1.0, 1.0), window=20, commit=10, u_bounds=(-1.0, 7.0)).fit().predict(wanted)
    found = ModelInverse(model(u_unit, y_unit), window=20, commit=10,
                         u_bounds=(-1.0 * u_unit, 7.0 * u_unit)).fit().predict(wanted * y_unit) / u_unit
    assert rmse(reference, u) < 0.06 and rmse(found, u) < 0.06  # mm in the reference units
    np.testing.assert_allclose(found, reference, atol=1e-3)


def test_model_inverse_pulls_a_hybrid_not_a_physics_model_towards_the_physics_inverse(split, truth, forward):
    test = split.test[0]
    y = test.y[:150]
    plain = [ModelInverse(truth, window=20, commit=10, w_physics=w).fit().predict(y) for w in (0.0, 100.0)]
    np.testing.assert_array_equal(plain[0], plain[1])  # a physics model is its own reference
    physics_inverse = truth.inverse(y)
    free, held = (ModelInverse(forward, window=20, commit=10, w_physics=w).fit().predict(y) for w in (0.0, 1e6))
    assert rmse(held, physics_inverse) < 0.1 * rmse(free, physics_inverse)  # the weight is wired in
    assert rmse(free, test.u[:150]) < 0.5  # mm: without it, this hybrid's inverse is fine too
    with pytest.raises(DataError, match="w_physics"):
        ModelInverse(truth, w_physics=-1.0).fit()


def test_a_physics_whose_output_never_moves_leaves_the_network_to_learn_alone(split):
    """Where no block explains the data (the Bouc-Wen benchmark's resonance under a static map), the
    fitted physics can be a constant: its output feature carries nothing, and the hybrid is then the
    network on the input alone, not an error that ends a comparison."""
    from physics import Series

    flat = Series.from_spec("linear", dt=split.train[0].dt).set_params(**{"linear.gain": 0.0, "linear.offset": 40.0})
    model = HybridModel(flat, FNNHIBNet(buffer=5, hidden=(16,)), **SMALL).fit(split.train)
    assert np.ptp(model.predict_physics(split.train[0])) == 0.0
    scaler = model.residual_.input_scaler_
    assert scaler.max_[1] > scaler.min_[1] == 40.0
    with pytest.raises(DataError, match="column 0 of x is constant"):  # the input itself must still vary
        still = [t.__class__(t.time, np.full(t.n, 3.0), t.y) for t in split.train]
        HybridModel(flat, FNNHIBNet(buffer=5, hidden=(16,)), **SMALL).fit(still)
    # the residual carries the whole signal: far better than the constant physics
    test = split.test[0]
    assert rmse(test.y, model.predict(test)) < 0.5 * rmse(test.y, model.predict_physics(test))
