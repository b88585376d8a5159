"""A hybrid is never kept where its network alone does better on runs held out of both fits.

A residual network sees what the network alone sees (the command) plus the physics' output. Where the
physics misleads it (a block that drifts on a run it never saw, a loop whose shape changes between
recordings), the hybrid can end up worse than the network that ignores the physics. ``hyst fit``
guards against that in its residual stage; :func:`hybrid_or_alone` is the same rule for a hybrid of
one named network, as ``hyst compare`` builds them: both are trained on the runs (or the stretches
before each run's last branch) that :func:`residual_split` leaves in, scored after the warm-up window
on what it holds out, and the network alone is kept as the model where its error there is lower.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field

from ._scoring import score_model
from ._split import PIECE_SAMPLES, residual_split

__all__ = ["HybridChoice", "hybrid_or_alone", "pooled_rmse", "HYBRID", "ALONE_KEPT"]

#: What :attr:`HybridChoice.kept` says: the hybrid, or the network alone in its place.
HYBRID, ALONE_KEPT = "hybrid", "network alone"


@dataclass(frozen=True)
class HybridChoice:
    """Which model a hybrid's row is, and the evidence: each candidate's pooled RMSE on the held-out runs
    or stretches (``inf`` where it diverged there; empty where nothing could be held out)."""

    kept: str
    held_out_rmse: dict[str, float] = field(default_factory=dict)
    how: str = ""
    held_out_runs: list[str] = field(default_factory=list)

    def to_dict(self) -> dict:
        return asdict(self)

    def line(self, name: str) -> str:
        """One line for a table: what was kept, and why (the held-out errors as the caller scored them)."""
        if not self.held_out_rmse:
            return f"{name}: the hybrid ({self.how})"
        scores = ", ".join(f"{k} {v:.4g}" for k, v in self.held_out_rmse.items())
        return f"{name}: {'the network alone kept' if self.kept == ALONE_KEPT else 'the hybrid'} (held out: {scores}; {self.how})"


def hybrid_or_alone(new_hybrid: Callable, new_alone: Callable, score: Callable, train: Sequence, warmup: int,
                    history: int = 1) -> HybridChoice:
    """The hybrid or its network alone, chosen on runs held out of both fits (:func:`residual_split`, stretches
    of at least ``history`` samples): ``new_hybrid()`` and ``new_alone()`` return the unfitted models,
    ``score(model, runs)`` a model's error on the held-out runs after their ``warmup`` samples (lower is better;
    :func:`pooled_rmse` for one output).

    The hybrid is kept where its error is at most the network alone's, and where nothing can be held out (runs
    too short: ``how`` says so). The caller fits the kept one on every run; the held-out fits are thrown away.
    """
    fit_on, held, how = residual_split(list(train), warmup, max(PIECE_SAMPLES, history))
    if not held:
        return HybridChoice(HYBRID, {}, how)
    scores = {name: float(score(new().fit(fit_on), held)) for name, new in ((HYBRID, new_hybrid), (ALONE_KEPT, new_alone))}
    kept = ALONE_KEPT if scores[ALONE_KEPT] < scores[HYBRID] else HYBRID
    return HybridChoice(kept, scores, how, [str(t.source) for t in held])


def pooled_rmse(direction: str, warmup: int) -> Callable:
    """``score(model, runs)``: the pooled RMSE of one output (the input, ``inverse``) after each run's ``warmup``
    samples, as ``hyst compare`` scores it (``inf`` where the prediction diverges)."""
    return lambda model, runs: score_model(model, runs, direction=direction, diverged="inf", warmup=warmup)[-1].rmse
