"""A model folder is one unit (#42): a fit writes it beside the old one and swaps it in whole, so an
interrupted fit leaves the previous folder as it was; no command writes inside a folder it reads or over
one of its files; card.json and stages.json are checked against their schemas, and every file against
the SHA-256 the card lists, with one line naming the file and the field."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from hybrid.cli import main
from hybrid.export import load
from hybrid.export._load import ExportError
from physics import Series
from physics.data import Trajectory

DT = 0.04
FIT = ["--physics", "linear", "--residual", "none", "--no-progress"]


def _run(seed: int, n: int = 200) -> Trajectory:
    t = np.arange(n) * DT
    u = 2.0 + 1.5 * np.sin(2 * np.pi * t / (n * DT / 3) + seed)
    truth = Series.from_spec("lag+linear", dt=DT).set_params(**{"linear.gain": 8.0})
    y = truth.simulate(u) + np.random.default_rng(seed).normal(0, 0.05, n)
    return Trajectory(t, u, y, source=f"run{seed}.csv")


@pytest.fixture(scope="module")
def csvs(tmp_path_factory):
    where = tmp_path_factory.mktemp("runs")
    return [str(_run(i).to_csv(where / f"run{i}.csv")) for i in range(2)]


@pytest.fixture(scope="module")
def model(csvs, tmp_path_factory):
    out = tmp_path_factory.mktemp("fit") / "model"
    assert main(["fit", *csvs, *FIT, "--out", str(out)]) == 0
    return out


def _snapshot(folder: Path) -> dict[str, bytes]:
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def _copy(folder: Path, to: Path) -> Path:
    import shutil

    shutil.copytree(folder, to)
    return to


def _one_line(capsys, *words) -> str:
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    for w in words:
        assert w in err, err
    return err


def test_an_interrupted_fit_leaves_the_previous_folder_as_it_was(model, csvs, tmp_path, monkeypatch, capsys):
    folder = _copy(model, tmp_path / "model")
    before = _snapshot(folder)
    (folder / "notes.txt").write_text("mine\n")  # someone else's file in the folder
    before["notes.txt"] = b"mine\n"

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    import hybrid.experiments._fit as fit

    monkeypatch.setattr(fit, "write_card", interrupted)  # the last stage, after every model file is new
    other = str(_run(7).to_csv(tmp_path / "other.csv"))  # other data: every stage runs again
    assert main(["fit", other, *csvs, *FIT, "--out", str(folder)]) == 130
    assert _snapshot(folder) == before  # byte-identical, not a mix of new and old files
    assert sorted(p.name for p in tmp_path.iterdir()) == ["model", "other.csv"]  # no staging folder left
    load(folder)  # and still a valid model

    monkeypatch.undo()
    assert main(["fit", other, *csvs, *FIT, "--out", str(folder)]) == 0  # the same fit, not interrupted
    card = json.loads((folder / "card.json").read_text())
    assert {r["run"] for r in card["rows"]} == {"other", "run0", "run1"}
    assert (folder / "notes.txt").read_text() == "mine\n"  # carried into the new folder, not a model file
    assert "notes.txt" not in card["files"] and "step.casadi" in card["files"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["model", "other.csv"]


def test_resume_reuses_the_finished_stages_with_their_files(model, csvs, tmp_path, capsys):
    folder = _copy(model, tmp_path / "model")
    step = (folder / "step.casadi").read_bytes()
    capsys.readouterr()
    assert main(["fit", *csvs, *FIT, "--out", str(folder), "--resume"]) == 0
    assert "(reused: physics, identify, residual, intervals, export)" in capsys.readouterr().out
    assert (folder / "step.casadi").read_bytes() == step and (folder / "intervals.json").is_file()
    load(folder)  # the new card lists the copied files
    # a reused stage's file that differs from the one it wrote is not reused: its stage runs again
    (folder / "intervals.json").write_text("{}")
    assert main(["fit", *csvs, *FIT, "--out", str(folder), "--resume"]) == 0
    assert "(reused: physics, identify, residual, export)" in capsys.readouterr().out
    load(folder)


def test_no_command_writes_inside_a_model_folder_it_reads(model, csvs, tmp_path, capsys):
    before = _snapshot(model)
    assert main(["export", str(model), "--warmup", "3", "--out", str(model / "step.casadi")]) == 2
    _one_line(capsys, "--out", "inside the model folder")
    assert main(["export", str(model), "--out", str(tmp_path / "s.casadi"), "--c-code", str(model / "c")]) == 2
    _one_line(capsys, "--c-code", "inside the model folder")
    assert main(["predict", str(model), csvs[0], "--out", str(model / "pred.csv")]) == 2
    _one_line(capsys, "inside the model folder")
    assert main(["simulate", "--out", str(model / "physics.json")]) == 2  # CSV over a model file
    _one_line(capsys, "is a file of the model folder")
    assert main(["identify", csvs[0], "--model", "linear", "--out", str(model / "physics.json")]) == 2
    _one_line(capsys, "is a file of the model folder")  # its own kind, but the card lists it
    assert _snapshot(model) == before
    assert main(["export", str(model), "--out", str(tmp_path / "s.casadi")]) == 0  # outside: fine


def test_mpc_into_the_same_folder_keeps_no_stale_figure(model, tmp_path):
    out = tmp_path / "mpc"
    common = ["mpc", "--model", str(model), "--out", str(out), "--duration", "2", "--horizon", "5"]
    assert main(common) == 0 and (out / "closed_loop.png").is_file()
    assert main([*common, "--no-figures"]) == 0
    assert not (out / "closed_loop.png").exists()


@pytest.mark.parametrize("edit, words", [
    (lambda c: c.update(rate_hz="fast"), ["card.json", "rate_hz is 'fast'", "a number > 0 or null"]),
    (lambda c: c.update(rate_hz=float("nan")), ["card.json", "rate_hz"]),
    (lambda c: c.update(columns=["time"]), ["card.json", "columns is ['time']"]),
    (lambda c: c.update(model={"file": "physics.json"}), ["card.json", "model is"]),
    (lambda c: c.pop("model"), ["card.json", "'model' is a required property"]),
])
def test_a_card_of_the_wrong_shape_is_refused_in_one_line(model, csvs, tmp_path, capsys, edit, words):
    folder = _copy(model, tmp_path / "model")
    card = json.loads((folder / "card.json").read_text())
    edit(card)
    (folder / "card.json").write_text(json.dumps(card))
    for argv in (["predict", str(folder), csvs[0], "--out", str(tmp_path / "p.csv")],
                 ["export", str(folder), "--out", str(tmp_path / "s.casadi")]):
        assert main(argv) == 2
        _one_line(capsys, *words)
    (folder / "card.json").write_text("[1, 2]")
    with pytest.raises(ExportError, match="card.json': the file is \\[1, 2\\]; it must be an object"):
        load(folder)


def test_stages_of_the_wrong_shape_are_refused_in_one_line(model, csvs, tmp_path, capsys):
    folder = _copy(model, tmp_path / "model")
    stages = json.loads((folder / "stages.json").read_text())
    stages["intervals"]["result"] = [1]
    (folder / "stages.json").write_text(json.dumps(stages))
    assert main(["fit", *csvs, *FIT, "--out", str(folder), "--resume"]) == 2
    _one_line(capsys, "stages.json", "intervals.result is [1]")
    (folder / "stages.json").write_text(json.dumps({"physics": "done"}))
    assert main(["fit", *csvs, *FIT, "--out", str(folder), "--resume"]) == 2
    _one_line(capsys, "stages.json", "physics is 'done'")


def test_a_truncated_step_is_refused_in_one_line(model, csvs, tmp_path, capsys):
    folder = _copy(model, tmp_path / "model")
    data = (folder / "step.casadi").read_bytes()
    (folder / "step.casadi").write_bytes(data[:-1])  # one byte short: CasADi itself loads it
    for argv in (["mpc", "--model", str(folder / "step.casadi"), "--out", str(tmp_path / "mpc"), "--duration", "2",
                  "--horizon", "5", "--no-figures"],
                 ["predict", str(folder), csvs[0], "--out", str(tmp_path / "p.csv")]):
        assert main(argv) == 2
        _one_line(capsys, "step.casadi' is not the file `hyst fit` wrote")
    (folder / "step.casadi").unlink()
    with pytest.raises(ExportError, match="step.casadi' is missing from the model folder"):
        load(folder)


@pytest.mark.parametrize("started", [True, False])
def test_an_interrupt_while_the_c_library_compiles_beside_the_card_stops_the_compiler(tmp_path, monkeypatch,
                                                                                     started):
    """The folder's C library compiles on a thread while the card is written: a Ctrl-C (or an error) in the
    card stops that compiler and waits for its thread, so no compiler runs on and no scratch folder stays;
    also when it comes before the thread has started the compiler (the C still being generated)."""
    import shutil
    import tempfile
    import time

    from hybrid.experiments._fit import _while_compiling
    from identification._trace import in_background
    from physics.data.io import CompileError, run_compiler

    if not shutil.which("sh"):
        pytest.skip("needs a POSIX shell to stand in for the compiler")
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))  # where the compiler's scratch folder goes
    marker = tmp_path / "done"
    def generate_then_compile():
        time.sleep(0 if started else 0.5)  # the C generated first
        run_compiler(["sh", "-c", f"sleep 30; touch {marker}"], "a slow compile")

    compiling = in_background("compile C", generate_then_compile)
    t0 = time.monotonic()
    with pytest.raises(KeyboardInterrupt):
        with _while_compiling(({}, compiling)):
            time.sleep(0.3 if started else 0.0)  # the compiler runs, or not yet
            raise KeyboardInterrupt
    assert time.monotonic() - t0 < 5, "waited for the compiler to end by itself"
    assert compiling.done() and isinstance(compiling.exception(), CompileError)
    assert not marker.exists()
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith("hyst_cc_")] == []
