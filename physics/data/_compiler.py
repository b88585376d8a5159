"""The system C compiler, run so that Ctrl-C and SIGTERM stop it and leave no files behind.

CasADi's JIT (``casadi.Importer`` plugin ``shell``) calls the compiler through the C library's
``system()``, which ignores SIGINT in the calling process while the compiler runs: a Ctrl-C during
a compile was lost and the command ran on. Here the compiler is a child of our own, in its own
process group, and we wait for it in Python: a Ctrl-C or SIGTERM (raised, or recorded by
:func:`physics.data._interrupt.recording`) kills the whole group (driver, ``cc1``, ``as``) and
raises. The compiler's own temporary files go to a private folder that is removed in every case.
A compiler run by another thread (a library built while the command goes on) is stopped by
:func:`stop_compilers`, which the interrupted command calls before it waits for that thread.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import tempfile
import threading
from collections.abc import Sequence
from pathlib import Path

from ._atomic import atomic_path
from ._interrupt import raise_if_pressed

__all__ = ["CompileError", "find_compiler", "run_compiler", "stop_compilers", "compile_function", "load_function"]

#: How often (s) a running compiler is checked for a recorded Ctrl-C or SIGTERM.
POLL_S = 0.05

#: The compilers running now, in any thread (:func:`stop_compilers`).
_RUNNING: set[subprocess.Popen] = set()
_RUNNING_LOCK = threading.Lock()


class CompileError(RuntimeError):
    """The compiler is missing or failed (the message holds the command and its error output)."""


def find_compiler(compiler: str = "gcc") -> str | None:
    """The compiler's path, or None when it is not on the PATH."""
    return shutil.which(compiler)


def run_compiler(cmd: Sequence[str], what: str, cwd=None) -> None:
    """Run a compiler command to its end, or stop it on Ctrl-C / SIGTERM.

    The command runs in a new session (its own process group, which the terminal's Ctrl-C does
    not reach) with ``TMPDIR`` set to a private folder: an interrupt kills the group, removes the
    folder and raises (KeyboardInterrupt, or what the signal handler raised). A non-zero exit
    raises :class:`CompileError` naming ``what``."""
    cmd = [str(c) for c in cmd]
    scratch = tempfile.mkdtemp(prefix="hyst_cc_")
    proc = None
    try:
        proc = subprocess.Popen(cmd, cwd=cwd, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True, start_new_session=True,
                                env={**os.environ, "TMPDIR": scratch})
        with _RUNNING_LOCK:
            _RUNNING.add(proc)
        main = threading.current_thread() is threading.main_thread()
        while True:
            try:
                _, err = proc.communicate(timeout=POLL_S)
                break
            except subprocess.TimeoutExpired:
                if main:  # a press recorded while CasADi's handlers were in place (the main thread's to raise)
                    raise_if_pressed()
    except BaseException:
        if proc is not None:
            _kill_group(proc)
        raise
    finally:
        with _RUNNING_LOCK:
            _RUNNING.discard(proc)
        shutil.rmtree(scratch, ignore_errors=True)
    if proc.returncode:
        raise CompileError(f"{what} failed ({' '.join(cmd)}): {err.strip()[:800]}")


def stop_compilers() -> None:
    """Kill every compiler this process runs now, whatever thread waits for it: that thread's
    :func:`run_compiler` then raises :class:`CompileError` and removes its scratch folder."""
    with _RUNNING_LOCK:  # a compiler its thread has reaped is no longer ours to signal (its pid may be reused)
        for proc in [p for p in _RUNNING if p.returncode is None]:
            try:
                os.killpg(proc.pid, signal.SIGKILL)
            except (ProcessLookupError, PermissionError):
                pass


def _kill_group(proc: subprocess.Popen) -> None:
    """Kill the compiler and every process it started (they share its process group), and reap it."""
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass
    try:
        proc.communicate(timeout=5)
    except BaseException:  # a second interrupt, or a grandchild holding the pipes: stop waiting
        proc.kill()


def compile_function(function, flags: Sequence[str], compiler: str = "gcc", keep: Path | None = None):
    """``function`` (a ``casadi.Function``) as C from CasADi's code generator, compiled with
    ``compiler`` and ``flags`` into a shared library and loaded back (``casadi.external``).

    The same C as CasADi's own JIT writes, in a private temporary folder removed before this
    returns (the loaded library stays mapped) or when a compile is interrupted. Its derivatives
    are finite differences: use it where only values are evaluated, as CasADi's JIT with
    interpreted derivatives was used. With ``keep``, the library is also moved there (atomically:
    another process loads it whole or not at all) for :func:`load_function` to load again."""
    import casadi as ca

    path = find_compiler(compiler)
    if path is None:
        raise CompileError(f"No C compiler '{compiler}' on the PATH.")
    folder = Path(tempfile.mkdtemp(prefix="hyst_jit_"))
    try:
        gen = ca.CodeGenerator("jit.c")  # symbols prefixed jit_, as CasADi's JIT names them
        gen.add(function)
        gen.generate(str(folder) + os.sep)
        run_compiler([path, *flags, "./jit.c", "-o", "./libjit.so"], f"Compiling {function.name()}", cwd=folder)
        loaded = load_function(function.name(), folder / "libjit.so")
        if keep is not None:
            try:
                with atomic_path(keep) as staged:
                    shutil.copyfile(folder / "libjit.so", staged)
            except OSError:  # nowhere to keep it (a read-only cache, a pool's folder already removed)
                pass
        return loaded
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def load_function(name: str, library):
    """The function ``name`` of a library :func:`compile_function` built. CasADi builds derivatives of
    whatever calls it (an NLP's gradient graph) even where they are never evaluated; a loaded library
    has none, so finite differences stand in."""
    import casadi as ca

    return ca.external(name, str(library), {"enable_fd": True})
