"""``hyst reproduce`` end to end on a tiny setting, and its errors."""

import csv
import json

import numpy as np
import pytest

from hybrid.cli._main import main
from physics.virtual import paper_protocol


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    """A small dataset folder like `hyst simulate --paper-dataset` writes: 2 train, 1 test."""
    root = tmp_path_factory.mktemp("data")
    split = paper_protocol(frequencies=(0.4, 0.5), tests=(0.45,), baselines=("mid",))
    for part, data in (("train", split.train), ("test", split.test)):
        (root / part).mkdir()
        for traj in data:
            traj.to_csv(root / part / f"{traj.source}.csv")
    (root / "manifest.json").write_text(json.dumps({"units": {"time": "s", "u": "mm", "y": "deg"}}))
    return root


def _rows(path):
    with open(path) as fh:
        return list(csv.DictReader(fh))


def test_reproduce_on_a_folder_writes_table_figures_and_models(folder, tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["reproduce", "--data", str(folder), "--preset", "tiny", "--out", str(out), "--no-progress"]) == 0
    rows = _rows(out / "table.csv")
    assert list(rows[0]) == ["direction", "model", "test", "rmse", "nrmse"]
    keys = {(r["direction"], r["model"], r["test"]) for r in rows}
    assert keys == {(d, m, t) for d in ("forward", "inverse") for m in ("fnn", "fnn-hib", "lstm")
                    for t in ("test_f0.45_mid", "all")}
    assert all(np.isfinite(float(r["rmse"])) and float(r["nrmse"]) > 0 for r in rows)
    md = (out / "table.md").read_text()
    assert "RMSE (deg)" in md and "RMSE (mm)" in md and "FNN-HIB" in md
    assert sorted(p.name for p in (out / "figures").glob("*.png")) == [
        "forward_test_f0.45_mid.png", "inverse_test_f0.45_mid.png"]
    assert len(list((out / "models").glob("*.pt"))) == 6
    assert {r["mode"] for r in _rows(out / "lstm_modes.csv")} == {"window", "carried"}
    assert str(out) in capsys.readouterr().out


def test_reproduce_virtual_tiny_has_every_test_run(tmp_path):
    out = tmp_path / "v"
    code = main(["reproduce", "--preset", "tiny", "--max-train", "2", "--models", "fnn,fnn-hib",
                 "--no-figures", "--no-progress", "--out", str(out)])
    assert code == 0
    rows = _rows(out / "table.csv")
    assert len(rows) == 2 * 2 * (6 + 1)  # directions x models x (6 test runs + pooled)


@pytest.mark.parametrize("argv, message", [
    (["--models", "fnn,gru"], "unknown model 'gru'. Must be one of"),
    (["--data", "/no/such/folder"], "neither 'virtual', a measured data set (catheter_2023, "),
    (["--preset", "huge"], "unknown preset 'huge'. Must be one of"),
])
def test_bad_input_is_one_line_and_exit_2(argv, message, tmp_path, capsys):
    assert main(["reproduce", "--out", str(tmp_path / "x"), "--no-progress", *argv]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
