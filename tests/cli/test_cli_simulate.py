"""``hyst simulate`` in-process."""

import json

import numpy as np
import pytest

from hybrid.cli._main import main


def test_single_run_writes_signals_and_true_states(tmp_path, capsys):
    out = tmp_path / "run.csv"
    assert main(["simulate", "--effects", "lag,hysteresis,backlash", "--freq", "0.5", "--baseline", "mid",
                 "--seed", "0", "--out", str(out)]) == 0
    header = out.read_text().splitlines()[0]
    assert header == "time,u,y,command,q_actual,q_backlash,z,y_true"
    data = np.loadtxt(out, delimiter=",", skiprows=1)
    assert data.shape == (351, 8)
    assert np.std(data[:, 2] - data[:, 7]) == pytest.approx(0.15, rel=0.15)
    np.testing.assert_array_equal(data[:, 1], data[:, 4])  # u: the measured displacement
    printed = capsys.readouterr().out
    assert str(out) in printed and "noise floor: 0.15 deg" in printed


@pytest.mark.parametrize("signal", ["multisine", "steps"])
def test_other_signals(tmp_path, signal):
    out = tmp_path / f"{signal}.csv"
    assert main(["simulate", "--signal", signal, "--duration", "10", "--noise", "0", "--out", str(out)]) == 0
    data = np.loadtxt(out, delimiter=",", skiprows=1)
    assert data.shape[0] == 251 and np.array_equal(data[:, 2], data[:, -1])


def test_paper_dataset_writes_train_test_and_manifest(tmp_path, capsys):
    out = tmp_path / "demo"
    assert main(["simulate", "--paper-dataset", "--seed", "1", "--out", str(out)]) == 0
    assert len(list((out / "train").glob("*.csv"))) == 15
    assert len(list((out / "test").glob("*.csv"))) == 6
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["noise_floor_deg"] == 0.15 and manifest["seed"] == 1
    assert manifest["effects"] == ["actuator_lag", "backlash", "hysteresis"]
    assert {f["file"] for f in manifest["files"]} == {
        str(p.relative_to(out)) for p in out.glob("*/*.csv")}
    assert manifest["truth_model"]["params"]["backlash.width"] == 0.2
    assert not list(out.rglob(".*.tmp"))
    printed = capsys.readouterr().out
    assert str(out) in printed and "noise floor" in printed


def test_unknown_effect_is_one_clear_line(tmp_path, capsys):
    assert main(["simulate", "--effects", "lag,friction", "--out", str(tmp_path / "x.csv")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "friction" in err
    assert "actuator_lag, time_delay, backlash, hysteresis, static_nonlinearity, drift" in err
    assert not (tmp_path / "x.csv").exists()


def test_paper_dataset_needs_a_folder(tmp_path):
    assert main(["simulate", "--paper-dataset", "--out", str(tmp_path / "x.csv")]) == 2


def test_help_has_an_example(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["simulate", "--help"])
    assert exc.value.code == 0
    assert "hyst simulate --paper-dataset --out results/demo" in capsys.readouterr().out


@pytest.mark.parametrize("argv, message", [
    (["--effects", ""], "--effects is empty"),
    (["--qmax", "1e300"], "argument --qmax: must be a number > 0 and <= 10 (mm)"),  # refused before any work
])
def test_empty_effects_and_an_overflowing_amplitude_name_their_flag(tmp_path, capsys, argv, message):
    out = tmp_path / "s.csv"
    assert main(["simulate", *argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1 and not out.exists()


def test_effects_none_is_the_linear_catheter(tmp_path):
    out = tmp_path / "s.csv"
    assert main(["simulate", "--effects", "none", "--noise", "0", "--out", str(out)]) == 0
    data = np.genfromtxt(out, delimiter=",", names=True)
    line = np.polyfit(data["u"], data["y"], 1)
    np.testing.assert_allclose(data["y"], np.polyval(line, data["u"]), atol=1e-9)  # no hysteresis, lag or drift
    assert line[0] > 0
