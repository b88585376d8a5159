"""C code of an exported step, compiled with the system gcc, and a tiny C program that calls it.

CasADi ships no C compiler: ``gcc -O3 -fPIC -shared`` (see :data:`CFLAGS`) builds a shared library that
``casadi.external`` loads back (or any C program links). The generated entry point
is CasADi's standard C API: ``<name>(arg, res, iw, w, mem)`` with ``<name>_work``
giving the work sizes (see the header ``<name>.h``).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
from collections.abc import Sequence
from pathlib import Path

import casadi as ca
import numpy as np

from physics.data.io import CompileError, atomic_paths, run_compiler

from ._errors import ExportError

__all__ = ["codegen", "has_compiler", "load_compiled", "write_c_demo", "compile_c_demo"]

#: ``-fno-semantic-interposition`` lets gcc inline CasADi's helper functions inside the shared
#: library (they are exported symbols); without it a call to the library runs 2x slower.
CFLAGS = ("-O3", "-fno-semantic-interposition", "-fPIC", "-shared")


def has_compiler(compiler: str = "gcc") -> bool:
    """True when ``compiler`` is on the PATH."""
    return shutil.which(compiler) is not None


def _run(cmd: list[str], what: str, cwd: Path) -> None:
    """Run a compiler command in ``cwd``, stopped with the command on Ctrl-C or SIGTERM."""
    try:
        run_compiler(cmd, what, cwd=cwd)
    except CompileError as exc:
        raise ExportError(str(exc)) from None


def _install(built: Sequence[Path], directory: Path) -> None:
    """Copy the files built in a scratch folder into ``directory``, all of them or none: an
    interrupted or failed build leaves the folder's previous files as they were."""
    with atomic_paths(*(directory / f.name for f in built)) as tmps:
        for f, tmp in zip(built, tmps):
            shutil.copyfile(f, tmp)
            shutil.copymode(f, tmp)


def codegen(function: ca.Function | Sequence[ca.Function], directory, name: str | None = None,
            compile: bool = True, compiler: str = "gcc", flags: tuple[str, ...] = CFLAGS) -> Path:
    """Write ``<name>.c`` and ``<name>.h`` for ``function`` (or several) in ``directory``;
    with ``compile``, build ``lib<name>.so`` and return its path (else the C file's).

    Each C symbol is its function's own name (``"step"`` for exported models);
    ``name`` (default: the first function's name) only names the files. They are built in a
    scratch folder and then put in ``directory`` together.
    """
    functions = [function] if isinstance(function, ca.Function) else list(function)
    directory = Path(directory).resolve()
    directory.mkdir(parents=True, exist_ok=True)
    name = name or functions[0].name()
    c_name, lib_name = f"{name}.c", f"lib{name}.so"
    with tempfile.TemporaryDirectory(prefix="hyst_codegen_") as scratch:
        scratch = Path(scratch)
        gen = ca.CodeGenerator(c_name, {"with_header": True})
        for f in functions:
            gen.add(f)
        gen.generate(str(scratch) + "/")
        sources = [scratch / c_name, scratch / f"{name}.h"]
        if not compile:
            _install(sources, directory)
            return directory / c_name
        if not has_compiler(compiler):
            _install(sources, directory)
            raise ExportError(f"No C compiler '{compiler}' on the PATH; install gcc or pass compile=False "
                              "and build the C file yourself.")
        # relative names in the scratch folder: never taken for options, never in the library
        _run([compiler, *flags, f"./{c_name}", "-o", f"./{lib_name}", "-lm"], "Compiling the generated C code",
             scratch)
        _install([*sources, scratch / lib_name], directory)
    return directory / lib_name


def cached_build(key: str, build) -> Path:
    """The folder ``hyst_mpc/<key>`` of the temp folder, made by ``build(scratch)`` where it is not there yet:
    in a scratch folder, then renamed, so it is there whole or not at all (gcc stops on Ctrl-C or SIGTERM,
    and the scratch folder goes with it). ``key`` names the content (a hash of what is built): a second
    build of the same content loads the first's instead of calling gcc again."""
    folder = Path(tempfile.gettempdir()) / "hyst_mpc" / key
    if not folder.is_dir():
        folder.parent.mkdir(parents=True, exist_ok=True)
        scratch = Path(tempfile.mkdtemp(prefix=f"{key}.", dir=folder.parent))
        try:
            build(scratch)
            try:
                os.replace(scratch, folder)
            except OSError:  # another process got there first: use its folder
                pass
        finally:
            shutil.rmtree(scratch, ignore_errors=True)  # gone already where it became the cache
    return folder


def load_compiled(library, function_name: str = "step") -> ca.Function:
    """The compiled function back in CasADi (``casadi.external``)."""
    library = Path(library)
    if not library.is_file():
        raise ExportError(f"No compiled library at '{library}'; build it with codegen(..., compile=True).")
    return ca.external(function_name, str(library.resolve()))


_DEMO = r"""/* Calls the exported step once: x = given state, u = given input; prints y and x_next. */
#include <stdio.h>
#include <stdlib.h>
#include "{header}"

int main(void) {{
  casadi_int sz_arg, sz_res, sz_iw, sz_w;
  if ({f}_work(&sz_arg, &sz_res, &sz_iw, &sz_w)) return 1;
  const casadi_real **arg = malloc(sz_arg * sizeof(*arg));
  casadi_real **res = malloc(sz_res * sizeof(*res));
  casadi_int *iw = malloc((sz_iw > 0 ? sz_iw : 1) * sizeof(*iw));
  casadi_real *w = malloc((sz_w > 0 ? sz_w : 1) * sizeof(*w));
  casadi_real x[{nx1}] = {{{x}}}, u[{nu}] = {{{u}}}, x_next[{nx1}], y[1];
  arg[0] = x; arg[1] = u; res[0] = x_next; res[1] = y;
  {f}_incref();
  int mem = {f}_checkout();
  int flag = {f}(arg, res, iw, w, mem);
  {f}_release(mem);
  {f}_decref();
  if (flag) return 2;
  printf("%.17g\n", y[0]);
  for (int i = 0; i < {nx}; ++i) printf("%.17g\n", x_next[i]);
  free(arg); free(res); free(iw); free(w);
  return 0;
}}
"""


def write_c_demo(function: ca.Function, directory, x, u, name: str | None = None) -> Path:
    """Write ``<name>_demo.c``: a C program that calls the generated step once at ``(x, u)``."""
    name = name or function.name()
    x = np.asarray(x, dtype=float).ravel()
    u = np.atleast_1d(np.asarray(u, dtype=float)).ravel()
    fmt = lambda v: ", ".join(repr(float(a)) for a in v) or "0"  # noqa: E731
    src = _DEMO.format(header=f"{name}.h", f=function.name(), nx=x.size, nx1=max(x.size, 1),
                       nu=u.size, x=fmt(x), u=fmt(u))
    path = Path(directory).resolve() / f"{name}_demo.c"
    path.write_text(src)
    return path


def compile_c_demo(function: ca.Function, directory, x, u, name: str | None = None,
                   compiler: str = "gcc") -> np.ndarray:
    """Generate the step's C code and a demo program, build and run it; returns ``[y, x_next...]``."""
    directory = Path(directory).resolve()
    name = name or function.name()
    c_file = codegen(function, directory, name=name, compile=False)
    demo = write_c_demo(function, directory, x, u, name=name)
    exe = directory / f"{name}_demo"
    with tempfile.TemporaryDirectory(prefix="hyst_codegen_") as scratch:
        _run([compiler, "-O2", str(demo), str(c_file), "-o", f"./{exe.name}", "-lm"], "Compiling the C demo",
             Path(scratch))
        _install([Path(scratch) / exe.name], directory)
    proc = subprocess.run([str(exe)], capture_output=True, text=True)
    if proc.returncode:
        raise ExportError(f"The C demo exited with status {proc.returncode}: {proc.stderr.strip()}")
    return np.array([float(v) for v in proc.stdout.split()])
