"""Held-out evidence that matches what a user does next: the next recording, or the next branch of a run.

Whole runs are held out in turn where there are several (:func:`run_folds`). One run is never cut into
pieces interleaved with the pieces a fit sees: such a piece lies between training pieces of the same
time course, so a spec that memorises the run's course (a resonance whose period is a third of the
record) predicts it well and then fails on the next branch. :func:`next_folds` holds out the run's
later branches between input reversals instead, each predicted by a fit on everything before it
(the run's prefix, started from rest as any run is), from its own warm-up window; a run with too few
reversals is held out in later stretches the same way. :func:`holdout` is the one rule every stage
of a fit (the physics' choice, the peers, the residual, the intervals) reads its folds from.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, is_dataclass, replace

import numpy as np

from identification._errors import IdentificationError

__all__ = ["Holdout", "holdout", "next_folds", "reversals", "run_folds", "NEXT_FOLDS", "MIN_PIECE"]

#: Most folds one run is held out in (its last branches or stretches, each after the ones before).
NEXT_FOLDS = 3
#: Fewest samples of a held-out branch or stretch (its warm-up window included).
MIN_PIECE = 40
#: An input turns where it leaves its last extreme by more than this share of its range.
TURN_SHARE = 0.1


@dataclass(frozen=True)
class Holdout:
    """Folds of held-out evidence: ``runs`` (whole runs, or a run's prefixes and later stretches) and,
    per fold, the indices of the runs fitted on (``fit``) and of those held out (``held``).
    ``pieces``: the held-out units are stretches of one run, not whole runs."""

    runs: list
    fit: list[list[int]]
    held: list[list[int]]
    how: str
    pieces: bool = False

    def split(self, k: int) -> tuple[list, list]:
        """``(fitted on, held out)`` runs of fold ``k``."""
        return [self.runs[i] for i in self.fit[k]], [self.runs[i] for i in self.held[k]]


def run_folds(runs: Sequence, group_by: str | None = None, max_folds: int = 6) -> tuple[list[list[int]], str]:
    """Indices of the runs held out in each fold, and how they were grouped.

    Each run is its own group (leave one run out), or runs sharing ``meta[group_by]`` form one
    (leave one condition out). More groups than ``max_folds`` are dealt round-robin into
    ``max_folds`` folds.
    """
    if group_by is None:
        keys, how = list(range(len(runs))), "leave-one-run-out"
    else:
        missing = [i for i, r in enumerate(runs) if group_by not in getattr(r, "meta", {})]
        if missing:
            raise IdentificationError(f"group_by={group_by!r}: run(s) {missing} have no meta[{group_by!r}]; "
                                      "group by a key every run has, or pass group_by=None (one run per fold).")
        keys, how = [runs[i].meta[group_by] for i in range(len(runs))], f"leave-one-{group_by}-out"
    groups = list(dict.fromkeys(keys))
    if len(groups) < 2:
        raise IdentificationError(f"Selecting physics by held-out runs needs at least two runs (groups); got "
                                  f"{len(groups)}. Give more trajectories, or choose the spec yourself.")
    if max_folds < 2:
        raise IdentificationError(f"max_folds must be >= 2. Got {max_folds} instead.")
    folds: list[list[int]] = [[] for _ in range(min(max_folds, len(groups)))]
    for g, key in enumerate(groups):
        folds[g % len(folds)] += [i for i, k in enumerate(keys) if k == key]
    return folds, how


def reversals(u, share: float = TURN_SHARE) -> list[int]:
    """Indices where the input turns: the last sample of an extreme that the input then leaves by more
    than ``share`` of its range (a hold at the extreme belongs to the branch before the turn).

    >>> reversals([0, 1, 2, 3, 2, 1, 0, 1, 2])
    [3, 6]
    """
    u = np.asarray(u, dtype=float)
    tol = share * float(np.ptp(u)) if u.size else 0.0
    if not tol > 0:
        return []
    turns, direction, ext = [], 0, 0
    for i in range(1, u.size):
        if direction == 0:
            if abs(u[i] - u[0]) > tol:
                direction, ext = (1 if u[i] > u[0] else -1), i
        elif direction * (u[i] - u[ext]) >= 0:
            ext = i
        elif direction * (u[ext] - u[i]) > tol:
            turns.append(ext)
            direction, ext = -direction, i
    return turns


def next_folds(run, warmup: int = 0, min_piece: int = MIN_PIECE, folds: int = NEXT_FOLDS) -> Holdout:
    """One run held out in its later branches (or stretches), each after a fit on all it follows.

    The run's branches lie between its input reversals (:func:`reversals`). Fold ``k`` holds out one of
    the last ``folds`` branches that follow at least two others (a rise and a fall: the loop a fit needs
    to see) and keep ``min_piece`` samples and twice the warm-up window, from ``warmup`` samples before
    it (the measured window that sets its state); it is fitted on the run up to that branch. A run with
    fewer such branches is cut into ``folds + 1`` equal stretches and the last ``folds`` are held out the
    same way (2 folds of thirds when it is too short for that).
    """
    least = max(int(min_piece), 2 * int(warmup))
    n = getattr(run, "n", None)
    if not is_dataclass(run) or n is None or n < 3 * least:
        raise IdentificationError(
            f"Selecting physics by held-out runs needs at least two runs, or one of at least {3 * least} samples "
            f"to hold its later stretches out; got one of {getattr(run, 'n', len(run.u))}. Give more "
            "trajectories, or choose the spec yourself.")
    cuts = [0, *(t + 1 for t in reversals(run.u)), n]
    starts = [(a, b) for i, (a, b) in enumerate(zip(cuts[:-1], cuts[1:])) if i >= 2 and b - a >= least]
    if len(starts) >= 2:
        held, how = starts[-folds:], "branch"
    else:
        parts = folds + 1 if n >= (folds + 1) * least else 3
        edges = np.linspace(0, n, parts + 1).round().astype(int)
        held, how = list(zip(edges[1:-1], edges[2:])), "stretch"
    name, runs, fit, out = run.source or "run", [], [], []
    for a, b in held:
        runs += [replace(run.segment(0, a), source=f"{name}[0:{a}]"),
                 replace(run.segment(max(a - warmup, 0), b), source=f"{name}[{max(a - warmup, 0)}:{b}]")]
        fit.append([len(runs) - 2])
        out.append([len(runs) - 1])
    what = "branches between input reversals" if how == "branch" else "stretches"
    return Holdout(runs, fit, out, f"next-{how} (one run: its last {len(held)} {what}, each predicted by a fit "
                   "on the run before it)", pieces=True)


def holdout(train: Sequence, warmup: int = 0, group_by: str | None = None, max_folds: int = 6,
            min_piece: int = MIN_PIECE) -> Holdout:
    """The folds every stage of a fit holds out: whole runs (or conditions, ``group_by``) left out in turn
    from two runs on (:func:`run_folds`), one run's later branches after a fit on what precedes them
    (:func:`next_folds`)."""
    runs = list(train)
    if len(runs) == 1 and group_by is None:
        return next_folds(runs[0], warmup, min_piece)
    held, how = run_folds(runs, group_by, max_folds)
    return Holdout(runs, [[i for i in range(len(runs)) if i not in f] for f in held], held, how)
