"""Saved files a careless user hands to `hyst`: mismatched checkpoint pairs, .casadi files that
would run native code, corrupt or hand-edited files, a folder named '-v'. Each is refused with
one line naming the file (and the flag), never a traceback, and the files are left as they were."""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from hybrid.cli._main import main
from hybrid.export import ExportError, ExportedModel, export_model, load
from physics import Series
from physics.data import DataError
from physics.data._atomic import atomic_paths

from _cli import refused


def digest(folder: Path) -> dict:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.iterdir()) if p.is_file()}


@pytest.fixture(scope="module")
def two_models(tmp_path_factory, run_csv):
    """Two FNN checkpoints trained with different seeds."""
    root = tmp_path_factory.mktemp("models")
    for seed in (0, 1):
        assert main(["train", str(run_csv), "--model", "fnn", "--epochs", "1", "--seed", str(seed),
                     "--validation", "0", "--out", str(root / f"m{seed}.pt")]) == 0
    return root


# ------------------------------------------------------------------------- defect 5
def test_a_checkpoint_with_another_models_sidecar_is_refused(two_models, run_csv, tmp_path, capsys):
    for suffix in (".pt", ".json"):
        shutil.copy(two_models / f"m0{suffix}", tmp_path / f"m{suffix}")
    shutil.copy(two_models / "m1.json", tmp_path / "m.json")  # the sidecar of another model
    before = digest(tmp_path)
    refused(["predict", tmp_path / "m.pt", run_csv, "--out", tmp_path / "p.csv"], capsys,
            "m.json does not belong to", "m.pt", "were not written together")
    refused(["export", tmp_path / "m.pt", "--out", tmp_path / "m.casadi"], capsys, "does not belong to")
    from hybrid.learning import LearnedModel

    with pytest.raises(DataError, match="does not belong to"):
        LearnedModel.load(tmp_path / "m.pt")
    assert digest(tmp_path) == before
    # the pair written together loads, and both files carry the same id
    import torch

    blob = torch.load(two_models / "m0.pt", weights_only=True)
    assert blob["pair_id"] == json.loads((two_models / "m0.json").read_text())["pair_id"]
    assert LearnedModel.load(two_models / "m0.pt").n_features_in_ >= 1


def test_the_same_model_saved_twice_gets_the_same_pair_id(two_models, tmp_path):
    from hybrid.learning import LearnedModel

    model = LearnedModel.load(two_models / "m0.pt")
    model.save(tmp_path / "again.pt")
    assert json.loads((tmp_path / "again.json").read_text())["pair_id"] == \
        json.loads((two_models / "m0.json").read_text())["pair_id"]


def test_a_pair_is_written_whole_or_not_at_all(tmp_path, monkeypatch):
    a, b = tmp_path / "m.pt", tmp_path / "m.json"
    a.write_text("old pt")
    b.write_text("old json")
    real, calls = os.replace, []

    def flaky(src, dst):
        calls.append(dst)
        if str(dst).endswith(".json") and not str(src).endswith(".bak"):
            raise OSError(28, "No space left on device", str(dst))
        return real(src, dst)

    monkeypatch.setattr(os, "replace", flaky)
    with pytest.raises(OSError, match="No space"):
        with atomic_paths(a, b) as (ta, tb):
            ta.write_text("new pt")
            tb.write_text("new json")
    assert a.read_text() == "old pt" and b.read_text() == "old json"  # the first replace was undone
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.json", "m.pt"]  # no temporary left
    monkeypatch.setattr(os, "replace", real)
    with atomic_paths(a, b) as (ta, tb):
        ta.write_text("new pt")
        tb.write_text("new json")
    assert (a.read_text(), b.read_text()) == ("new pt", "new json")


# ------------------------------------------------------------------------- defect 6
EVIL = """
import casadi as ca, sys
from hybrid.export import ExportedModel
u0 = ca.SX.sym("u0")
base = ca.Function("base", [u0], [u0])
external = ca.external("step", sys.argv[1])
ExportedModel(step=external, state_names=("x",), x0_base=base, kind="physics").save(sys.argv[2])
"""


@pytest.fixture(scope="module")
def external_casadi(tmp_path_factory) -> Path:
    """A .casadi whose step is casadi.external of a library whose constructor leaves a mark (saved
    in a subprocess, so this process has never loaded the library)."""
    if shutil.which("gcc") is None:
        pytest.skip("gcc is not installed: cannot build the external library")
    root = tmp_path_factory.mktemp("evil")
    marker = root / "constructor_ran"
    x, u = ca.SX.sym("x"), ca.SX.sym("u")
    gen = ca.CodeGenerator("step.c")
    gen.add(ca.Function("step", [x, u], [x, 2 * u], ["x", "u"], ["x_next", "y"]))
    gen.generate(str(root) + "/")
    with open(root / "step.c", "a") as fh:
        fh.write(f'\n#include <stdio.h>\n__attribute__((constructor)) static void mark(void) '
                 f'{{ FILE *f = fopen("{marker}", "w"); if (f) fclose(f); }}\n')
    subprocess.run(["gcc", "-fPIC", "-shared", str(root / "step.c"), "-o", str(root / "libstep.so")], check=True)
    path = root / "evil.casadi"
    subprocess.run([sys.executable, "-c", EVIL, str(root / "libstep.so"), str(path)], check=True,
                   cwd=Path(__file__).resolve().parents[2])
    assert marker.exists()  # saving it ran the constructor (in the subprocess)
    marker.unlink()
    return path


def test_a_casadi_file_calling_an_external_library_is_refused(external_casadi, tmp_path, capsys):
    marker = external_casadi.parent / "constructor_ran"
    before = digest(external_casadi.parent)
    refused(["mpc", "--model", external_casadi, "--out", tmp_path / "mpc"], capsys,
            "evil.casadi", "calls an external library", "--allow-external")
    refused(["export", external_casadi, "--out", tmp_path / "o.casadi"], capsys, "--allow-external")
    with pytest.raises(ExportError, match="allow_external=True"):
        ExportedModel.load(external_casadi)
    assert not marker.exists() and digest(external_casadi.parent) == before
    assert not (tmp_path / "mpc").exists()


def test_allow_external_loads_a_trusted_external_function(external_casadi):
    model = load(external_casadi, allow_external=True)
    assert float(model.step(0.0, 1.5)[1]) == 3.0
    assert (external_casadi.parent / "constructor_ran").exists()  # its native code did run


def test_a_function_compiled_on_load_is_refused(tmp_path):
    x, u = ca.SX.sym("x"), ca.SX.sym("u")
    step = ca.Function("step", [x, u], [x, u], ["x", "u"], ["x_next", "y"])
    jit = ca.Function("step", [x, u], [x, u], ["x", "u"], ["x_next", "y"], {"jit": True, "compiler": "shell"}) \
        if shutil.which("gcc") else None
    base = ca.Function("base", [u], [u])
    plain = ExportedModel(step=step, state_names=("x",), x0_base=base).save(tmp_path / "plain.casadi")
    assert ExportedModel.load(plain).n_x == 1
    if jit is not None:
        path = ExportedModel(step=jit, state_names=("x",), x0_base=base).save(tmp_path / "jit.casadi")
        with pytest.raises(ExportError, match="compiled on load"):
            ExportedModel.load(path)


# ------------------------------------------------------------------------- defect 7
@pytest.mark.skipif(shutil.which("gcc") is None, reason="gcc is not installed")
def test_a_c_code_folder_named_like_a_gcc_option_is_a_folder(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["export", "linear", "--out", "step.casadi", "--c-code=-v"]) == 0
    assert (tmp_path / "-v" / "libstep.so").is_file() and (tmp_path / "-v" / "step.c").is_file()
    (tmp_path / "-o").write_text("a file")
    refused(["export", "linear", "--out", "step.casadi", "--c-code=-o"], capsys, "--c-code '-o' is a file")


# ------------------------------------------------------------------------- defects 8, 9
@pytest.fixture
def fit_json(tmp_path) -> Path:
    model = Series.from_spec("linear").set_params(**{"linear.gain": 10.0, "linear.offset": 30.0})
    path = tmp_path / "fit.json"
    path.write_text(json.dumps({"model": "linear", "dt": 0.04, "series": model.to_dict(),
                                "parameters": model.param_dict()}))
    return path


@pytest.mark.parametrize("edit, needles", [
    (lambda d: d["parameters"].pop("linear.gain"), ("has no value for linear.gain",)),
    (lambda d: d["parameters"].update({"linear.gain": float("nan")}), ("linear.gain", "NaN")),
    (lambda d: d["parameters"].update({"linear.gain": "abc"}), ("linear.gain", "'abc', not a number")),
    (lambda d: d["parameters"].update({"linear.slope": 1.0}), ("'linear.slope'",)),
    (lambda d: d["parameters"].update({"linear.gain": 11.0}), ("disagree on linear.gain",)),
    (lambda d: d["series"].update({"dt": "fast"}), ("does not describe a physics model",)),
])
def test_a_hand_edited_fit_is_refused_naming_file_and_parameter(fit_json, tmp_path, capsys, edit, needles):
    info = json.loads(fit_json.read_text())
    edit(info)
    fit_json.write_text(json.dumps(info))
    refused(["export", fit_json, "--out", tmp_path / "o.casadi"], capsys, "fit.json", *needles)
    assert not (tmp_path / "o.casadi").exists()


def test_the_fit_as_written_exports(fit_json, tmp_path):
    assert main(["export", str(fit_json), "--out", str(tmp_path / "o.casadi")]) == 0
    assert float(ExportedModel.load(tmp_path / "o.casadi").step(ca.DM.zeros(0), 1.0)[1]) == 40.0


@pytest.mark.parametrize("damage", ["truncate", "garbage", "empty"])
def test_a_corrupt_casadi_file_is_one_line(tmp_path, capsys, damage):
    path = export_model(Series.from_spec("lag+linear")).save(tmp_path / "m.casadi")
    text = path.read_text()
    path.write_text({"truncate": text[:len(text) // 2], "garbage": "hello world", "empty": ""}[damage])
    refused(["mpc", "--model", path, "--out", tmp_path / "mpc"], capsys, "m.casadi")
    side = tmp_path / "m.casadi.json"
    path.write_text(text)
    side.write_text(side.read_text()[:50])
    refused(["mpc", "--model", path, "--out", tmp_path / "mpc"], capsys, "m.casadi.json", "not valid JSON")


def test_a_corrupt_sidecar_names_the_file(two_models, tmp_path, run_csv, capsys):
    for suffix in (".pt", ".json"):
        shutil.copy(two_models / f"m0{suffix}", tmp_path / f"m{suffix}")
    (tmp_path / "m.json").write_text('{"format": "hysteresis-hybrid/learned-model", ')
    refused(["predict", tmp_path / "m.pt", run_csv, "--out", tmp_path / "p.csv"], capsys, "m.json", "not valid JSON")
    (tmp_path / "m.pt").write_bytes((two_models / "m0.pt").read_bytes()[:300])
    shutil.copy(two_models / "m0.json", tmp_path / "m.json")
    refused(["predict", tmp_path / "m.pt", run_csv, "--out", tmp_path / "p.csv"], capsys, "m.pt",
            "not a readable checkpoint")


def test_an_outlier_is_named_by_line_and_column(run_csv, tmp_path, capsys):
    lines = run_csv.read_text().splitlines()
    cells = lines[40].split(",")
    cells[2] = "1e30"
    lines[40] = ",".join(cells)
    bad = tmp_path / "bad.csv"
    bad.write_text("\n".join(lines) + "\n")
    for argv in (["identify", bad, "--model", "linear", "--out", tmp_path / "f.json"],
                 ["train", bad, "--model", "fnn", "--epochs", "1", "--out", tmp_path / "m.pt"],
                 ["discover", bad, "--out", tmp_path / "d"]):
        refused(argv, capsys, "bad.csv, line 41, column 'y': 1e30 is far outside the range")


def test_silent_acceptances_are_refused(run_csv, two_models, tmp_path, capsys):
    refused(["train", run_csv, "--physics", "", "--out", tmp_path / "m.pt"], capsys, "argument --physics: is empty")
    refused(["mpc", "--model", "linear", "--noise", "-1", "--out", tmp_path / "m"], capsys, "argument --noise")
    refused(["simulate", "--freq", "100", "--out", tmp_path / "s.csv"], capsys, "--freq 100 Hz is too fast")
    refused(["export", two_models / "m0.pt", "--mode", "carried", "--out", tmp_path / "o.casadi"], capsys,
            "--mode carried does not apply", "fnn")
    assert not any(tmp_path.iterdir())


def test_a_constant_input_is_warned_in_discover(tmp_path, capsys):
    t = np.arange(200) * 0.04
    path = tmp_path / "flat.csv"
    rng = np.random.default_rng(0)
    path.write_text("time,u,y\n" + "".join(f"{a},1.5,{b}\n" for a, b in zip(t, 30 + rng.standard_normal(200))))
    main(["discover", str(path), "--max-steps", "1", "--no-figures", "--out", str(tmp_path / "d")])
    err = capsys.readouterr().err
    assert "hyst discover: warning: " in err and "flat.csv" in err and "is constant" in err


def test_text_files_in_other_encodings_and_layouts(run_csv, tmp_path, capsys):
    latin = tmp_path / "latin.csv"
    latin.write_bytes("time,u,y\n0,1,2\n0.04,1,2\n# r\xe9sum\xe9\n".encode("latin-1"))
    refused(["identify", latin, "--out", tmp_path / "f.json"], capsys, "latin.csv is not UTF-8", "Latin-1")
    utf16 = tmp_path / "u16.csv"
    utf16.write_bytes(run_csv.read_text().encode("utf-16"))
    refused(["identify", utf16, "--out", tmp_path / "f.json"], capsys, "u16.csv is not UTF-8", "UTF-16")
    semi = tmp_path / "semi.csv"
    semi.write_text(run_csv.read_text().replace(",", ";"))
    refused(["identify", semi, "--out", tmp_path / "f.json"], capsys, "semi.csv separates its columns with ;")
    refused(["identify", tmp_path, "--out", tmp_path / "f.json"], capsys, "is a folder")


def test_mpc_reads_references_with_a_bom_or_semicolons(tmp_path):
    from hybrid.cli._commands.mpc import read_reference

    (tmp_path / "bom.csv").write_bytes("\ufeffreference\n40\n50.5\n".encode("utf-8"))
    (tmp_path / "semi.csv").write_text("time;reference\n0;40,5\n0,04;50\n")
    (tmp_path / "plain.txt").write_text("40\n\n50\n")
    assert read_reference(tmp_path / "bom.csv").tolist() == [40.0, 50.5]
    assert read_reference(tmp_path / "semi.csv").tolist() == [40.5, 50.0]
    assert read_reference(tmp_path / "plain.txt").tolist() == [40.0, 50.0]


def test_options_are_named_in_their_errors(tmp_path, capsys):
    refused(["simulate", "--seed", "-1", "--out", tmp_path / "s.csv"], capsys, "argument --seed", "'-1'")
    refused(["simulate", "--duration", "0", "--out", tmp_path / "s.csv"], capsys, "argument --duration")
    refused(["ablate", "x.toml", "--scheduler", "tcp://127.0.0.1:1", "--out", tmp_path / "a"], capsys,
            "--scheduler tcp://127.0.0.1:1", "no Dask scheduler answers")
    for command in (["fit", "a.csv"], ["compare", "--data", "virtual"]):
        refused([*command, "--scheduler", "tcp://127.0.0.1:1", "--out", tmp_path / "m"], capsys,
                "--scheduler tcp://127.0.0.1:1", "no Dask scheduler answers")
        refused([*command, "--scheduler", "nowhere", "--out", tmp_path / "m"], capsys, "not an address")
    assert not any(tmp_path.iterdir())


def test_a_corrupt_manifest_is_named_before_any_training(tmp_path, capsys):
    assert main(["simulate", "--paper-dataset", "--out", str(tmp_path / "d")]) == 0
    capsys.readouterr()
    (tmp_path / "d" / "manifest.json").write_text('{"files": [')
    refused(["reproduce", "--data", tmp_path / "d", "--out", tmp_path / "r"], capsys, "manifest.json is not valid JSON")
    assert not (tmp_path / "r").exists()


def test_a_checkpoint_whose_weights_were_changed_is_damaged(two_models, run_csv, tmp_path, capsys):
    import torch

    blob = torch.load(two_models / "m0.pt", weights_only=True)
    first = next(iter(blob["state_dict"]))
    blob["state_dict"][first] = blob["state_dict"][first] + 1.0  # pair_id left as it was
    torch.save(blob, tmp_path / "m.pt")
    shutil.copy(two_models / "m0.json", tmp_path / "m.json")
    refused(["predict", tmp_path / "m.pt", run_csv, "--out", tmp_path / "p.csv"], capsys, "m.pt is damaged")


def test_predict_uses_the_models_rate_and_refuses_another(two_models, run_csv, tmp_path, capsys):
    refused(["predict", two_models / "m0.pt", run_csv, "--rate", "10", "--out", tmp_path / "p.csv"], capsys,
            "--rate 10 Hz is not the 25 Hz")
    assert main(["predict", str(two_models / "m0.pt"), str(run_csv), "--out", str(tmp_path / "p.csv")]) == 0
    assert np.allclose(np.diff(np.loadtxt(tmp_path / "p.csv", delimiter=",", skiprows=1)[:, 0]), 0.04)


def test_an_mpc_horizon_longer_than_the_reference_is_refused_before_building(tmp_path, capsys):
    refused(["mpc", "--model", "linear", "--horizon", "100000", "--out", tmp_path / "m"], capsys,
            "--horizon 100000 is longer than the reference (501 samples)")
    refused(["mpc", "--model", "linear", "--duration", "0.01", "--out", tmp_path / "m"], capsys, "--duration 0.01 s")
