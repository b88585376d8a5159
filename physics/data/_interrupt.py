"""Ctrl-C that survives CasADi: presses are recorded, so one swallowed inside a CasADi call (an
IPOPT solve ends 'NonIpopt_Exception_Thrown' and the next one starts) still stops the work.

Where a command installs :func:`record_and_raise` for SIGTERM too, a SIGTERM is handled like a
press (recorded, raised as :class:`Terminated`, a KeyboardInterrupt), so the same clean-up runs; a
SIGHUP (a closed terminal or ssh session) is handled like a SIGTERM."""

from __future__ import annotations

import contextlib
import math
import signal
import threading

__all__ = ["Terminated", "recording", "raise_if_pressed", "record_and_raise", "stop_callback", "ENDING"]

#: Presses (signal numbers: SIGINT, or SIGTERM and SIGHUP where handled) not yet acted on.
PRESSED: list[int] = []
#: The signals that end a command as SIGTERM does (SIGHUP: its terminal or ssh session closed).
ENDING = tuple(getattr(signal, name) for name in ("SIGTERM", "SIGHUP") if hasattr(signal, name))


class Terminated(KeyboardInterrupt):
    """SIGTERM (or SIGHUP: ``signum``), raised like Ctrl-C where a command handles it (the CLI then
    exits 128 + ``signum``: 143, 129)."""

    def __init__(self, signum: int = signal.SIGTERM):
        super().__init__()
        self.signum = int(signum)


def _interrupt(signum: int) -> KeyboardInterrupt:
    return Terminated(signum) if signum in ENDING else KeyboardInterrupt()


def record_and_raise(signum: int = signal.SIGINT, _frame=None) -> None:
    """SIGINT (and SIGTERM, SIGHUP) handler for a whole command: record the press, and raise as Python
    would (SIGTERM, SIGHUP: :class:`Terminated`)."""
    PRESSED.append(signum)
    raise _interrupt(signum)


def _record(signum: int = signal.SIGINT, _frame=None) -> None:
    PRESSED.append(signum)


def raise_if_pressed() -> None:
    """KeyboardInterrupt (:class:`Terminated` for a SIGTERM) when Ctrl-C was pressed since the
    last check."""
    if PRESSED:
        signum = next((s for s in PRESSED if s in ENDING), signal.SIGINT)
        PRESSED.clear()
        raise _interrupt(signum)


@contextlib.contextmanager
def recording():
    """Only record presses inside (for work CasADi runs); raise when the outermost block ends."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    raise_if_pressed()  # a press swallowed before this work began
    outermost = signal.getsignal(signal.SIGINT) is not _record
    previous = signal.signal(signal.SIGINT, _record)
    # SIGTERM, SIGHUP only where the command raises on them: elsewhere they keep ending the process
    ending = [s for s in ENDING if signal.getsignal(s) is record_and_raise]
    for s in ending:
        signal.signal(s, _record)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
        for s in ending:
            signal.signal(s, record_and_raise)
    if outermost:
        raise_if_pressed()


def stop_callback(n_x: int, n_g: int, n_p: int = 0, stall: tuple[int, float] | None = None):
    """An ``iteration_callback`` for ``casadi.nlpsol`` (IPOPT, sqpmethod) that ends the solve once
    Ctrl-C was pressed (IPOPT: ``User_Requested_Stop``) instead of running on to its iteration
    limit. Keep a reference to it as long as the solver lives.

    With ``stall=(window, rtol)`` it also ends the solve once the lowest objective so far has
    dropped by no more than ``rtol`` of itself over the last ``window`` iterations: the solver is
    then crawling through the objective's rounding noise (a smoothed ``|x|``, a long rollout's
    sums), where its own tolerances may never be met. Its ``stalled`` is then True; call its
    ``reset()`` before each solve. Setting its ``cancel`` to a ``threading.Event`` ends the solve
    once that is set (a start run at once with others that one of them made moot)."""
    import casadi as ca

    class _Stop(ca.Callback):
        def __init__(self):
            ca.Callback.__init__(self)
            self._sizes = {"x": (n_x, 1), "f": (1, 1), "g": (n_g, 1), "lam_x": (n_x, 1), "lam_g": (n_g, 1),
                           "lam_p": (n_p, 1)}
            self.reset()
            self.construct("stop_on_ctrl_c_or_stall", {})

        def reset(self):
            self.best, self.stalled = [], False

        cancel = None

        def get_n_in(self):
            return ca.nlpsol_n_out()

        def get_n_out(self):
            return 1

        def get_name_in(self, i):
            return ca.nlpsol_out(i)

        def get_name_out(self, i):
            return "ret"

        def get_sparsity_in(self, i):
            return ca.Sparsity.dense(*self._sizes[ca.nlpsol_out(i)])

        def eval(self, arg):
            if PRESSED or (self.cancel is not None and self.cancel.is_set()):
                return [1]
            if stall is not None:
                window, rtol = stall
                f = float(arg[ca.nlpsol_out().index("f")])
                if not math.isfinite(f):
                    return [0]
                self.best.append(min(f, self.best[-1]) if self.best else f)
                if len(self.best) > window and self.best[-1 - window] - self.best[-1] <= rtol * abs(self.best[-1]):
                    self.stalled = True
                    return [1]
            return [0]

    return _Stop()
