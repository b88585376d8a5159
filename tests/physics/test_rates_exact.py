"""A model keeps the rate its data were recorded at, exactly, and runs at it (issue #41, item 5)."""

import json

import numpy as np
import pytest

from hybrid.cli import main
from physics.data import Trajectory, raw_rate, resample


def _linear_run(path, rate_hz, n):
    """``n`` samples at ``rate_hz`` of y = 2 u + 0.5 with a little noise, written as a CSV."""
    t = np.arange(n) / rate_hz
    u = 1.0 + np.sin(2 * np.pi * t / (40 / rate_hz)) + 0.3 * np.sin(2 * np.pi * t / (11 / rate_hz))
    y = 2.0 * u + 0.5 + 0.01 * np.random.default_rng(0).standard_normal(n)
    return Trajectory(t, u, y).to_csv(path)


def _fit(csv, out):
    assert main(["fit", str(csv), "--physics", "linear", "--residual", "none", "--no-progress",
                 "--out", str(out)]) == 0


def test_the_files_rate_is_kept_to_its_last_digit():
    assert raw_rate([np.arange(3000) / 500.8]) == 500.8
    assert raw_rate([np.arange(100) / 1234.5, 7.0 + np.arange(50) / 1234.5]) == 1234.5
    # unix time: the float64 steps of 1.7e9 + k / 25 are 0.04 +/- 2.4e-7 s (read as 25.00002384 Hz before)
    assert raw_rate([1.7e9 + np.arange(400) / 25]) == 25.0
    assert raw_rate([1.7e9 + np.arange(4000) / 2000]) == 2000.0
    unix = Trajectory.from_raw(1.7e9 + np.arange(400) / 25, np.zeros(400), np.zeros(400), rate_hz=25.0)
    assert unix.dt == 0.04  # its resampled stamps are as coarse: the rate it was resampled at
    t, _ = resample(np.arange(3000) / 500.8, np.zeros(3000), 500.8)
    assert t.size == 3000  # the grid of the file's own rate is the file's, no row added or lost


def test_a_500_8_hz_file_stays_500_8_hz_from_fit_to_export_and_predict(tmp_path, capsys):
    """3000 samples: at 501 Hz they would span 3001 rows."""
    csv = _linear_run(tmp_path / "run.csv", 500.8, 3000)
    _fit(csv, tmp_path / "m")
    assert "model rate 500.8 Hz" in capsys.readouterr().out
    card = json.loads((tmp_path / "m" / "card.json").read_text())
    assert card["rate_hz"] == 500.8
    step = json.loads((tmp_path / "m" / "step.casadi.json").read_text())
    assert step["dt"] == pytest.approx(1 / 500.8, rel=1e-12)
    pred = tmp_path / "pred.csv"
    assert main(["predict", str(tmp_path / "m"), str(csv), "--warmup", "0", "--out", str(pred)]) == 0  # every row
    table = np.loadtxt(pred, delimiter=",", skiprows=1)
    raw = np.loadtxt(csv, delimiter=",", skiprows=1)
    assert len(table) == len(resample(raw[:, 0], raw[:, 1], 500.8)[0]) == 3000
    np.testing.assert_allclose(np.diff(table[:, 0]), 1 / 500.8, rtol=1e-9)


@pytest.mark.parametrize(("rate", "n"), [(1.0, 276), (50.0, 300)])
def test_a_physics_folder_runs_at_its_own_rate_and_refuses_another(tmp_path, capsys, rate, n):
    csv = _linear_run(tmp_path / "run.csv", rate, n)
    folder = tmp_path / "m"
    _fit(csv, folder)
    pred = tmp_path / "pred.csv"
    assert main(["predict", str(folder), str(csv), "--warmup", "0", "--out", str(pred)]) == 0  # every row
    table = np.loadtxt(pred, delimiter=",", skiprows=1)
    assert len(table) == n
    np.testing.assert_allclose(np.diff(table[:, 0]), 1 / rate, rtol=1e-9)
    assert main(["predict", str(folder), str(csv), "--rate", f"{rate:g}", "--out", str(pred)]) == 0
    capsys.readouterr()
    for command in (["predict", str(folder), str(csv), "--out", str(tmp_path / "p25.csv")],
                    ["export", str(folder), "--out", str(tmp_path / "s25.casadi")],
                    ["mpc", "--model", str(folder), "--no-figures", "--out", str(tmp_path / "mpc25")]):
        assert main([*command, "--rate", "25"]) == 2, command[0]
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "25 Hz" in err and f"{rate:g} Hz" in err, err
    assert not any((tmp_path / name).exists() for name in ("p25.csv", "s25.casadi", "mpc25"))
    assert main(["export", str(folder), "--out", str(tmp_path / "s.casadi")]) == 0
    assert json.loads((tmp_path / "s.casadi.json").read_text())["dt"] == pytest.approx(1 / rate, rel=1e-12)
