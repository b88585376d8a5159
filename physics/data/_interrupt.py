"""Ctrl-C that survives CasADi: presses are recorded, so one swallowed inside a CasADi call (an
IPOPT solve ends 'NonIpopt_Exception_Thrown' and the next one starts) still stops the work."""

from __future__ import annotations

import contextlib
import signal
import threading

__all__ = ["recording", "raise_if_pressed", "record_and_raise"]

#: Presses not yet acted on.
PRESSED: list[int] = []


def record_and_raise(*_) -> None:
    """SIGINT handler for a whole command: record the press, and raise as Python would."""
    PRESSED.append(1)
    raise KeyboardInterrupt


def _record(*_) -> None:
    PRESSED.append(1)


def raise_if_pressed() -> None:
    """KeyboardInterrupt when Ctrl-C was pressed since the last check."""
    if PRESSED:
        PRESSED.clear()
        raise KeyboardInterrupt


@contextlib.contextmanager
def recording():
    """Only record presses inside (for work CasADi runs); raise when the outermost block ends."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    raise_if_pressed()  # a press swallowed before this work began
    outermost = signal.getsignal(signal.SIGINT) is not _record
    previous = signal.signal(signal.SIGINT, _record)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
    if outermost:
        raise_if_pressed()
