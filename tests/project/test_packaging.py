"""Packaging: one version, the files a wheel must carry, output folders, no compiler litter."""

from __future__ import annotations

import importlib.metadata
import os
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

import hybrid
from hybrid.cli._main import main

ROOT = Path(__file__).resolve().parents[2]


def test_version_has_one_source(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["--version"])
    assert exit_.value.code == 0
    assert capsys.readouterr().out.strip() == f"hyst {importlib.metadata.version('hysteresis-hybrid')}"
    assert hybrid.__version__ == importlib.metadata.version("hysteresis-hybrid")


@pytest.mark.slow
def test_the_wheel_carries_license_type_markers_and_the_ablation_configs(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q",
                           "-w", str(tmp_path), str(ROOT)], capture_output=True, text=True,
                          cwd=tmp_path, env={**os.environ, "PIP_DISABLE_PIP_VERSION_CHECK": "1"})
    assert proc.returncode == 0, proc.stderr[-2000:]
    wheel, = tmp_path.glob("hysteresis_hybrid-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    assert any(n.endswith(".dist-info/licenses/LICENSE") or n.endswith(".dist-info/LICENSE") for n in names), names
    assert {"physics/py.typed", "identification/py.typed", "hybrid/py.typed"} <= names
    configs = {n for n in names if n.startswith("hybrid/experiments/ablation/configs/")}
    assert {f"hybrid/experiments/ablation/configs/{c}.toml" for c in ("tiny", "buffer_length", "lstm_sequence",
                                                                       "hybrid_vs_pure")} <= configs
    metadata = zipfile.ZipFile(wheel).read(next(n for n in names if n.endswith(".dist-info/METADATA"))).decode()
    assert "Classifier: Intended Audience :: Science/Research" in metadata and "Project-URL: Source" in metadata


def test_out_creates_missing_folders_and_refuses_a_file_parent(tmp_path, capsys):
    out = tmp_path / "new" / "dir" / "step.casadi"
    assert main(["export", "lag+linear", "--out", str(out)]) == 0
    assert out.is_file() and out.with_suffix(".casadi.json").is_file()
    (tmp_path / "afile").write_text("x")
    assert main(["export", "lag+linear", "--out", str(tmp_path / "afile" / "step.casadi")]) == 2
    assert "inside the file" in capsys.readouterr().err


def test_compiled_functions_leave_no_sources_in_the_temp_folder(tmp_path):
    from identification._sensitivity import jit_available

    if not jit_available():
        pytest.skip("no C compiler: nothing is compiled")
    code = ("import casadi as ca\n"
            "from identification._sensitivity import _compiled\n"
            "x = ca.SX.sym('x')\n"
            "f = _compiled('square', [x], [x * x + ca.sin(x)])\n"
            "assert abs(float(f(2.0)) - 4.909297426825682) < 1e-12\n")
    env = {**os.environ, "TMPDIR": str(tmp_path), "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT),
                                                                                             os.environ.get("PYTHONPATH")]))}
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert sorted(p.name for p in tmp_path.iterdir()) == [], "compiled functions left files in the temp folder"
