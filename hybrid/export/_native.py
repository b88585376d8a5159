"""Reading a saved CasADi function without running native code it may bring along.

A serialized CasADi function can reference a shared library (a function made by
``casadi.external``, or one compiled by ``jit``): deserializing it loads the library or runs the
compiler, and a library's constructors run at load time. Like an unpickled file, such a
``.casadi`` file is code, so it is refused unless the caller trusts it (``allow_external=True``,
``--allow-external`` on the command line).

The check reads CasADi's text serialization (each byte written as two letters ``a``-``p``,
low nibble first) and looks for the classes that load native code and for the ``jit`` flag.
"""

from __future__ import annotations

import re
import tempfile
from pathlib import Path

import casadi as ca

from ._errors import ExportError

__all__ = ["deserialize", "load_function", "native_code"]

#: Classes whose deserialization loads a shared library or runs a compiler.
NATIVE_CLASSES = ("External", "GenericExternal", "DllLibrary", "ImporterInternal", "ShellCompiler", "ClangCompiler")
_CLASS = re.compile(b"|".join(re.escape(len(n).to_bytes(4, "little") + n.encode()) for n in NATIVE_CLASSES))
#: Every function body holds: jit flag, jit_cleanup flag, jit_serialize ("source" | "link" | "embed").
_JIT = re.compile(rb"([\x00\x01])[\x00\x01](\x06\x00\x00\x00source|\x04\x00\x00\x00link|\x05\x00\x00\x00embed)")
_NIBBLES = re.compile(r"[a-p]*")

FLAG = "--allow-external"


def _decode(text: str) -> bytes | None:
    """The bytes of CasADi's text serialization, or None when ``text`` is not in that form."""
    text = text.strip()
    if len(text) % 2 or not _NIBBLES.fullmatch(text):
        return None
    raw = text.encode("ascii")
    return bytes((raw[i] - 97) | ((raw[i + 1] - 97) << 4) for i in range(0, len(raw), 2))


def native_code(text: str) -> str | None:
    """What in the serialized function ``text`` would run native code when it is loaded (None: nothing);
    an :class:`ExportError` when ``text`` is not a serialized function at all.

    >>> x = ca.SX.sym("x")
    >>> native_code(ca.Function("f", [x], [2 * x]).serialize()) is None
    True
    """
    data = _decode(text)
    if data is None:
        raise ExportError("not in CasADi's text format")
    found = _CLASS.search(data)
    if found:
        return f"it calls an external library ({found.group()[4:].decode()})"
    bodies = _JIT.findall(data)
    if not bodies:
        raise ExportError("no function body found")
    if any(flag == b"\x01" for flag, _ in bodies):
        return "a function in it is compiled on load (jit)"
    if any(not kind.endswith(b"source") for _, kind in bodies):
        return "a function in it links or embeds a compiled library"
    return None


def _native(text: str, where: str) -> str | None:
    try:
        return native_code(text)
    except ExportError as exc:
        raise _not_a_function(where, str(exc)) from None


def _not_a_function(where: str, why: str) -> ExportError:
    return ExportError(f"'{where}' is not a CasADi function ({why}: corrupt or truncated?); export the model "
                       "again with `hyst export`.")


def _refuse(where: str, why: str) -> ExportError:
    return ExportError(f"'{where}' was not loaded: {why}, and loading it would run native code. Load only "
                       f"files you trust, and then pass {FLAG} (allow_external=True in Python).")


def deserialize(text: str, where: str, allow_external: bool = False) -> ca.Function:
    """``casadi.Function.deserialize(text)``, refused when it would run native code (unless allowed)
    and with a clear error when ``text`` is corrupt or truncated; ``where`` names it in messages."""
    if not isinstance(text, str):
        raise ExportError(f"'{where}' does not hold a serialized CasADi function (got {type(text).__name__}).")
    why = None if allow_external else _native(text, where)
    if why:
        raise _refuse(where, why)
    try:
        f = ca.Function.deserialize(text)
    except (RuntimeError, MemoryError) as exc:
        raise _corrupt(where, exc) from None
    if f.is_null():
        raise ExportError(f"'{where}' does not hold a CasADi function (empty or truncated).")
    return f


def load_function(path: Path, allow_external: bool = False) -> ca.Function:
    """``casadi.Function.load(path)`` with the checks of :func:`deserialize`; the bytes checked are
    the bytes loaded (read once, loaded from a private copy)."""
    raw = path.read_bytes()
    try:
        text = raw.decode("ascii")
    except UnicodeDecodeError:
        text = None
    if not allow_external:
        why = _native(text, str(path)) if text is not None else None
        if text is None:
            raise _not_a_function(str(path), "not in CasADi's text format")
        if why:
            raise _refuse(str(path), why)
    with tempfile.TemporaryDirectory() as tmp:
        copy = Path(tmp) / "f.casadi"
        copy.write_bytes(raw)
        try:
            f = ca.Function.load(str(copy))
        except (RuntimeError, MemoryError) as exc:
            raise _corrupt(str(path), exc) from None
    if f.is_null():
        raise ExportError(f"'{path}' does not hold a CasADi function (empty or truncated).")
    return f


def _corrupt(where: str, exc: BaseException) -> ExportError:
    lines = [re.sub(r"^\.\.\./\S+:\d+:\s*", "", ln).strip() for ln in str(exc).splitlines()]
    lines = [ln for ln in lines if ln and "Notify the CasADi developers" not in ln and "Assertion" not in ln]
    detail = f" (CasADi: {lines[-1][:160]})" if lines else ""
    return ExportError(f"'{where}' is corrupt or truncated{detail}; export the model again with `hyst export`.")
