"""Write each notebook's ``.ipynb`` from its jupytext source (``NN_name.py``, percent format).

The ``.py`` files are the source; the ``.ipynb`` beside them are generated, without outputs,
for people who open Jupyter. Run after editing a notebook::

    .venv/bin/python notebooks/build.py            # rewrite every .ipynb
    .venv/bin/python notebooks/build.py --check    # exit 1 if any .ipynb is missing or stale

``tests/project/test_notebooks.py`` runs the same comparison.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import jupytext
import nbformat

HERE = Path(__file__).resolve().parent
#: Notebook sources: numbered jupytext scripts (this file and helpers are not notebooks).
PATTERN = "[0-9][0-9]_*.py"


def sources(folder: Path = HERE) -> list[Path]:
    """The notebooks' ``.py`` sources, in order."""
    return sorted(folder.glob(PATTERN))


def cells(nb: nbformat.NotebookNode) -> list[tuple[str, str]]:
    """What a reader sees: each cell's type and source."""
    return [(c.cell_type, c.source) for c in nb.cells]


def convert(source: Path) -> nbformat.NotebookNode:
    """The notebook of a jupytext ``.py`` source, without outputs.

    Cell ids are numbered (jupytext draws random ones), so a rebuild changes no byte.
    """
    nb = jupytext.read(source)
    for i, cell in enumerate(nb.cells):
        cell.id = f"cell-{i:02d}"
    return nb


def stale(source: Path) -> str | None:
    """Why the ``.ipynb`` beside ``source`` is out of date, or None when it is up to date."""
    target = source.with_suffix(".ipynb")
    if not target.is_file():
        return f"{target.name} is missing"
    committed = nbformat.read(target, as_version=4)
    if cells(committed) != cells(convert(source)):
        return f"{target.name} differs from {source.name}"
    if any(c.get("outputs") or c.get("execution_count") for c in committed.cells if c.cell_type == "code"):
        return f"{target.name} holds outputs; notebooks are committed without them"
    return None


def build(source: Path) -> Path:
    target = source.with_suffix(".ipynb")
    jupytext.write(convert(source), target, fmt="ipynb")
    return target


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--check", action="store_true", help="only check; exit 1 if any .ipynb is stale")
    args = parser.parse_args(argv)
    if args.check:
        problems = [p for p in map(stale, sources()) if p]
        for p in problems:
            print(f"{p}: run `python notebooks/build.py`", file=sys.stderr)
        return 1 if problems else 0
    for source in sources():
        print("wrote", build(source).relative_to(HERE.parent))
    return 0


if __name__ == "__main__":
    sys.exit(main())
