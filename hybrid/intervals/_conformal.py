"""Split-conformal prediction intervals calibrated on whole held-out runs.

Samples inside one run are not exchangeable (a free run's error carries from one sample to the
next), but runs are: the calibration unit is a run a model was *not* fitted on. Each held-out sample
gets a score, its absolute error divided by a width factor fixed before calibration,

    s = |y - y_hat| / sigma,    sigma = 1 + spread * max(d - 1, 0),

with ``d`` the input row's distance to the data the predicting model was fitted on
(:class:`DataDistance`, in radii: inside the data ``d <= 1`` and ``sigma = 1``). The interval of a
new sample is ``y_hat +- q * sigma``, ``q`` the conformal quantile of the scores pooled over groups
(Dunn, Wasserman and Ramdas 2022, "pooling CDFs"): each group (a run) weighs the same whatever its
length, and the unseen run's group is a point mass at +inf, so ``q`` is the smallest score at which

    sum_g  F_g(q) / (G + 1)  >=  level.

That needs ``G >= level / (1 - level)`` groups (9 at 90 %), and with few groups the point mass
makes ``q`` conservative (15 runs at 90 %: the pooled 96 % quantile; on the virtual catheter that
covered 96 % at 5.4x the RMSE). So the runs are the groups when there are at least
:data:`GROUPS_PER_ALPHA` / (1 - level) of them (40 at 90 %); with fewer, each run is cut into
contiguous segments, that many in all, which count as the groups. The guarantee then assumes the
segments exchangeable, which is weaker than for whole runs (:meth:`ConformalIntervals.groups`
shows which were pooled).

Runs are also offset from each other as a whole (a recording day, a start, a history): with
``shift=True`` (the default) the half-width is at least the one a new run's offset needs under a
random effect per held-out run (:func:`._shift.offset_quantile`), which widens with few runs rather
than take the offsets seen for all there are. Held-out runs may carry a ``condition`` (a baseline,
a recording day, a file-name group): they were then predicted by a model fitted without their whole
condition, and :meth:`ConformalIntervals.report` says how many conditions and runs the calibration
saw and what it covers of a run left out of it (:func:`._shift.nested_coverage`), from the
training data alone.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike, NDArray

from physics.data import DataError, NotFittedError, Trajectory

from ._distance import DataDistance, input_rows
from ._envelope import Envelope
from ._report import CalibrationReport
from ._shift import nested_shares, offset_quantile, pooled_quantile

__all__ = ["ConformalIntervals", "HeldOut", "Interval", "check_level", "coverage", "MIN_RUNS", "per_output_to_dict",
           "per_output_from_dict", "PER_OUTPUT_FORMAT"]

#: Fewest held-out runs to calibrate on: one run says nothing of how runs differ.
MIN_RUNS = 2
#: Groups asked for: this many over (1 - level) (40 at 90 %), so the +inf mass costs little.
GROUPS_PER_ALPHA = 4
#: Fewest held-out runs whose offsets set the random effect (fewer: their segments' offsets).
OFFSET_RUNS = 3
#: Fewest samples of a segment when runs are cut into groups.
MIN_SEGMENT = 10


def check_level(level) -> float:
    """``level`` as a float in (0, 1), or a :class:`DataError` that says so."""
    if isinstance(level, bool) or not isinstance(level, (int, float, np.floating)) or not 0 < level < 1:
        raise DataError(f"An interval level must be a number between 0 and 1 (exclusive), e.g. 0.9 for 90 %. "
                        f"Got {level!r} instead.")
    return float(level)


@dataclass
class HeldOut:
    """One run a model was not fitted on: the scored part of the run, the model's prediction on it
    and the runs the model was fitted on (which set the distance of each of its inputs)."""

    run: Trajectory
    prediction: NDArray[np.float64]
    trained_on: Sequence[Trajectory]
    #: The condition the run was recorded under (None: only the run itself was left out of the fit).
    condition: str | None = None
    #: A piece of a run (held out of a fit on the run's other pieces), not a whole run.
    piece: bool = False


class Interval(NamedTuple):
    """A prediction with its interval; ``outside`` flags samples whose input leaves the data."""

    y: NDArray[np.float64]
    lo: NDArray[np.float64]
    hi: NDArray[np.float64]
    outside: NDArray[np.bool_]
    distance: NDArray[np.float64]

    @property
    def half_width(self) -> NDArray[np.float64]:
        return (self.hi - self.lo) / 2


def coverage(y: ArrayLike, lo: ArrayLike, hi: ArrayLike) -> float:
    """Share of the samples of ``y`` inside ``[lo, hi]``."""
    y = np.asarray(y, dtype=float)
    return float(np.mean((y >= np.asarray(lo)) & (y <= np.asarray(hi))))


def _needed(level: float) -> int:
    """Fewest groups for a finite quantile at ``level``: ``G / (G + 1) >= level``."""
    return math.ceil(level / (1 - level) - 1e-9)


def _rows(runs: Sequence[Trajectory]) -> NDArray[np.float64]:
    return np.vstack([input_rows(t.u, t.dt, t.y) for t in runs])


def _groups(residuals: Sequence[NDArray], level: float) -> list[NDArray]:
    """The score groups the pooled quantile at ``level`` uses: the runs, or their segments."""
    wanted = math.ceil(GROUPS_PER_ALPHA / (1 - level) - 1e-9)
    if len(residuals) >= wanted:  # whole runs
        return list(residuals)
    per_run = math.ceil(wanted / len(residuals))
    return [piece for s in residuals for piece in np.array_split(s, max(1, min(per_run, s.size // MIN_SEGMENT)))]


def _half_width(residuals: Sequence[NDArray], level: float, shift: bool) -> float:
    """The rule: the pooled conformal quantile of the groups (+inf with too few), at least the one a new
    run's offset needs (``shift``; offsets between the runs, or between their segments with fewer than
    :data:`OFFSET_RUNS`: two runs' offsets give Student's t one degree of freedom)."""
    groups = _groups(residuals, level)
    q = pooled_quantile(groups, level)
    units = residuals if len(residuals) >= OFFSET_RUNS else groups
    return max(q, offset_quantile(units, level)) if shift and len(units) >= 2 else q


class ConformalIntervals:
    """Scores of held-out runs and the intervals they give (see the module's notes).

    Parameters
    ----------
    level : float
        Default coverage asked of :meth:`interval` (0.9: 90 % of the samples of a new run).
    spread : float
        How fast the width grows with the distance beyond the data (per spacing of the training runs, or per
        spread of their amplitudes and rates beyond the held-out runs' ``reach_``; 0: not at all).
    shift : bool
        Widen for the offset of a new run (a random effect per run, :func:`._shift.offset_quantile`).

    Attributes
    ----------
    distance_ : DataDistance
        Fitted on the training runs of the final model.
    envelope_ : Envelope
        The training runs' amplitudes and rates.
    reach_ : float
        The farthest a held-out run lay beyond the amplitudes and rates its model saw (:meth:`Envelope.distance`,
        in the training runs' spread): a new run as far is covered by the held-out errors as they are; a
        run farther widens the band by ``spread`` per unit beyond.
    reaches_ : list of float
        Each held-out run's distance beyond its model's runs (0: inside them). A new run outside the
        training runs gets at least the band the held-out runs outside theirs needed (:meth:`run_floor`).
    residuals_ : list of ndarray
        One per held-out run: its signed errors ``y - y_hat`` over the width factor ``sigma``.
    errors_ : list of ndarray
        The same unscaled: ``y - y_hat`` (what :class:`AdaptiveIntervals` follows from sample to sample).
    scores_ : list of ndarray
        The absolute values of the residuals.
    runs_ : list of str
        The held-out runs' sources.
    conditions_ : list of str or None
        The held-out runs' conditions (None where only the run was left out).
    """

    def __init__(self, level: float = 0.9, spread: float = 1.0, shift: bool = True):
        self.level = level
        self.spread = spread
        self.shift = shift

    def fit(self, train: Sequence[Trajectory], held_out: Sequence[HeldOut]) -> ConformalIntervals:
        """Score each held-out run against the data of the model that predicted it."""
        check_level(self.level)
        if isinstance(self.spread, bool) or not isinstance(self.spread, (int, float)) or not self.spread >= 0:
            raise DataError(f"spread must be a number >= 0. Got {self.spread!r} instead.")
        if not isinstance(self.shift, (bool, np.bool_)):
            raise DataError(f"shift must be True or False. Got {self.shift!r} instead.")
        held_out = list(held_out)
        if len(held_out) < MIN_RUNS:
            raise DataError(f"Calibrating intervals needs at least {MIN_RUNS} runs held out of the model's fit; got "
                            f"{len(held_out)}. Give more training runs (each fold holds one out).")
        self.distance_ = DataDistance().fit(_rows(train), np.concatenate([np.full(t.n, i) for i, t in enumerate(train)]))
        self.dt_ = float(train[0].dt)
        self.envelope_ = Envelope.fit(train)
        self.residuals_, self.errors_, self.runs_, self.conditions_ = [], [], [], []
        envelopes: dict[int, Envelope] = {}
        reach = []
        for h in held_out:
            y_hat = np.asarray(h.prediction, dtype=float).ravel()
            if y_hat.shape != h.run.y.shape or not np.all(np.isfinite(y_hat)):
                raise DataError(f"The prediction on held-out run {h.run.source!r} must be finite and as long as the "
                                f"run ({h.run.n}); got shape {y_hat.shape}.")
            # the held-out run's distance from the data its model saw, in the training runs' spacing (the
            # yardstick a new run is measured with): a run as far from the rest as the training runs lie
            # from each other keeps its error unscaled, so the band is as wide as what held-out runs missed
            # and how far the run's amplitude and rate lie beyond those its model saw, in the training runs' spread
            if id(h.trained_on) not in envelopes:
                envelopes[id(h.trained_on)] = Envelope.fit(h.trained_on, unit=self.envelope_.unit)
            reach.append(envelopes[id(h.trained_on)].distance(h.run.u, h.run.dt))
            sigma = self._sigma(self.distance_.spacings(input_rows(h.run.u, h.run.dt, y_hat), _rows(h.trained_on)))
            self.errors_.append(h.run.y - y_hat)
            self.residuals_.append(self.errors_[-1] / sigma)
            self.runs_.append(str(h.run.source))
            self.conditions_.append(None if h.condition is None else str(h.condition))
        self.reaches_ = [float(r) for r in reach]
        self.reach_ = max(self.reaches_)
        self.pieces_ = any(h.piece for h in held_out)
        self._cache: dict = {}
        return self

    @property
    def scores_(self) -> list[NDArray[np.float64]]:
        return [np.abs(r) for r in self.residuals_]

    def _sigma(self, d: NDArray) -> NDArray[np.float64]:
        """The width factor of samples ``d`` spacings of the training runs from their data."""
        return 1.0 + self.spread * np.maximum(np.asarray(d, dtype=float) - 1.0, 0.0)

    def run_factor(self, u: ArrayLike, dt: float) -> float:
        """The band's factor for a whole run: 1, plus ``spread`` per unit its amplitudes and rates lie
        beyond the training runs' farther than any held-out run lay beyond its model's (``reach_``)."""
        self._check_fitted()
        envelope = getattr(self, "envelope_", None)
        beyond = 0.0 if envelope is None else envelope.distance(u, dt) - getattr(self, "reach_", 0.0)
        return 1.0 + self.spread * max(beyond, 0.0)

    def run_floor(self, u: ArrayLike, dt: float, level: float | None = None) -> float:
        """The least half-width of a whole run outside the training runs' amplitudes and rates (0 inside
        them): the ``level`` quantile of the errors of the held-out runs that lay outside their models'
        runs (each run weighs the same; 0 where none did). A run outside is calibrated on those (its
        own group, as in Mondrian conformal prediction): where a loop changes with its rate or
        amplitude, the errors there are unlike the ones inside, whatever the samples' own distance."""
        self._check_fitted()
        level = check_level(self.level if level is None else level)
        envelope = getattr(self, "envelope_", None)
        if envelope is None or envelope.distance(u, dt) <= 0:
            return 0.0
        outside = [e for e, d in zip(self.errors_, getattr(self, "reaches_", ())) if d > 0 and e.size]
        return pooled_quantile(outside, level, unseen=False) if outside else 0.0

    def run_outside(self, u: ArrayLike, dt: float) -> str | None:
        """What of the run (its input's amplitude, its rate) lies outside the training runs, in words;
        None inside them (or for intervals saved before runs were measured as a whole)."""
        self._check_fitted()
        envelope = getattr(self, "envelope_", None)
        return None if envelope is None else envelope.describe(u, dt)

    def groups(self, level: float | None = None) -> list[NDArray[np.float64]]:
        """The score groups the quantile at ``level`` pools: the runs, or their segments."""
        self._check_fitted()
        return [np.abs(g) for g in _groups(self.residuals_, check_level(self.level if level is None else level))]

    def quantile(self, level: float | None = None) -> float:
        """``q``: the half-width, in output units, where ``sigma = 1``."""
        self._check_fitted()
        level = check_level(self.level if level is None else level)
        if level not in self._cache:
            needed = _needed(level)
            groups = _groups(self.residuals_, level)
            if len(groups) < needed:
                raise DataError(f"A {level * 100:.4g}% interval needs at least {needed} groups of held-out samples; the "
                                f"{len(self.residuals_)} held-out runs give {len(groups)} (segments of >= "
                                f"{MIN_SEGMENT} samples). Give more or longer runs, or ask for a lower level.")
            self._cache[level] = _half_width(self.residuals_, level, bool(self.shift))
        return self._cache[level]

    def nested_coverage(self, level: float | None = None) -> float | None:
        """What the rule covers of a held-out run calibrated without it (without its whole condition,
        where the runs carry conditions; mean over the runs), from the training runs alone
        (:func:`._shift.nested_coverage`); None with fewer than 3 held-out runs."""
        shares = self.nested_shares(level)
        return float(np.mean(shares)) if shares else None

    def nested_shares(self, level: float | None = None) -> list[float]:
        """Each held-out run's coverage calibrated without it (its condition), whose mean is
        :meth:`nested_coverage` (:func:`._shift.nested_shares`); empty with fewer than 3 held-out runs."""
        self._check_fitted()
        level = check_level(self.level if level is None else level)
        return nested_shares(self.residuals_, level, lambda rs, lv: _half_width(rs, lv, bool(self.shift)),
                             self.conditions_)

    def report(self, level: float | None = None) -> CalibrationReport:
        """How many conditions and runs the calibration saw, its nested coverage, and plain notes on
        whether that is enough for ``level`` (:class:`CalibrationReport`)."""
        level = check_level(self.level if level is None else level)
        conditions = len({c for c in self.conditions_ if c is not None})
        return CalibrationReport.build(level, len(self.residuals_), conditions,
                                       self.pieces_ or len(self.residuals_) < OFFSET_RUNS,
                                       self.nested_shares(level), whole_runs=not self.pieces_)

    def interval(self, y_hat: ArrayLike, u: ArrayLike, dt: float, level: float | None = None,
                 window: Trajectory | None = None, whole_run: bool = True) -> Interval:
        """``y_hat +- q sigma`` for the prediction ``y_hat`` on the input path ``u`` (sampled at ``dt``).

        ``outside`` flags the samples whose input, rate or predicted output leave the training data, and
        every sample of a run whose amplitude or rate as a whole lies outside the training runs'
        (:meth:`run_outside`; its band is then at least what the held-out runs outside theirs needed,
        :meth:`run_floor`, and widens with that distance, :meth:`run_factor`);
        ``whole_run=False`` judges each sample alone, as an exported step does (:meth:`function`);
        with the warm-up ``window`` the prediction started from (measured), every sample when the
        state the run starts in is unlike the training runs': a window row ``(u, du/dt, y measured)``
        outside their data (:meth:`start_outside`)."""
        self._check_fitted()
        y_hat = np.asarray(y_hat, dtype=float).ravel()
        rows = input_rows(u, dt, y_hat)
        if rows.shape[0] != y_hat.size:
            raise DataError(f"The prediction ({y_hat.size} samples) and the input ({rows.shape[0]}) differ in length.")
        d = self.distance_.distance(rows)
        half = self.quantile(level) * self._sigma(self.distance_.spacings(rows, distance=d))
        if whole_run:
            half = np.maximum(half, self.run_floor(u, dt, level)) * self.run_factor(u, dt)
        outside = self.distance_.outside(rows, d) | self.start_outside(window)
        if whole_run and self.run_outside(u, dt):
            outside = np.ones_like(outside)
        return Interval(y_hat, y_hat - half, y_hat + half, outside, d)

    def start_outside(self, window: Trajectory | None) -> bool:
        """Whether a run starts in a state the training runs do not show: a row ``(u, du/dt, y)`` of its
        measured warm-up ``window`` outside their data (False without a window)."""
        self._check_fitted()
        if window is None or window.n == 0:
            return False
        return bool(self.distance_.outside(input_rows(window.u, window.dt, window.y)).any())

    def function(self, level: float | None = None, dt: float | None = None) -> ca.Function:
        """``Function('half_width', [u, u_prev, y], [half_width, outside])``: the interval of one
        step (input, the previous input, the model's output) as CasADi, for an exported step or a
        controller; ``dt`` the sample time (default: the calibration runs'). A step sees one sample,
        not the whole run: it equals :meth:`interval` with ``whole_run=False``."""
        self._check_fitted()
        q = self.quantile(level)
        dt = self.dt_ if dt is None else float(dt)
        u, u_prev, y = ca.SX.sym("u"), ca.SX.sym("u_prev"), ca.SX.sym("y")
        _, out, d = self.distance_.function()(ca.vertcat(u, (u - u_prev) / dt, y))
        half = q * (1 + self.spread * ca.fmax(d - 1, 0))
        return ca.Function("half_width", [u, u_prev, y], [half, out], ["u", "u_prev", "y"], ["half_width", "outside"])

    def to_dict(self) -> dict:
        self._check_fitted()
        return {"level": self.level, "dt": self.dt_, "spread": self.spread, "reach": self.reach_,
                "reaches": self.reaches_,
                "shift": bool(self.shift),
                "distance": self.distance_.to_dict(), "runs": self.runs_, "conditions": self.conditions_,
                "envelope": None if getattr(self, "envelope_", None) is None else self.envelope_.to_dict(),
                "pieces": self.pieces_,
                "residuals": [[float(f"{v:.6g}") for v in r] for r in self.residuals_],
                "errors": [[float(f"{v:.6g}") for v in r] for r in self.errors_]}

    @classmethod
    def from_dict(cls, d: dict) -> ConformalIntervals:
        # a file from before the signed residuals kept only |scores|: no offsets to widen for
        signed = "residuals" in d
        out = cls(d["level"], d["spread"], bool(d.get("shift", False)) and signed)
        out.distance_ = DataDistance.from_dict(d["distance"])
        out.reach_ = float(d.get("reach", 0.0))
        out.reaches_ = [float(r) for r in d.get("reaches", [])]  # older files: no run measured alone
        out.envelope_ = Envelope.from_dict(d.get("envelope"))  # older files: runs not measured as a whole
        out.runs_ = list(d["runs"])
        out.residuals_ = [np.asarray(s, dtype=float) for s in d["residuals" if signed else "scores"]]
        out.errors_ = [np.asarray(e, dtype=float) for e in d["errors"]] if "errors" in d else out.residuals_
        out.conditions_ = list(d.get("conditions") or [None] * len(out.runs_))
        out.pieces_ = bool(d.get("pieces", False))
        out.dt_, out._cache = float(d["dt"]), {}
        return out

    def _is_fitted(self) -> bool:
        return hasattr(self, "residuals_")

    def _check_fitted(self) -> None:
        if not self._is_fitted():
            raise NotFittedError("These intervals are not calibrated yet. Call fit(train, held_out) first.")

    def __repr__(self) -> str:
        runs = f", {len(self.residuals_)} held-out runs" if self._is_fitted() else ", uncalibrated"
        return f"ConformalIntervals(level={self.level}{runs})"


#: ``format`` of the intervals of a model of several outputs: one calibration per output, by name.
PER_OUTPUT_FORMAT = "hysteresis-hybrid/intervals-per-output/1"


def per_output_to_dict(intervals: dict[str, ConformalIntervals]) -> dict:
    """The intervals of a model of several outputs (name -> :class:`ConformalIntervals`), JSON-ready."""
    return {"format": PER_OUTPUT_FORMAT, "outputs": {name: ci.to_dict() for name, ci in intervals.items()}}


def per_output_from_dict(d: dict) -> dict[str, ConformalIntervals]:
    """Read back :func:`per_output_to_dict`; a clear error for anything else."""
    if not isinstance(d, dict) or d.get("format") != PER_OUTPUT_FORMAT or not isinstance(d.get("outputs"), dict):
        raise DataError(f"Not the intervals of a model of several outputs (format {PER_OUTPUT_FORMAT!r}); fit the "
                        "folder again with `hyst fit --output A,B,...`.")
    return {name: ConformalIntervals.from_dict(v) for name, v in d["outputs"].items()}
