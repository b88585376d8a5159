"""The documentation: the site builds with no warning, and the code of the README and of every
docs page runs as written.

``bash`` blocks run in a temporary folder with the project's ``hyst`` and ``python`` on the PATH
(the catheter examples skip where the shared data is absent; ``make`` and ``pip install`` blocks
are what CI and PyPI do), ``python`` blocks as scripts (a page's together, in order); ``text``
blocks are file formats, not code.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
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


DOCS = sorted((ROOT / "docs").glob("*.md"))


def _skip_reason(kind: str, code: str) -> str | None:
    if kind == "text":
        return "a file format, not code"
    if kind == "bash" and code.lstrip().startswith("make "):
        return "`make demo` and `make test` are what CI runs"
    if kind == "bash" and code.lstrip().startswith("pip install"):
        return "installing from PyPI needs the network; the wheel's contents are checked in test_packaging"
    if "data_root()" in code:
        from physics.data import DataNotFoundError, data_root

        try:
            data_root()
        except DataNotFoundError as exc:
            return f"the example reads the shared catheter data, which is absent: {exc}"
    return None


def _run(kind: str, code: str, tmp_path: Path, where: str) -> None:
    command = ["bash", "-euo", "pipefail", "-c", code] if kind == "bash" else [sys.executable, "-c", code]
    proc = subprocess.run(command, cwd=tmp_path, capture_output=True, text=True, env=_env(tmp_path), timeout=600)
    assert proc.returncode == 0, f"{where} ({kind}) failed:\n{code}\n{proc.stdout[-2000:]}\n{proc.stderr[-3000:]}"


@pytest.mark.slow
@pytest.mark.parametrize("index", range(len(blocks(README))))
def test_readme_code_runs(index, tmp_path):
    kind, code = blocks(README)[index]
    reason = _skip_reason(kind, code)
    if reason:
        pytest.skip(reason)
    _run(kind, code, tmp_path, f"README block {index}")


@pytest.mark.slow
@pytest.mark.parametrize("page", [p for p in DOCS if any(k in ("bash", "python") for k, _ in blocks(p))],
                         ids=lambda p: p.stem)
def test_docs_code_runs(page, tmp_path):
    """A page's blocks run in order in one folder, as a reader follows them; its python blocks as one
    script (a later block uses what an earlier one made)."""
    ran, python = 0, []
    readme = {code for kind, code in blocks(README) if kind == "bash"}
    for index, (kind, code) in enumerate(blocks(page)):
        if _skip_reason(kind, code) or (kind == "bash" and code in readme):  # test_readme_code_runs runs it
            continue
        if kind == "python":
            python.append(code)
        else:
            _run(kind, code, tmp_path, f"{page.name} block {index}")
        ran += 1
    if python:
        _run("python", "\n".join(python), tmp_path, f"{page.name} python blocks")
    if not ran:
        pytest.skip(f"{page.name}: every block needs what is absent here (data, network), is not code, or is a "
                    "README block (test_readme_code_runs runs those)")
