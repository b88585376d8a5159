"""hyst train / hyst predict / hyst export on the same checkpoint."""

import numpy as np
import pytest

from hybrid.cli._main import main
from physics.virtual import DecayingSinusoid, VirtualCatheter


@pytest.fixture(scope="module")
def csvs(tmp_path_factory):
    root = tmp_path_factory.mktemp("runs")
    cath = VirtualCatheter(seed=0)
    paths = []
    for f, b in ((0.3, "mid"), (0.5, "end"), (0.4, "zero")):
        paths.append(cath.run(DecayingSinusoid(f, b, cycles=3), name=f"r{f}{b}").to_csv(root / f"{b}.csv"))
    return paths


@pytest.mark.parametrize("physics", [None, "boucwen+linear"])
def test_train_predict_export_round_trip(csvs, tmp_path, capsys, physics):
    model = tmp_path / "m.pt"
    args = ["train", str(csvs[0]), str(csvs[1]), "--model", "fnn-hib", "--epochs", "3",
            "--out", str(model)] + (["--physics", physics] if physics else [])
    assert main(args) == 0
    pred = tmp_path / "pred.csv"
    assert main(["predict", str(model), str(csvs[2]), "--out", str(pred)]) == 0
    table = np.loadtxt(pred, delimiter=",", skiprows=1)
    assert table.shape[1] == 4 and np.all(np.isfinite(table))
    rmse = np.sqrt(np.mean((table[:, 2] - table[:, 3]) ** 2))
    assert f"RMSE {rmse:.4g}" in capsys.readouterr().out
    if physics:  # the physics alone explains this data: the hybrid is near the noise
        assert rmse < 0.5
    assert main(["export", str(model), "--out", str(tmp_path / "m.casadi")]) == 0
    assert (tmp_path / "m.casadi").is_file()
    # the state from the first 10 measured samples: the rows after them, the model's own warm-up prediction
    assert main(["predict", str(model), str(csvs[2]), "--warmup", "10", "--out", str(pred)]) == 0
    warm = np.loadtxt(pred, delimiter=",", skiprows=1)
    np.testing.assert_array_equal(warm[:, :3], table[10:, :3])
    assert "after a warm-up of 10 measured samples" in capsys.readouterr().out
    assert main(["export", str(model), "--warmup", "10", "--out", str(tmp_path / "w.casadi")]) == 0
    from hybrid.export import ExportedModel

    step = ExportedModel.load(tmp_path / "w.casadi")
    np.testing.assert_allclose(step.simulate(warm[:, 1], warmup=(table[:10, 1], table[:10, 2])), warm[:, 3],
                               rtol=0, atol=1e-4)  # torch in float32
    assert main(["predict", str(model), str(csvs[2]), "--warmup", str(len(table)), "--out", str(pred)]) == 2
    if physics:  # a hybrid: the MPC picks the adjoint-sqp solver with the physics Hessian
        out = tmp_path / "mpc"
        assert main(["mpc", "--model", str(model), "--duration", "2", "--horizon", "10", "--effects",
                     "hysteresis", "--no-figures", "--out", str(out)]) == 0
        import json

        summary = json.loads((out / "summary.json").read_text())
        assert summary["solver"] == "adjoint-sqp" and summary["kind"] == "hybrid"
        assert summary["rmse_deg"] < 2.0 and summary["solves"] == 50


def test_bad_arguments_are_one_line(csvs, tmp_path, capsys):
    assert main(["train", str(csvs[0]), "--model", "gru", "--out", str(tmp_path / "m.pt")]) == 2
    assert "unknown network 'gru'" in capsys.readouterr().err
    assert main(["predict", str(tmp_path / "none.pt"), str(csvs[0]), "--out", "x.csv"]) == 2
    assert "No checkpoint" in capsys.readouterr().err


def test_residual_domain_reaches_the_hybrid_and_needs_physics(csvs, tmp_path, capsys):
    from hybrid.export import load

    model = tmp_path / "m.pt"
    base = ["train", str(csvs[0]), "--model", "fnn", "--epochs", "2", "--out", str(model)]
    assert main([*base, "--residual-domain", "0.5"]) == 2
    assert "--residual-domain weighs a hybrid's residual" in capsys.readouterr().err and not model.exists()
    assert main([*base, "--physics", "linear", "--residual-domain", "0.5"]) == 0
    assert load(model).residual_domain == 0.5


def test_predict_starts_a_model_folder_as_its_card_scored_each_run(tmp_path, capsys):
    """No --warmup: the folder's own warm-up, so a scored run prints the card's RMSE; --warmup 0 starts from rest."""
    import json

    from physics import Series
    from physics.data import Trajectory

    series = Series.from_spec("lag+linear", dt=0.04).set_params(**{"lag.time_constant_s": 0.3, "linear.gain": 0.02,
                                                                   "linear.offset": -20.0})
    t = np.arange(600) * 0.04
    runs = []
    for i, period in enumerate((9.0, 13.0)):
        u = 1900 + 800 * np.sin(2 * np.pi * t / period)  # motor steps, starting far from zero
        y = series.simulate(u) + 0.05 * np.random.default_rng(i).standard_normal(t.size)
        runs.append(Trajectory(t, u, y).to_csv(tmp_path / f"run{i}.csv"))
    folder = tmp_path / "m"
    assert main(["fit", str(runs[0]), "--test", str(runs[1]), "--physics", "lag+linear", "--residual", "none",
                 "--warmup", "7", "--no-progress", "--jobs", "1", "--out", str(folder)]) == 0
    card = {row["run"]: row for row in json.loads((folder / "card.json").read_text())["rows"]}
    capsys.readouterr()
    assert main(["predict", str(folder), str(runs[1]), "--out", str(tmp_path / "p.csv")]) == 0
    out = capsys.readouterr().out
    assert "after a warm-up of 7 measured samples (the model folder's" in out
    assert len(np.loadtxt(tmp_path / "p.csv", delimiter=",", skiprows=1)) == t.size - 7
    scored = float(out.split("RMSE ")[-1].split()[0])
    assert scored == pytest.approx(card["run1"]["model_rmse"], rel=1e-3)
    assert main(["predict", str(folder), str(runs[1]), "--warmup", "0", "--out", str(tmp_path / "p0.csv")]) == 0
    out = capsys.readouterr().out
    assert "from rest at the first input" in out and "folder's" not in out
    assert float(out.split("RMSE ")[-1].split()[0]) < 0.2  # the rest start at 1900 is the steady state there
