"""Every ``--input`` column is used or refused (issue #41): a measured input reaches the residual
network, the exported step and ``hyst predict``; a model that cannot use it, and a column no model
can learn from (constant, a copy of the output or of the time), is refused in one line before any work."""

import json
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("torch")

from hybrid.cli import main  # noqa: E402
from dataclasses import replace  # noqa: E402

from hybrid.experiments import BUDGETS, NetworkBudget  # noqa: E402
from hybrid.experiments._fit import Columns, fit_model_dir  # noqa: E402
from hybrid.learning import TrainingSettings  # noqa: E402
from hybrid.export import ExportedModel  # noqa: E402
from physics.data import DataError, Trajectory  # noqa: E402

RATE_HZ = 25.0


def _run(seed: int, n: int = 300) -> Trajectory:
    """y = 2 u + 1 + 3 volt: the command alone explains only part of the output."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / RATE_HZ
    u = 3 + 2 * np.sin(2 * np.pi * (0.3 + 0.1 * seed) * t + seed)
    volt = np.sin(2 * np.pi * 0.17 * t + 2.0 * seed + 1.0) + 0.3 * np.sin(2 * np.pi * 0.05 * t)
    y = 2 * u + 1 + 3 * volt + 0.01 * rng.standard_normal(n)
    return Trajectory(t, u, y, source=f"run{seed}", extra={"volt": volt})


@pytest.fixture
def csvs(tmp_path):
    return [str(_run(i).to_csv(tmp_path / f"run{i}.csv")) for i in range(4)]


@pytest.fixture
def short(monkeypatch):
    """The quick preset cut to a few seconds, and no C compilation."""
    import hybrid.export._codegen as codegen

    monkeypatch.setitem(BUDGETS, "quick", replace(BUDGETS["quick"], networks=NetworkBudget(
        TrainingSettings(epochs=40, stride=1, batch_size=64))))
    import hybrid.control._estimator as estimator

    monkeypatch.setattr(codegen, "has_compiler", lambda *compiler: False)
    monkeypatch.setattr(estimator, "has_compiler", lambda *compiler: False)  # predict --measure-every's estimator


def _fit(csvs, out, *extra) -> int:
    return main(["fit", *csvs[:3], "--physics", "linear", "--out", str(out), "--no-progress", *extra])


def test_a_measured_input_reaches_the_network_the_step_and_predict(csvs, tmp_path, short, capsys):
    with_volt, without = tmp_path / "with", tmp_path / "without"
    assert _fit(csvs, with_volt, "--residual", "fnn", "--input", "u,volt") == 0
    printed = capsys.readouterr().out
    assert "measured inputs 'volt': read by the fnn residual network" in printed  # where the column went
    assert _fit(csvs, without, "--residual", "fnn") == 0
    step = ExportedModel.load(with_volt / "step.casadi")
    assert step.n_u == 2 and step.meta["inputs"] == ["u", "volt"]
    assert ExportedModel.load(without / "step.casadi").n_u == 1
    assert json.loads((with_volt / "card.json").read_text())["columns"]["input"] == "u,volt"
    # predict reads the folder's columns, volt included, with no flags
    errors = {}
    for name, folder in (("with", with_volt), ("without", without)):
        capsys.readouterr()
        assert main(["predict", str(folder), csvs[3], "--warmup", "0", "--out", str(tmp_path / f"{name}.csv")]) == 0
        pred = np.genfromtxt(tmp_path / f"{name}.csv", delimiter=",", names=True)
        errors[name] = float(np.sqrt(np.mean((pred["y"] - pred["y_pred"]) ** 2)))
    assert errors["with"] < 0.5 * errors["without"], errors  # the volt term is learned only from volt
    # --measure-every steps the estimator on [u, volt] too (was: "The input must hold 2 finite value(s)")
    assert main(["predict", str(with_volt), csvs[3], "--measure-every", "1", "--out", str(tmp_path / "m1.csv")]) == 0
    fed = np.genfromtxt(tmp_path / "m1.csv", delimiter=",", names=True)
    assert float(np.sqrt(np.mean((fed["y"] - fed["y_pred"]) ** 2))) < errors["with"] + 0.05
    # the step steps [u, volt] as the model predicts
    test = _run(3)
    pred = np.genfromtxt(tmp_path / "with.csv", delimiter=",", names=True)["y_pred"]
    np.testing.assert_allclose(step.simulate(np.column_stack([test.u, test.extra["volt"]])), pred, atol=1e-4)
    assert main(["export", str(with_volt), "--out", str(tmp_path / "s.casadi")]) == 0
    assert ExportedModel.load(tmp_path / "s.casadi").n_u == 2
    capsys.readouterr()  # mpc's virtual plant gives no volt: a clear refusal, not a dropped column
    assert main(["mpc", "--model", str(with_volt), "--out", str(tmp_path / "mpc")]) == 2
    assert "measured inputs (volt)" in capsys.readouterr().err


def _one_line_refusal(capsys, *needles) -> str:
    captured = capsys.readouterr()
    err = captured.err.strip()
    assert err.startswith("hyst fit: error: ") and "\n" not in err and "Traceback" not in err, err
    for needle in needles:
        assert needle in err, (needle, err)
    return err


def test_physics_only_with_a_measured_input_is_refused_before_any_work(csvs, tmp_path, capsys):
    out = tmp_path / "m"
    assert _fit(csvs, out, "--residual", "none", "--input", "u,volt") == 2
    _one_line_refusal(capsys, "'volt'", "--input", "--residual")
    assert not out.exists()


def test_fit_model_dir_refuses_what_it_cannot_feed(tmp_path):
    runs = [_run(i) for i in range(3)]
    with pytest.raises(DataError, match=r"'none'.*'volt'"):
        fit_model_dir(runs, tmp_path / "m", physics="linear", residual="none", columns=Columns(measured=("volt",)))
    with pytest.raises(DataError, match="run0.*no measured input 'current'"):
        fit_model_dir(runs, tmp_path / "m", physics="linear", residual="fnn", columns=Columns(measured=("current",)))
    assert not (tmp_path / "m").exists()


def _with_column(path, name, values) -> str:
    """A copy of the CSV ``path`` with one more column."""
    lines = Path(path).read_text().splitlines()
    out = Path(path).with_name(f"{Path(path).stem}_{name}.csv")
    out.write_text(f"{lines[0]},{name}\n" + "".join(f"{row},{float(v)!r}\n" for row, v in zip(lines[1:], values)))
    return str(out)


@pytest.mark.parametrize("how", ["constant command", "constant extra", "output by name", "output by values",
                                 "time by name", "time by values"])
def test_an_input_no_model_can_learn_from_is_refused_in_one_line(csvs, tmp_path, capsys, how):
    runs = [_run(i) for i in range(3)]
    if how == "constant command":
        paths = [_with_column(p, "hold", np.full(t.n, 2.5)) for p, t in zip(csvs, runs)]
        argv, needles = ["--input", "hold"], ["'hold'", "constant"]
    elif how == "constant extra":
        paths = [_with_column(p, "hold", np.full(t.n, 2.5)) for p, t in zip(csvs, runs)]
        argv, needles = ["--input", "u,hold"], ["'hold'", "constant"]
    elif how == "output by name":
        paths, argv, needles = csvs, ["--input", "u,y"], ["'y'", "output"]
    elif how == "output by values":
        paths = [_with_column(p, "angle", t.y) for p, t in zip(csvs, runs)]
        argv, needles = ["--input", "u,angle"], ["'angle'", "output"]
    elif how == "time by name":
        paths, argv, needles = csvs, ["--input", "time"], ["'time'", "time column"]
    else:
        paths = [_with_column(p, "clock", t.time) for p, t in zip(csvs, runs)]
        argv, needles = ["--input", "clock"], ["'clock'", "time"]
    out = tmp_path / "m"
    assert _fit(paths, out, "--residual", "fnn", *argv) == 2
    _one_line_refusal(capsys, *needles)
    assert not out.exists()


def test_a_second_input_the_output_does_not_depend_on_is_not_read(tmp_path):
    # the physics explains everything and volt nothing: a network that reads volt was chosen regardless
    # (the user asked for the column); now the physics alone, which ignores it, wins held out, and the
    # folder reads and exports the command alone and says so
    import json

    from hybrid.export import ExportedModel
    from physics import Series

    runs = [Trajectory(t.time, t.u, 2 * t.u + 1, source=t.source, extra=t.extra) for t in map(_run, range(3))]
    result = fit_model_dir(runs, tmp_path / "m", physics="linear", residual="auto", preset="tiny", progress=False,
                           columns=Columns("time", "u", "y", measured=("volt",)))
    assert result.residual == "none" and isinstance(result.model, Series) and result.dropped == ["volt"]
    assert ExportedModel.load(tmp_path / "m" / "step.casadi").n_u == 1
    assert json.loads((tmp_path / "m" / "card.json").read_text())["columns"]["input"] == "u"
    assert "`volt` are **not read**" in (tmp_path / "m" / "report.md").read_text()
