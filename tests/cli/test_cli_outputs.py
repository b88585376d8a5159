"""--out is checked before any work: never over an input, never a folder for a file or the reverse,
never under a missing or read-only folder; inputs are left byte-identical."""

from __future__ import annotations

import os

import pytest

from hybrid.cli import main


@pytest.fixture(scope="module")
def csv(tmp_path_factory):
    path = tmp_path_factory.mktemp("in") / "a.csv"
    assert main(["simulate", "--out", str(path), "--freq", "0.3"]) == 0
    return path


def _refused(argv, capsys, *words):
    assert main([str(a) for a in argv]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    for w in words:
        assert w in err, err


def test_an_output_that_is_an_input_is_refused_and_the_input_kept(csv, tmp_path, capsys):
    before = csv.read_bytes()
    _refused(["predict", tmp_path / "m.pt", csv, "--out", csv], capsys, "is one of the inputs", "--out")
    _refused(["identify", csv, "--model", "linear", "--out", csv], capsys, "--out must end in .json")
    assert csv.read_bytes() == before


def test_a_folder_for_a_file_or_a_file_for_a_folder_is_refused(csv, tmp_path, capsys):
    _refused(["identify", csv, "--model", "linear", "--out", tmp_path], capsys, "--out must end in .json")
    (tmp_path / "x.json").mkdir()
    _refused(["identify", csv, "--model", "linear", "--out", tmp_path / "x.json"], capsys, "is a folder")
    _refused(["discover", csv, "--out", csv], capsys, "is a file; give a folder")
    _refused(["identify", csv, "--model", "linear", "--out", csv / "fit.json"], capsys, "inside the file")


def test_missing_folders_of_an_output_file_are_created(csv, tmp_path):
    out = tmp_path / "missing" / "deeper" / "fit.json"
    assert main(["identify", str(csv), "--model", "linear", "--out", str(out)]) == 0
    assert out.read_text().startswith("{")


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes anywhere")
def test_a_read_only_folder_is_refused_before_the_work(csv, tmp_path, capsys):
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    try:
        _refused(["identify", csv, "--model", "linear", "--out", locked / "fit.json"], capsys, "cannot be written")
    finally:
        locked.chmod(0o700)


def test_a_good_output_is_written(csv, tmp_path):
    assert main(["identify", str(csv), "--model", "linear", "--out", str(tmp_path / "fit.json")]) == 0
    assert (tmp_path / "fit.json").read_text().startswith("{")


def test_a_model_folder_over_the_data_folder_is_refused(csv, tmp_path, capsys):
    """It was written there: the runs mixed with the model's files, the data folder a model folder."""
    before = sorted(p.name for p in csv.parent.iterdir())
    _refused(["fit", csv, "--physics", "linear", "--residual", "none", "--out", csv.parent], capsys,
             f"--out '{csv.parent}' holds input files ('a.csv')", "a folder of its own")
    assert sorted(p.name for p in csv.parent.iterdir()) == before
