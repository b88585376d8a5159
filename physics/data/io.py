"""Files and the process around them: atomic writes, reading JSON/text/CSV columns, Ctrl-C and SIGTERM.

The public seam for every package that writes results or runs a long solve:

- atomic writes: :func:`atomic_path` / :func:`atomic_paths` / :func:`atomic_folder` give a temporary
  path that replaces the target only when the block finishes, so an interrupted run never leaves a
  half-written file; :func:`write_text` and :func:`write_json` write one file that way;
- reading: :func:`read_text`, :func:`read_json` and :func:`read_csv_columns`, each failing with a
  :class:`~physics.data.DataError` that names the file and what was wrong;
- interrupts: :func:`recording` records Ctrl-C / SIGTERM while a solver runs, :func:`raise_if_pressed`
  and :func:`stop_callback` stop a loop or an IPOPT solve at the next safe point,
  :class:`Terminated` is the ``KeyboardInterrupt`` of a SIGTERM, :func:`record_and_raise` the handler;
- compiled code: :func:`run_compiler`, :func:`compile_function`, :func:`load_function` and
  :class:`CompileError`.
"""

from ._atomic import atomic_folder, atomic_path, atomic_paths, write_json, write_text
from ._compiler import CompileError, compile_function, load_function, run_compiler, stop_compilers
from ._interrupt import ENDING, Terminated, raise_if_pressed, record_and_raise, recording, stop_callback
from ._io import read_csv_columns, read_json, read_text

__all__ = [
    "atomic_path", "atomic_paths", "atomic_folder", "write_text", "write_json",
    "read_text", "read_json", "read_csv_columns",
    "recording", "raise_if_pressed", "stop_callback", "Terminated", "record_and_raise", "ENDING",
    "run_compiler", "stop_compilers", "compile_function", "load_function", "CompileError",
]
