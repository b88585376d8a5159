"""Atomic writes: a result file is either complete or absent, never half written."""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import tempfile
from pathlib import Path


@contextlib.contextmanager
def atomic_path(path):
    """Yield a temporary path beside ``path``; on success it replaces ``path``.

    >>> with atomic_path("out.csv") as tmp:  # doctest: +SKIP
    ...     np.savetxt(tmp, data)
    """
    with atomic_paths(path) as (tmp,):
        yield tmp


@contextlib.contextmanager
def atomic_paths(*paths):
    """Yield one temporary path beside each of ``paths``; on success they replace their targets
    together: all of them, or (when a replace fails) none, the old files put back.

    >>> with atomic_paths("m.pt", "m.json") as (pt, js):  # doctest: +SKIP
    ...     torch.save(blob, pt); js.write_text(meta)
    """
    paths = [Path(p) for p in paths]
    tmps: list[Path] = []
    try:
        for path in paths:
            path.parent.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
            os.close(fd)
            os.chmod(tmp, _new_file_mode(path))  # mkstemp makes 0600; results are read like any file
            tmps.append(Path(tmp))
        yield tuple(tmps)
        for tmp in tmps:
            with open(tmp, "rb+") as fh:  # on disk before it takes the final name
                os.fsync(fh.fileno())
        _replace_all(tmps, paths)
    finally:
        for tmp in tmps:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(tmp)


def _replace_all(tmps: list[Path], paths: list[Path]) -> None:
    """``os.replace`` each temporary file onto its target; if one fails, undo the ones done."""
    if len(paths) == 1:
        os.replace(tmps[0], paths[0])
        return
    backups: list[Path | None] = []
    try:
        for path in paths:
            backups.append(_backup(path))
        done = []
        try:
            for tmp, path in zip(tmps, paths):
                os.replace(tmp, path)
                done.append(path)
        except BaseException:
            for path, backup in zip(done, backups):
                if backup is not None:
                    os.replace(backup, path)
                else:
                    with contextlib.suppress(FileNotFoundError):
                        os.unlink(path)
            raise
    finally:
        for backup in backups:
            if backup is not None:
                with contextlib.suppress(FileNotFoundError):
                    os.unlink(backup)


def _backup(path: Path) -> Path | None:
    """A second name for the current ``path`` (a hard link, else a copy), or None if it does not exist."""
    if not path.exists():
        return None
    fd, name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".bak", dir=path.parent)
    os.close(fd)
    os.unlink(name)
    try:
        os.link(path, name)
    except OSError:
        shutil.copy2(path, name)
    return Path(name)


def _new_file_mode(path: Path) -> int:
    """The mode the file would get from ``open(path, "w")``: an existing file's own, else 0666 less the umask."""
    try:
        return path.stat().st_mode & 0o777
    except FileNotFoundError:
        umask = os.umask(0)
        os.umask(umask)
        return 0o666 & ~umask


def write_text(path, text: str) -> Path:
    with atomic_path(path) as tmp:
        tmp.write_text(text)
    return Path(path)


def write_json(path, obj) -> Path:
    return write_text(path, json.dumps(obj, indent=2, sort_keys=False) + "\n")
