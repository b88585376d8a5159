"""The one scorer of the experiments: RMSE and NRMSE per test trajectory and pooled.

Table I (:func:`hybrid.reproduce`), the comparison (:func:`hybrid.compare`) and every
ablation run score a fitted model here, so that "the error on the test set" means
one thing everywhere: the model's prediction over each whole test trajectory against
its measured output (the input for an inverse model), then the same pooled over every
test sample (``test="all"``).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from physics.data import Trajectory, check_warmup_length, nrmse, rmse, warmup_split

__all__ = ["Score", "label", "score_model"]


@dataclass(frozen=True)
class Score:
    """Error of one model on one test trajectory (``test="all"``: pooled over every test sample)."""

    direction: str
    model: str
    test: str
    rmse: float
    nrmse: float
    n: int


def label(traj: Trajectory) -> str:
    """A short name for a trajectory: its source without folder or file extension."""
    name = Path(traj.source).name if traj.source else "?"
    stem, dot, ext = name.rpartition(".")
    return stem if dot and ext.lower() in ("csv", "txt", "mat") else name


def score_model(model, tests: Iterable[Trajectory], name: str = "", mode: str | None = None,
                direction: str | None = None, diverged: str = "raise", warmup: int = 0) -> list[Score]:
    """RMSE and NRMSE of ``model`` per test trajectory, then pooled over all of them (``test="all"``).

    Parameters
    ----------
    model
        Anything with ``predict(trajectory)`` (and ``predict(trajectory, mode=...)`` when
        ``mode`` is given).
    tests : iterable of Trajectory
    name : str
        The model's name in the scores.
    mode : str, optional
        Prediction scheme passed to ``predict`` (a network's ``modes``); default the model's own.
    direction : {"forward", "inverse"}, optional
        What the model predicts: the output (forward) or the input (inverse) of each test
        trajectory; default ``model.direction``.
    diverged : {"raise", "inf"}
        A prediction that is not finite: a DataError naming the sample (default), or a score
        of ``inf`` (:func:`hybrid.compare` reports it as diverged and goes on).
    warmup : int, default 0
        The protocol of a free run from measured samples: each test run's first ``warmup`` samples
        are given to the model as its warm-up window (``predict(rest, warmup=window)``, from which it
        sets its state) and every model is scored on the samples after them. 0: from rest at the
        first sample, scored on all.
    """
    if diverged not in ("raise", "inf"):
        raise ValueError(f"diverged must be 'raise' or 'inf'. Got {diverged!r} instead.")
    check_warmup_length(warmup)
    direction = model.direction if direction is None else direction
    ys, yhats, out = [], [], []
    for traj in tests:
        window, traj = warmup_split(traj, warmup)
        kwargs = ({} if mode is None else {"mode": mode}) | ({} if window is None else {"warmup": window})
        y = (traj.swap() if direction == "inverse" else traj).y
        yhat = np.asarray(model.predict(traj, **kwargs), dtype=np.float64)
        ys.append(y)
        yhats.append(yhat)
        out.append(_score(direction, name, label(traj), y, yhat, diverged))
    out.append(_score(direction, name, "all", np.concatenate(ys), np.concatenate(yhats), diverged))
    return out


def _score(direction: str, name: str, test: str, y: np.ndarray, yhat: np.ndarray, diverged: str) -> Score:
    """With ``diverged="inf"``, a prediction that is not finite everywhere, or that leaves the measured
    values by more than ``RUNAWAY`` times their span (a model that diverges on a run it never saw:
    the catheter's inverse ARX reached 1e74 mm), scores ``inf``; else ``rmse`` says where."""
    from identification.discovery import diverges, spread_of  # the selection's rule for a diverged fold

    if diverged == "inf" and yhat.shape == y.shape and diverges(yhat - y, spread_of(y)):
        return Score(direction, name, test, float("inf"), float("inf"), int(y.size))
    return Score(direction, name, test, rmse(y, yhat), nrmse(y, yhat), int(y.size))
