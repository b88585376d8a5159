"""Messages of issue #42 that misled: each refusal names what was wrong (the missing file, the
unwritable folder, the NaN sample) in one line and says how to fix it, before any work is written."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from hybrid.cli._main import main
from physics.data import DataError
from physics.virtual import DecayingSinusoid, VirtualCatheter
from _cli import refused

UNWRITABLE = Path("/proc")  # tests run as root, which chmod does not stop: /proc takes no new files


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory, run_csv) -> Path:
    """A one-epoch FNN checkpoint (``m.pt`` and its ``m.json``)."""
    out = tmp_path_factory.mktemp("model") / "m.pt"
    assert main(["train", str(run_csv), "--model", "fnn", "--epochs", "1", "--validation", "0",
                 "--out", str(out)]) == 0
    return out


@pytest.mark.parametrize("model", ["model.casadi", "fit.json", "model.pt"])
def test_a_model_folder_missing_its_model_names_the_file(model, run_csv, tmp_path, capsys):
    folder = tmp_path / "folder"
    folder.mkdir()
    (folder / "card.json").write_text(json.dumps({"format": "hysteresis-hybrid/model-dir/1", "model": model}))
    err = refused(["predict", folder, run_csv, "--out", tmp_path / "p.csv"], capsys, f"'{folder / model}' is missing",
                  "card.json", "hyst fit")
    assert f"at '{folder}'" not in err, err


def test_a_garbage_checkpoint_is_not_ours_without_torchs_advice(checkpoint, run_csv, tmp_path, capsys):
    shutil.copy(checkpoint.with_suffix(".json"), tmp_path / "model.json")  # a valid-looking sidecar
    (tmp_path / "model.pt").write_bytes(np.random.default_rng(0).bytes(512))
    refused(["predict", tmp_path / "model.pt", run_csv, "--out", tmp_path / "p.csv"], capsys, "model.pt",
            "not one this project wrote", "hyst train", absent=("weights_only", "PyTorch"))


@pytest.mark.parametrize("argv", [
    lambda csv, ckpt, bad: ["predict", ckpt, csv, "--out", bad / "p.csv"],  # a file in the folder
    lambda csv, ckpt, bad: ["predict", ckpt, csv, "--out", bad / "new" / "p.csv"],  # in a folder to create
    lambda csv, ckpt, bad: ["mpc", "--model", "lag+boucwen+linear", "--out", bad / "mpc"],  # a folder
], ids=["file", "file-in-new-folder", "folder"])
def test_an_unwritable_out_folder_is_named_not_a_temp_file(argv, run_csv, checkpoint, capsys):
    err = refused(argv(run_csv, checkpoint, UNWRITABLE), capsys, f"'{UNWRITABLE}' is not writable",
                  absent=(".tmp",))
    assert "No such file" not in err, err


def test_the_writability_probe_leaves_no_file(run_csv, checkpoint, tmp_path):
    assert main(["predict", str(checkpoint), str(run_csv), "--out", str(tmp_path / "p.csv")]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p.csv"]


@pytest.mark.parametrize("option", ["--controller", "--c-code"])
def test_export_checks_its_folders_before_writing_anything(option, checkpoint, tmp_path, capsys):
    (tmp_path / "taken").write_text("a file, not a folder\n")
    out = tmp_path / "step.casadi"
    refused(["export", checkpoint, option, tmp_path / "taken", "--out", out], capsys, option, "is a file")
    refused(["export", checkpoint, option, UNWRITABLE / "ctl", "--out", out], capsys, option,
            f"'{UNWRITABLE}' is not writable")
    assert not out.exists() and not Path(f"{out}.json").exists()


def test_a_nan_input_to_hybrid_predict_names_the_sample():
    from hybrid import HybridModel, TrainingSettings
    from hybrid.networks import FNNNet

    cath = VirtualCatheter(seed=0)
    traj = cath.run(DecayingSinusoid(0.4, "mid", cycles=1), name="r")
    model = HybridModel(cath.truth_model(), FNNNet(hidden=(4,)),
                        training=TrainingSettings(epochs=1, progress=False, threads=1, seed=0))
    model.fit([traj])
    u = np.array(traj.u, dtype=float)
    u[7] = np.nan
    with pytest.raises(DataError, match=r"input sample 7 is NaN") as info:
        model.predict(u)
    assert "shape" not in str(info.value)
    assert np.all(np.isfinite(model.predict(np.array(traj.u, dtype=float))))
    with pytest.raises(DataError, match="shape"):  # a wrong shape is still a shape error
        model.predict(np.ones((3, 4)))
