"""The runs or branches held out of a model folder's fits: what its residual is chosen and its intervals are
calibrated on."""

from __future__ import annotations

import numpy as np

__all__ = ["residual_split", "RESIDUAL_RUNS", "PIECE_SAMPLES"]

#: Fewest training runs whose every third is held out of the residual's fits; fewer are cut into pieces.
RESIDUAL_RUNS = 3
#: Fewest samples of a piece the residual is trained or chosen on (and at least the networks' history).
PIECE_SAMPLES = 40


def residual_split(train, warmup: int, min_piece: int | None = None) -> tuple[list, list, str]:
    """``(fit_on, held, how)``: the runs the residual's candidates are trained on and those they are
    chosen and calibrated on, never trained on. From :data:`RESIDUAL_RUNS` runs on, every third run
    (``train[1::3]``) is held out; from fewer, each run's last branch (or stretch) is held out and the
    candidates are trained on what precedes it (the last fold of
    :func:`identification.discovery.next_folds`, branches of at least ``min_piece`` samples: the
    networks' history), so the held-out stretch is what the user predicts next, never a piece
    interleaved with the pieces trained on."""
    from identification import IdentificationError
    from identification.discovery import next_folds

    if len(train) >= RESIDUAL_RUNS:
        index = set(range(1, len(train), 3))
        return ([t for i, t in enumerate(train) if i not in index], [train[i] for i in sorted(index)],
                f"every third run held out ({len(index)} of {len(train)})")
    fit_on, held = [], []
    for run in train:
        try:
            folds = next_folds(run, warmup, *([] if min_piece is None else [min_piece]))
        except IdentificationError:
            return list(train), [], (f"fewer than {RESIDUAL_RUNS} runs, too short to hold stretches out: scored "
                                     "on the training runs themselves, no intervals; record longer or more runs")
        (before,), (after,) = folds.split(len(folds.held) - 1)
        fit_on.append(before)
        # the held stretch starts its warm-up window where the fit's prefix ends, less that window
        held += _cut(run, max(before.n - warmup, 0), after.n, warmup, min_piece or PIECE_SAMPLES)
    return (fit_on, held, f"fewer than {RESIDUAL_RUNS} runs: the last branch or stretch of "
            f"{'the run' if len(train) == 1 else f'each of the {len(train)} runs'} held out ({len(held)} piece{'s' if len(held) != 1 else ''}), "
            "trained on what precedes it")


def _cut(run, first: int, length: int, warmup: int, least: int, most: int = 4) -> list:
    """The held-out stretch ``run[first:first + length]`` as up to ``most`` contiguous pieces of at least
    ``least`` scored samples, each with the ``warmup`` samples before it as its window (calibration
    groups of the intervals), named by their place in ``run``."""
    from dataclasses import replace

    m = int(np.clip((length - warmup) // max(least, 1), 1, most))
    cuts = first + np.linspace(warmup, length, m + 1).round().astype(int)
    return [replace(run.segment(a - warmup, b), source=f"{run.source or 'run'}[{a - warmup}:{b}]")
            for a, b in zip(cuts[:-1], cuts[1:])]


