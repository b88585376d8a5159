"""Several input columns: the command drives the physics, the residual also reads measured inputs
(e.g. the motor current), and export and MPC take them as measured disturbances."""

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from hybrid import HybridModel, LearnedModel, TrainingSettings  # noqa: E402
from hybrid.cli import main  # noqa: E402
from hybrid.control import TrackingMPC, reference_signal, rest_output, run_closed_loop  # noqa: E402
from hybrid.export import ExportError, ExportedModel, export_model  # noqa: E402
from hybrid.networks import FNNHIBNet, LSTMNet  # noqa: E402
from physics.data import Trajectory, rmse  # noqa: E402
from physics.virtual import VirtualCatheter, paper_protocol  # noqa: E402

FAST = TrainingSettings(progress=False, threads=1, seed=0)


def _with_current(t):
    """A run whose output also depends on a measured 'current' that the command alone does not give."""
    current = 0.05 * t.u + 0.6 * np.sin(0.9 * t.time + 1.0)  # mostly independent of the command
    return Trajectory(t.time, t.u, t.y + 1.5 * np.tanh(current), source=t.source, extra={"current": current})


@pytest.fixture(scope="module")
def runs():
    split = paper_protocol(VirtualCatheter(seed=0, noise_std_deg=0.05), frequencies=(0.3, 0.5), tests=(0.45,),
                           baselines=("zero", "mid", "end"))
    return [_with_current(t) for t in split.train], _with_current(split.test[1])


@pytest.mark.parametrize("net", [FNNHIBNet(buffer=6, hidden=(8,)), LSTMNet(hidden=6, seq_len=8, mode="carried")],
                         ids=["fnn-hib", "lstm"])
def test_hybrid_with_a_measured_input_exports_and_steps_as_it_predicts(runs, net, tmp_path):
    train, test = runs
    model = HybridModel("lag+boucwen+linear", net, features=("u", "physics", "current"),
                        training=FAST.replace(epochs=1)).fit(train)
    model.residual_.module_.double()
    assert model.extra_inputs_ == ("current",)
    U = np.column_stack([test.u, test.extra["current"]])  # [command, measured] per sample
    expected = model.predict(test)
    np.testing.assert_array_equal(model.predict(U), expected)
    exported = export_model(model)
    assert exported.n_u == 2 and exported.meta["inputs"] == ["u", "current"]
    np.testing.assert_allclose(exported.simulate(U), expected, rtol=0, atol=1e-9)
    back = ExportedModel.load(exported.save(tmp_path / "h.casadi"))
    np.testing.assert_allclose(back.simulate(U[:50]), expected[:50], rtol=0, atol=1e-9)
    state, steps = model.initial_state(U[0]), []
    for row in U[:30]:
        state, y = model.step(state, row)
        steps.append(y)
    np.testing.assert_allclose(steps, expected[:30], rtol=0, atol=1e-9)
    with pytest.raises(Exception, match=r"\[u, current\]"):
        model.step(state, 1.0)


def test_the_measured_input_is_what_closes_the_gap(runs):
    """The output carries 1.5 tanh(current): the residual that reads the current explains it."""
    train, test = runs
    errors = {}
    for features in (("u", "physics"), ("u", "physics", "current")):
        model = HybridModel("lag+boucwen+linear", FNNHIBNet(buffer=4, hidden=(32, 32)), features=features,
                            training=FAST.replace(epochs=40)).fit(train)
        errors[features[-1]] = rmse(test.y, model.predict(test))
    # measured: without the current 0.57 deg, with it 0.09 deg
    assert errors["current"] < 0.3 * errors["physics"], errors


def test_learned_model_with_a_measured_input_exports(runs):
    train, test = runs
    model = LearnedModel(FNNHIBNet(buffer=6, hidden=(8,)), features=("current",),
                         training=FAST.replace(epochs=1)).fit(train)
    model.module_.double()
    exported = export_model(model)
    U = np.column_stack([test.u, test.extra["current"]])
    assert exported.meta["inputs"] == ["u", "current"]
    np.testing.assert_allclose(exported.simulate(U), model.predict(test), rtol=0, atol=1e-9)


def test_mpc_takes_measured_inputs_as_disturbances(runs):
    train, _ = runs
    model = HybridModel("lag+boucwen+linear", FNNHIBNet(buffer=4, hidden=(8,)), features=("u", "physics", "current"),
                        training=FAST.replace(epochs=2)).fit(train)
    exported = export_model(model)
    ref = reference_signal("sine", rest_output(exported, [1.0, 0.1]), rest_output(exported, [4.5, 0.1]),
                           duration_s=5.0)
    mpc = TrackingMPC(exported, u_bounds=(0.0, 6.0), horizon=10)
    assert mpc.solver_name == "sqp" and mpc.n_d == 1
    result = run_closed_loop(mpc, exported, ref, noise_std_deg=0.0, measured=np.full((ref.size, 1), 0.1))
    assert result.rmse_deg < 0.1, result.rmse_deg  # the plant is the model: it tracks
    with pytest.raises(ExportError, match="measured input"):
        mpc.solve(exported.x0([1.0, 0.1]), ref[:10], u_prev=1.0)
    with pytest.raises(ExportError, match="adjoint SQP steps a model with one input"):
        TrackingMPC(exported, u_bounds=(0.0, 6.0), horizon=10, solver="adjoint-sqp")


def test_cli_reads_several_input_columns(runs, tmp_path, capsys):
    train, test = runs
    paths = [t.to_csv(tmp_path / f"r{i}.csv") for i, t in enumerate([*train[:2], test])]
    model = tmp_path / "m.pt"
    cols = ["--input", "u,current"]
    assert main(["train", str(paths[0]), str(paths[1]), "--model", "fnn-hib", "--physics", "lag+linear",
                 "--epochs", "1", *cols, "--out", str(model)]) == 0
    assert main(["predict", str(model), str(paths[2]), *cols, "--out", str(tmp_path / "p.csv")]) == 0
    assert main(["export", str(model), "--out", str(tmp_path / "m.casadi")]) == 0
    assert ExportedModel.load(tmp_path / "m.casadi").n_u == 2
    capsys.readouterr()
    assert main(["predict", str(model), str(paths[2]), "--out", str(tmp_path / "q.csv")]) == 2  # current not loaded
    assert "current" in capsys.readouterr().err
    assert main(["mpc", "--model", str(model), "--out", str(tmp_path / "mpc")]) == 2
    assert "measured inputs (current)" in capsys.readouterr().err
    assert main(["train", str(paths[0]), "--input", "u,u", "--out", str(tmp_path / "x.pt")]) == 2
