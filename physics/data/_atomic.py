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


@contextlib.contextmanager
def atomic_folder(path, carry=None):
    """Yield a new empty folder beside ``path`` (``.NAME.staging-PID``); on success it replaces ``path``
    whole, on any exception (Ctrl-C too) it is removed and ``path`` is left as it was: a reader sees
    the old folder or the new one, never a mix.

    ``carry(name) -> bool`` picks entries of the old folder the new one takes over (linked or copied)
    when it holds none of that name: files someone else put there. Leftovers of a process that died
    mid-way (killed) are removed on the next call.

    >>> with atomic_folder("model") as tmp:  # doctest: +SKIP
    ...     (tmp / "a.json").write_text("{}"); (tmp / "b.json").write_text("{}")
    """
    real = Path(os.path.realpath(path))  # a link to a folder: the folder it names is replaced
    if real.exists() and not real.is_dir():
        raise NotADirectoryError(20, "a file is in the way of the folder", str(path))
    real.parent.mkdir(parents=True, exist_ok=True)
    _remove_leftovers(real)
    staging = real.parent / f".{real.name}.staging-{os.getpid()}"
    shutil.rmtree(staging, ignore_errors=True)
    staging.mkdir()
    try:
        if real.is_dir():
            os.chmod(staging, real.stat().st_mode & 0o7777)
        yield staging
        if real.is_dir() and carry is not None:
            for entry in real.iterdir():
                if carry(entry.name) and not (staging / entry.name).exists():
                    if entry.is_dir() and not entry.is_symlink():
                        shutil.copytree(entry, staging / entry.name, symlinks=True, copy_function=_link_or_copy)
                    else:
                        _link_or_copy(entry, staging / entry.name)
        _swap_in(staging, real)
    finally:
        shutil.rmtree(staging, ignore_errors=True)  # gone already when it was swapped in


def _swap_in(new: Path, real: Path) -> None:
    """Rename ``real`` away, ``new`` to ``real``, delete the old one; put the old back if the second fails."""
    old = None
    if real.exists():
        old = real.parent / f".{real.name}.old-{os.getpid()}"
        shutil.rmtree(old, ignore_errors=True)
        os.rename(real, old)
    try:
        os.rename(new, real)
    except BaseException:
        if old is not None:
            os.rename(old, real)
        raise
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


def _remove_leftovers(real: Path) -> None:
    """Staging and old folders of ``real`` left by processes no longer running."""
    for kind in ("staging", "old"):
        prefix = f".{real.name}.{kind}-"
        for entry in real.parent.iterdir() if real.parent.is_dir() else ():
            pid = entry.name[len(prefix):]
            if entry.name.startswith(prefix) and pid.isdigit() and not _running(int(pid)):
                shutil.rmtree(entry, ignore_errors=True)


def _running(pid: int) -> bool:
    if pid == os.getpid():
        return False  # our own leftover from an earlier call
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:
        return True  # someone else's process
    return True


def _link_or_copy(src, dst) -> None:
    try:
        os.link(src, dst)
    except OSError:
        shutil.copy2(src, dst)


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
