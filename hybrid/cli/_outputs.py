"""Where a command writes, checked before any work: never over an input, never where it cannot.

Each command says what its ``--out`` is (``out_kind``: ``"file"`` with the suffixes it takes,
or ``"dir"``); :func:`check_out` refuses an output that is one of the command's inputs, a
folder given for a file (or the reverse), a missing or read-only parent folder, or a wrong
suffix, in the CLI's own words. A model folder written by ``hyst fit`` (holding ``card.json``) is one
unit: no command but ``hyst fit`` writes inside one it reads, and none writes over a file of one
(a file its card lists, or one of another kind than the command writes).
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["check_out", "check_model_folder_out", "check_out_folder", "inputs_of", "writable"]

#: Commands whose output is a model folder: they replace one whole (``hyst fit``).
WRITES_MODEL_FOLDERS = ("fit",)


def _argument_paths(args):
    """Every non-empty path-like value of an argument other than ``--out`` (lists walked)."""
    def visit(value):
        if isinstance(value, (list, tuple)):
            for v in value:
                yield from visit(v)
        elif isinstance(value, (str, os.PathLike)) and str(value):
            yield Path(value)

    for key, value in vars(args).items():
        if key not in ("out", "func", "command"):
            yield from visit(value)


def inputs_of(args) -> list[Path]:
    """Every existing file named by an argument other than ``--out``."""
    return [path.resolve() for path in _argument_paths(args) if path.is_file()]


def check_out(args, error) -> None:
    """Raise ``error(message)`` when ``args.out`` cannot or must not be written."""
    kind = getattr(args, "out_kind", None)
    out = getattr(args, "out", None)
    if kind is None or out is None:
        return
    check_model_folder_out(args, out, "--out", error)
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
        _check_model_file(args, path, out, error)
        parent = path.parent if str(path.parent) else Path(".")
        ancestor = parent  # missing folders are created on writing
        while not ancestor.exists():
            ancestor = ancestor.parent
        if not ancestor.is_dir():
            raise error(f"--out '{out}' is inside the file '{ancestor}'; give a path in a folder.")
        if not writable(ancestor):
            raise error(f"--out '{out}' cannot be written: the folder '{ancestor}' is not writable; choose another "
                        "place.")
        if path.exists() and not os.access(path, os.W_OK):
            raise error(f"--out '{out}' cannot be written (no permission); choose another place.")
    else:
        if path.exists() and not path.is_dir():
            raise error(f"--out '{out}' is a file; give a folder (it is created if missing).")
        ancestor = path
        while not ancestor.exists():
            ancestor = ancestor.parent
        if ancestor.is_file():
            raise error(f"--out '{out}' is inside the file '{ancestor}'; give a folder path.")
        if ancestor == path and getattr(args, "command", None) in WRITES_MODEL_FOLDERS:
            ancestor = path.resolve().parent  # a model folder is written beside it, then swapped in
            inside = [p for p in inputs_of(args) if path.resolve() in p.parents]
            if inside:  # the data folder would become a model folder, its runs mixed with the model's files
                raise error(f"--out '{out}' holds input files ('{inside[0].name}'); a model folder is one unit "
                            "written by `hyst fit`: give a folder of its own (it is created if missing).")
        if not writable(ancestor):
            raise error(f"--out '{out}' cannot be written: the folder '{ancestor}' is not writable; choose another "
                        "folder.")


def writable(folder: Path) -> bool:
    """Whether a file can be created in ``folder``: a probe file is made there and removed. ``os.access``
    is no test (always True for root, blind to read-only mounts and to /proc or /sys)."""
    import tempfile

    try:
        fd, probe = tempfile.mkstemp(prefix=".hyst-probe-", dir=folder)
    except OSError:
        return False
    os.close(fd)
    try:
        os.unlink(probe)
    except OSError:
        pass
    return True


def check_out_folder(option: str, value, what: str, error) -> None:
    """Raise ``error(message)`` when the folder ``value`` (of ``option``, for ``what``) cannot be written:
    a file, inside a file, or in a folder where no file can be created."""
    path = Path(value)
    if path.exists() and not path.is_dir():
        raise error(f"{option} '{value}' is a file; give a folder for {what} (it is created if missing).")
    ancestor = path
    while not ancestor.exists():
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        raise error(f"{option} '{value}' is inside the file '{ancestor}'; give a folder path.")
    if not writable(ancestor):
        raise error(f"{option} '{value}' cannot be written: the folder '{ancestor}' is not writable; choose another "
                    "folder.")


def model_folders_read(args) -> list[Path]:
    """The model folders (holding ``card.json``) an argument other than ``--out`` names, or names a file of."""
    from hybrid.export._load import MODEL_DIR_MANIFEST

    found = []
    for path in _argument_paths(args):
        folder = path if path.is_dir() else path.parent if path.is_file() else None
        if folder is not None and (folder / MODEL_DIR_MANIFEST).is_file():
            found.append(folder.resolve())
    return found


def check_model_folder_out(args, out, option: str, error) -> None:
    """Raise ``error(message)`` when ``out`` (the value of ``option``) lies in a model folder the command reads."""
    if getattr(args, "command", None) in WRITES_MODEL_FOLDERS or out is None:
        return
    where = Path(os.path.abspath(out))
    where = where.parent.resolve() / where.name  # a link in the parents leads to the folder it names
    for folder in model_folders_read(args):
        if where == folder or folder in where.parents:
            raise error(f"{option} '{out}' is inside the model folder '{folder}' this command reads; its files are "
                        "one unit written by `hyst fit`. Write outside it.")


def _check_model_file(args, path: Path, out, error) -> None:
    """Refuse writing over a file of a model folder: one its ``card.json`` lists (the model's own), or one
    of another kind than the command writes (``out_suffixes``)."""
    from hybrid.export._load import MODEL_DIR_MANIFEST, model_folder_of

    if getattr(args, "command", None) in WRITES_MODEL_FOLDERS or not path.is_file():
        return
    folder = model_folder_of(path.parent)
    if folder is None:
        return
    name = path.resolve().relative_to(folder.resolve()).as_posix() if folder.resolve() in path.resolve().parents \
        else path.name
    try:
        import json

        listed = json.loads((folder / MODEL_DIR_MANIFEST).read_text()).get("files") or {}
    except (OSError, ValueError, AttributeError):
        listed = {}
    own = path.suffix in getattr(args, "out_suffixes", ())
    if name in listed or name == MODEL_DIR_MANIFEST or not own:
        raise error(f"--out '{out}' is a file of the model folder '{folder}' (written by `hyst fit`, one unit); "
                    "writing it would break the model. Choose another file.")
