"""The documentation: the site builds with no warning, and the README's code runs as written.

The README's ``bash`` blocks run in a temporary folder with the project's ``hyst`` and ``python``
on the PATH (the catheter example skips where the shared data is absent), its ``python`` blocks
as scripts; ``text`` blocks are file formats, not code.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
MAX_README_LINES = 120


def blocks(path: Path) -> list[tuple[str, str]]:
    return re.findall(r"^```(\w+)\n(.*?)^```", path.read_text(), flags=re.S | re.M)


def _env(tmp_path: Path) -> dict:
    bin_dir = str(Path(sys.executable).parent)
    return {**os.environ, "PATH": os.pathsep.join([bin_dir, os.environ.get("PATH", "")]), "MPLBACKEND": "Agg",
            "TMPDIR": str(tmp_path), "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))}


def test_readme_is_a_front_door():
    lines = README.read_text().splitlines()
    assert len(lines) <= MAX_README_LINES, f"README.md has {len(lines)} lines; keep it to {MAX_README_LINES}"
    kinds = {kind for kind, _ in blocks(README)}
    assert kinds <= {"bash", "python", "text"}, kinds


@pytest.mark.slow
def test_the_site_builds_strictly(tmp_path):
    pytest.importorskip("mkdocs", reason="the docs extra is not installed: pip install -e '.[docs]'")
    proc = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "-q", "-d", str(tmp_path / "site")],
                          cwd=ROOT, capture_output=True, text=True, env={**os.environ, "NO_MKDOCS_2_WARNING": "1"})
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert (tmp_path / "site" / "api" / "export" / "index.html").is_file()


@pytest.mark.slow
@pytest.mark.parametrize("index", range(len(blocks(README))))
def test_readme_code_runs(index, tmp_path):
    kind, code = blocks(README)[index]
    if kind == "text":
        pytest.skip("a file format, not code")
    if kind == "bash" and code.lstrip().startswith("make "):
        pytest.skip("`make demo` and `make test` are what CI runs")
    if kind == "bash" and code.lstrip().startswith("pip install"):
        pytest.skip("installing from PyPI needs the network; the wheel's contents are checked in test_packaging")
    if "data_root()" in code:
        from physics.data import DataNotFoundError, data_root

        try:
            data_root()
        except DataNotFoundError as exc:
            pytest.skip(f"the example reads the shared catheter data, which is absent: {exc}")
    command = ["bash", "-euo", "pipefail", "-c", code] if kind == "bash" else [sys.executable, "-c", code]
    proc = subprocess.run(command, cwd=tmp_path, capture_output=True, text=True, env=_env(tmp_path), timeout=600)
    assert proc.returncode == 0, f"README block {index} ({kind}) failed:\n{code}\n{proc.stdout[-2000:]}\n{proc.stderr[-3000:]}"
