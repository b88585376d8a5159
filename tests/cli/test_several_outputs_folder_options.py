"""What ``hyst fit --output "Angle x,Pos x,Pos y"`` takes as a folder of one output does (issues 53 and 55): measured
inputs (``--input "Tendon Disp.,Motor Curr."``) read by the residual network beside the command, dropped and said
where no network that reads them beats the physics alone held out; and ``--group``, each condition left out whole
of a refit of the physics for the intervals; and ``--resume``, the stages whose inputs are unchanged reused."""

import json

import numpy as np
import pytest

from _cli import write_pose

from hybrid.cli._main import main
from hybrid.virtual import DecayingSinusoid, TipArc, VirtualCatheter

COLUMNS = ("time", "Tendon Disp.", "Motor Curr.", "Angle x", "Pos x", "Pos y")
OUTPUTS = "Angle x,Pos x,Pos y"
#: The condition in each file name: the day it was recorded
GROUP = r"day(\d)"
#: mm of ``Pos x`` per unit of the measured current: the truth the network has to find in the second input
GAIN = 1.0


def _write(path, run, current, gain):
    """A run's CSV with a measured current that moves ``Pos x`` by ``gain`` per unit (0: a current it ignores)."""
    return write_pose(path, run, COLUMNS, **{"Motor Curr.": current, "Pos x": run.extra["Pos x"] + gain * current})


@pytest.fixture(scope="module")
def runs():
    cath = VirtualCatheter(seed=6, tip=TipArc())
    return [cath.run(DecayingSinusoid(frequency_hz=f, baseline=b)) for f, b in
            ((0.2, "zero"), (0.5, "end"), (0.3, "mid"), (0.4, "zero"), (0.25, "mid"), (0.45, "end"))]


def _files(runs, folder, gain):
    """The runs' CSVs, each with its own slow current (a sine of its own rate and phase, not the tendon's)."""
    return [_write(folder / f"r{i}.csv", r, np.sin(2 * np.pi * (0.05 + 0.03 * i) * r.time + i), gain)
            for i, r in enumerate(runs)]


def _fit(files, out, residual, *extra, physics="lag+backlash+linear"):
    """``hyst fit`` of every output on ``files[1:]``, tested on ``files[0]``, reading the current."""
    return main(["fit", *files[1:], "--test", files[0], "--input", "Tendon Disp.,Motor Curr.", "--output", OUTPUTS,
                 "--rate", "25", "--physics", physics, "--residual", residual, "--jobs", "1", "--no-progress",
                 "--out", str(out), *extra])


def test_a_network_of_every_output_reads_the_measured_input_and_the_step_takes_it(runs, tmp_path, capsys):
    """``Pos x`` moves with the current, which the chain cannot see: the network that reads it brings the test
    error of ``Pos x`` well below the physics' own; ``hyst predict`` reads the current from the folder's columns
    and prints the card's numbers, and the exported step takes ``[u, current]`` and gives the same predictions."""
    from hybrid.export import ExportedModel

    files = _files(runs, tmp_path, GAIN)
    out = tmp_path / "m"
    assert _fit(files, out, "fnn-hib") == 0
    printed = capsys.readouterr().out
    assert "measured inputs 'Motor Curr.': read by the fnn-hib residual network" in printed
    assert "the exported step takes [Tendon Disp., Motor Curr.]" in printed
    card = json.loads((out / "card.json").read_text())
    assert card["columns"]["input"] == "Tendon Disp.,Motor Curr." and card["residual"] == "fnn-hib"
    rows = {r["output"]: r for r in card["rows"] if r["set"] == "test"}
    assert rows["Pos x"]["model_rmse"] < 0.6 * rows["Pos x"]["physics_rmse"], rows["Pos x"]
    assert "reads the measured input(s) `Motor Curr.` beside the command" in (out / "report.md").read_text()

    pred = tmp_path / "pred.csv"
    assert main(["predict", str(out), files[0], "--out", str(pred)]) == 0
    header = pred.read_text().splitlines()[0].split(",")
    data = np.loadtxt(pred, delimiter=",", skiprows=1)
    for o, r in rows.items():
        err = data[:, header.index(o)] - data[:, header.index(o + "_pred")]
        assert np.sqrt(np.mean(err ** 2)) == pytest.approx(r["model_rmse"], rel=1e-9)
    step = ExportedModel.load(out / "step.casadi")
    test = np.loadtxt(files[0], delimiter=",", skiprows=1)
    u, y = test[:, 1:3], test[:, 3:6]  # the command and the current; the three outputs
    assert step.init.size_in(0) == (2, 10)
    stepped = step.simulate(u[10:], warmup=(u[:10], y[:10]))
    np.testing.assert_allclose(stepped, data[:, [header.index(o + "_pred") for o in card["outputs"]]], rtol=1e-6,
                               atol=1e-6)


def test_a_measured_input_no_network_helps_with_is_dropped_and_the_step_takes_the_command(runs, tmp_path, capsys,
                                                                                        monkeypatch):
    """``--residual auto`` with every candidate worse held out than the physics alone (each prediction made 5
    mm or deg off): the physics alone is kept, the current is not read, and the card, the command line and the
    exported step (one input) say so."""
    from hybrid.experiments import _fit_outputs
    from hybrid.export import ExportedModel

    trained = []
    held_out = _fit_outputs._residual_held_out

    def worse(series, name, networks, outputs, fit_on, check, warmup, measured=()):
        trained.append((name, measured))
        return [p + 5.0 for p in held_out(series, name, networks, outputs, fit_on, check, warmup, measured)]

    monkeypatch.setattr(_fit_outputs, "_residual_held_out", worse)
    files = _files(runs, tmp_path, 0.0)
    out = tmp_path / "m"
    assert _fit(files, out, "auto") == 0
    printed = capsys.readouterr().out
    assert trained and all(m == ("Motor Curr.",) for _, m in trained)  # every candidate read it held out
    assert "measured inputs 'Motor Curr.': not read" in printed and "the exported step takes [Tendon Disp.]" in printed
    card = json.loads((out / "card.json").read_text())
    assert card["residual"] == "none" and card["model"] == "physics.json"
    assert "`Motor Curr.` are **not read**" in (out / "report.md").read_text()
    assert ExportedModel.load(out / "step.casadi").init.size_in(0) == (1, 10)


def test_group_calibrates_the_intervals_leaving_each_condition_out_of_a_refit_of_the_physics(runs, tmp_path, capsys):
    """``--group 'day(\\d)'`` on five training runs recorded on three days: the physics of every output is refitted
    without each day and predicts that day's runs; the held-out errors on the card are those of three such refits
    done here, and the card and the command line name the conditions."""
    from identification import identify_outputs, output_columns, predict_outputs
    from physics import Series
    from physics.data import load_csvs

    days = ["test", "day1", "day1", "day2", "day2", "day3"]
    files = [_write(tmp_path / f"{d}_r{i}.csv", r, np.zeros(r.n), 0.0) for i, (d, r) in enumerate(zip(days, runs))]
    out = tmp_path / "m"
    spec = "lag+backlash+linear"
    assert main(["fit", *files[1:], "--test", files[0], "--input", "Tendon Disp.", "--output", OUTPUTS, "--rate", "25",
                 "--physics", spec, "--residual", "none", "--group", GROUP, "--jobs", "1", "--no-progress",
                 "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "each condition left out: the physics refitted without it (3 folds); conditions: file names by" in printed
    card = json.loads((out / "card.json").read_text())
    assert f"conditions: file names by {GROUP!r}" in (out / "report.md").read_text()

    outputs = tuple(OUTPUTS.split(","))
    train = load_csvs(files[1:], time="time", input="Tendon Disp.", output=outputs[0], extra=outputs[1:], rate_hz=25)
    errors = {o: [] for o in outputs}
    for fold in ([0, 1], [2, 3], [4]):
        fit = identify_outputs(Series.from_spec(spec, dt=train[0].dt), [t for i, t in enumerate(train) if i not in fold],
                               outputs, warmup=10)
        for i in fold:
            y = output_columns(train[i], outputs)
            p = predict_outputs(fit.series, train[i].u, y, 10)
            for j, o in enumerate(outputs):
                errors[o].append(y[10:, j] - p[:, j])
    for o in outputs:
        expected = float(np.sqrt(np.mean(np.concatenate(errors[o]) ** 2)))
        assert card["held_out_rmse"][o]["physics"] == pytest.approx(expected, rel=1e-6), o


def test_resume_reuses_the_joint_fit_and_the_network_whose_inputs_are_unchanged(runs, tmp_path, capsys):
    """``--resume`` after a fit of every output with a network: the same command reuses the joint fit and the
    network (the same files, the same card); another network reuses the joint fit alone; another physics reuses
    nothing (as in a folder of one output, the test runs are among every stage's inputs)."""
    import hashlib

    files = _files(runs, tmp_path, GAIN)
    out = tmp_path / "m"
    assert _fit(files, out, "fnn-hib") == 0
    capsys.readouterr()
    card = json.loads((out / "card.json").read_text())
    digest = hashlib.sha256((out / "model.pt").read_bytes()).hexdigest()
    physics = json.loads((out / "physics.json").read_text())["parameters"]
    assert _fit(files, out, "fnn-hib", "--resume") == 0
    assert "(reused: identify, residual)" in capsys.readouterr().out
    again = json.loads((out / "card.json").read_text())
    assert again["rows"] == card["rows"] and again["held_out_rmse"] == card["held_out_rmse"]
    assert hashlib.sha256((out / "model.pt").read_bytes()).hexdigest() == digest
    assert _fit(files, out, "lstm", "--resume") == 0  # another network on the same joint fit
    assert "(reused: identify)" in capsys.readouterr().out
    lstm = json.loads((out / "card.json").read_text())
    assert lstm["residual"] == "lstm" and lstm["spec"] == card["spec"]
    assert json.loads((out / "physics.json").read_text())["parameters"] == physics  # the joint fit, as it was
    assert _fit(files, out, "fnn-hib", "--resume", physics="lag+linear") == 0
    assert "reused" not in capsys.readouterr().out
