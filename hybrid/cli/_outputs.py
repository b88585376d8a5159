"""Where a command writes, checked before any work: never over an input, never where it cannot.

Each command says what its ``--out`` is (``out_kind``: ``"file"`` with the suffixes it takes,
or ``"dir"``); :func:`check_out` refuses an output that is one of the command's inputs, a
folder given for a file (or the reverse), a missing or read-only parent folder, or a wrong
suffix, in the CLI's own words.
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["check_out", "inputs_of"]


def inputs_of(args) -> list[Path]:
    """Every existing file named by an argument other than ``--out``."""
    found = []

    def visit(value):
        if isinstance(value, (list, tuple)):
            for v in value:
                visit(v)
        elif isinstance(value, (str, os.PathLike)) and str(value) and Path(value).is_file():
            found.append(Path(value).resolve())

    for key, value in vars(args).items():
        if key not in ("out", "func", "command"):
            visit(value)
    return found


def check_out(args, error) -> None:
    """Raise ``error(message)`` when ``args.out`` cannot or must not be written."""
    kind = getattr(args, "out_kind", None)
    out = getattr(args, "out", None)
    if kind is None or out is None:
        return
    if kind == "file" and getattr(args, "paper_dataset", False):
        kind = "dir"
    path = Path(out)
    if kind == "file":
        suffixes = getattr(args, "out_suffixes", ())
        if suffixes and path.suffix not in suffixes:
            raise error(f"--out must end in {' or '.join(suffixes)}; got '{out}'.")
        if path.is_dir():
            raise error(f"--out '{out}' is a folder; give a file path such as '{path / ('out' + suffixes[0])}'."
                        if suffixes else f"--out '{out}' is a folder; give a file path.")
        inputs = inputs_of(args)
        if path.exists() and path.resolve() in inputs:
            raise error(f"--out '{out}' is one of the inputs; writing it would destroy them. Choose another file.")
        sidecar = path.with_suffix(".json")
        if path.suffix == ".pt" and sidecar.exists() and sidecar.resolve() in inputs:
            raise error(f"--out '{out}' would overwrite '{sidecar}', one of the inputs. Choose another file.")
        parent = path.parent if str(path.parent) else Path(".")
        ancestor = parent  # missing folders are created on writing
        while not ancestor.exists():
            ancestor = ancestor.parent
        if not ancestor.is_dir():
            raise error(f"--out '{out}' is inside the file '{ancestor}'; give a path in a folder.")
        if not os.access(ancestor, os.W_OK) or (path.exists() and not os.access(path, os.W_OK)):
            raise error(f"--out '{out}' cannot be written (no permission); choose another place.")
    else:
        if path.exists() and not path.is_dir():
            raise error(f"--out '{out}' is a file; give a folder (it is created if missing).")
        if path.exists() and not os.access(path, os.W_OK):
            raise error(f"--out '{out}' cannot be written (no permission); choose another folder.")
        ancestor = path
        while not ancestor.exists():
            ancestor = ancestor.parent
        if ancestor.is_file():
            raise error(f"--out '{out}' is inside the file '{ancestor}'; give a folder path.")
        if not os.access(ancestor, os.W_OK):
            raise error(f"--out '{out}' cannot be created under '{ancestor}' (no permission).")
