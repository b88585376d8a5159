"""The condition each training run was recorded under, for calibrating intervals by leaving one out.

A model fitted on runs of one recording day meets the next day's runs offset as a whole; only
leaving a whole condition out of a fit shows how far. A condition is read from the runs' ``meta``
(the first of :data:`CONDITION_KEYS` that every run carries and that groups some runs together), or
from the user's ``group``: a ``meta`` key, or a regular expression searched in each run's file name
(its first capture group, else the whole match, is the condition: ``"day(\\d+)"``).
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from pathlib import Path

from physics.data import DataError

__all__ = ["CONDITION_KEYS", "run_conditions", "condition_folds"]

#: ``meta`` keys that name a condition, tried in order when the user gives no ``group``.
CONDITION_KEYS = ("condition", "recording_day", "day", "session", "baseline", "set", "frequency_hz")


def _name(run) -> str:
    return Path(str(run.source or "")).name


def run_conditions(runs: Sequence, group: str | None = None) -> tuple[list[str] | None, str]:
    """``(labels, how)``: each run's condition, or None where the runs carry no condition that puts
    two of them together (each run is then its own condition: leave one run out)."""
    runs = list(runs)
    if group is not None:
        if not isinstance(group, str) or not group:
            raise DataError(f"group must be a meta key or a regular expression on the file names; got {group!r}.")
        if all(group in getattr(r, "meta", {}) for r in runs):
            labels, how = [str(r.meta[group]) for r in runs], f"meta {group!r}"
        else:
            try:
                pattern = re.compile(group)
            except re.error as exc:
                raise DataError(f"group {group!r} is neither a meta key every run carries nor a valid regular "
                                f"expression ({exc}).") from None
            labels = []
            for r in runs:
                m = pattern.search(_name(r))
                if m is None:
                    raise DataError(f"group {group!r} matches no part of the file name {_name(r)!r}; give a pattern "
                                    "every training file name matches, e.g. 'day(\\d+)'.")
                labels.append(m.group(1) if m.groups() else m.group(0))
            how = f"file names by {group!r}"
        if len(set(labels)) < 2:
            raise DataError(f"group {group!r} puts every training run in one condition ({labels[0]!r}); nothing "
                            "can be left out. Give a group that tells at least two conditions apart.")
        return labels, how
    for key in CONDITION_KEYS:
        values = [r.meta.get(key) if hasattr(r, "meta") else None for r in runs]
        if any(v is None for v in values):
            continue
        labels = [str(v) for v in values]
        if 2 <= len(set(labels)) < len(labels):
            return labels, f"meta {key!r}"
    return None, "each run its own condition"


def condition_folds(labels: Sequence[str]) -> list[list[int]]:
    """The runs each fold leaves out: one fold per condition, in order of first appearance."""
    order = list(dict.fromkeys(labels))
    return [[i for i, v in enumerate(labels) if v == c] for c in order]
