"""How IPOPT solves a fit: :class:`SolverSettings`, one object passed to ``identify`` and ``discover``."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ._errors import IdentificationError

__all__ = ["SolverSettings", "METHODS"]

#: Transcriptions of the fit: single shooting (multiple shooting is not offered: see ``identify``'s notes).
METHODS = ("single",)


@dataclass(frozen=True)
class SolverSettings:
    """The solver of a fit: its transcription, its budget and what it prints.

    These settings change how a fit is computed, not what is fitted (the model, the data, the held
    parameters and the starts are ``identify``'s own arguments), so they travel together: a
    selection's fold fits, a discovery step and a model folder each state theirs in one object.

    Parameters
    ----------
    method : {"single"}
        Single shooting (multiple shooting is not offered: see :func:`identification.identify`).
    max_iter : int
        IPOPT iterations per start: the limit that decides the answer, the same on any machine
        whatever its load.
    max_wall_time : float, optional
        A last safeguard (s) for all starts together, off by default. When it stops a solve the
        result's status says so (``Maximum_WallTime_Exceeded``), and starts it leaves no time for
        are skipped: the answer then depends on the machine, which is why iterations are the limit.
    ipopt_options : mapping, optional
        Extra IPOPT options, e.g. ``{"tol": 1e-10}`` (a ``max_iter`` here wins over the field).
    jit : bool, optional
        Compile the sensitivity step with the system C compiler (default: when there is one).
    verbose : bool
        Print IPOPT's iterations.
    threads : int
        Starts of a multi-start solved at once, each on its own thread (default 1: one after another).
        The answer is the same for any number: each start is the same solve, and the multi-start's
        extra starts, run beside the first, are dropped where the first alone would have been kept.
        Ignored with ``max_wall_time`` or ``verbose``.

    Examples
    --------
    >>> from identification import SolverSettings
    >>> SolverSettings(max_iter=150).max_iter
    150
    >>> SolverSettings(max_iter=0)
    Traceback (most recent call last):
    ...
    identification._errors.IdentificationError: max_iter must be an integer >= 1. Got 0 instead.
    """

    method: str = "single"
    max_iter: int = 3000
    max_wall_time: float | None = None
    ipopt_options: Mapping[str, Any] | None = None
    jit: bool | None = None
    verbose: bool = False
    threads: int = 1

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise IdentificationError(f"method must be one of {', '.join(METHODS)}. Got {self.method!r}.")
        if isinstance(self.max_iter, bool) or not isinstance(self.max_iter, (int, np.integer)) or self.max_iter < 1:
            raise IdentificationError(f"max_iter must be an integer >= 1. Got {self.max_iter!r} instead.")
        if self.max_wall_time is not None and not (np.isfinite(self.max_wall_time) and self.max_wall_time > 0):
            raise IdentificationError(f"max_wall_time must be None or > 0 s. Got {self.max_wall_time} instead.")
        if self.ipopt_options is not None:
            if not isinstance(self.ipopt_options, Mapping):
                raise IdentificationError(f"ipopt_options must be a dict of IPOPT options, e.g. {{'tol': 1e-10}}. "
                                          f"Got {self.ipopt_options!r} instead.")
            object.__setattr__(self, "ipopt_options", dict(self.ipopt_options))  # a copy: the caller's dict may change
        if isinstance(self.threads, bool) or not isinstance(self.threads, (int, np.integer)) or self.threads < 1:
            raise IdentificationError(f"threads must be a whole number >= 1. Got {self.threads!r} instead.")
        if self.jit is not None and not isinstance(self.jit, bool):
            raise IdentificationError(f"jit must be True, False or None (when a C compiler is found). "
                                      f"Got {self.jit!r} instead.")

    def options(self) -> dict[str, Any]:
        """IPOPT's options of these settings: ``max_iter`` and the extra ``ipopt_options``."""
        return {"max_iter": int(self.max_iter), **(self.ipopt_options or {})}

    def with_budget(self, max_iter: int) -> "SolverSettings":
        """These settings with another iteration budget."""
        return replace(self, max_iter=max_iter)
