"""``hyst identify`` in-process: JSON keys, report, exit statuses."""

import json
from dataclasses import replace

import pytest

from hybrid.cli._main import main

from _synthetic import NOISE_DEG, make_runs, truth_model, write_csv


@pytest.fixture(scope="module")
def csvs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("identify")
    runs = make_runs(truth_model("backlash+linear"), NOISE_DEG, seed=3)
    return [write_csv(folder / f"run{i}.csv", r) for i, r in enumerate(runs)]


def test_identify_writes_the_json_with_the_required_keys(csvs, tmp_path, capsys):
    out = tmp_path / "fit.json"
    status = main(["identify", *csvs[:2], "--model", "backlash+linear", "--test", csvs[2],
                   "--rate", "25", "--starts", "2", "--out", str(out)])
    assert status == 0
    fit = json.loads(out.read_text())
    for key in ("model", "parameters", "standard_errors", "train_rmse", "test_rmse", "status",
                "success", "iterations", "wall_time_s"):
        assert key in fit, key
    assert fit["model"] == "backlash+linear" and fit["success"] is True
    assert fit["parameters"]["backlash.width"] == pytest.approx(0.4, rel=0.1)
    assert fit["test_rmse"] == pytest.approx(NOISE_DEG, rel=0.15)
    printed = capsys.readouterr().out
    assert "backlash.width" in printed and "+/-" in printed and "test RMSE" in printed


def test_identify_fixed_and_bad_input(csvs, tmp_path, capsys):
    out = tmp_path / "fit.json"
    assert main(["identify", csvs[0], "--model", "backlash+linear", "--fixed",
                 "backlash.width=0.4", "--out", str(out)]) == 0
    # the parameters the block holds by default (where the play starts in its band) are listed too
    assert json.loads(out.read_text())["fixed"] == {"backlash.width": 0.4, "backlash.start": 0.0}
    assert main(["identify", csvs[0], "--model", "backlash+linear", "--fixed", "nope=1",
                 "--out", str(out)]) == 2
    assert "Unknown parameter 'nope'" in capsys.readouterr().err
    assert main(["identify", csvs[0], "--model", "backlash+linear", "--input", "tension",
                 "--out", str(out)]) == 2
    assert main(["identify", csvs[0], "--model", "wobble+linear", "--out", str(out)]) == 2
    assert "Unknown block 'wobble'" in capsys.readouterr().err


def test_identify_failure_exits_non_zero_and_is_flagged(csvs, tmp_path, capsys, monkeypatch):
    import identification

    real = identification.identify

    def one_iteration(*args, solver, **kwargs):
        return real(*args, solver=replace(solver, ipopt_options={"max_iter": 1}), **kwargs)

    monkeypatch.setattr(identification, "identify", one_iteration)
    out = tmp_path / "fit.json"
    assert main(["identify", *csvs, "--model", "lag+boucwen+linear", "--out", str(out)]) == 2
    assert "did not converge" in capsys.readouterr().err and not out.exists()
    assert main(["identify", *csvs, "--model", "lag+boucwen+linear", "--allow-failure",
                 "--out", str(out)]) == 1
    assert json.loads(out.read_text())["success"] is False
    assert "NOT CONVERGED" in capsys.readouterr().out
