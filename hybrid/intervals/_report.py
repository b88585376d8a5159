"""What a calibration saw and what it can promise, in plain words, from the training data alone."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

__all__ = ["CalibrationReport", "TOLERANCE"]

#: A nested coverage this far under the level is reported as short of it (0.05: 85 % at 90 %).
TOLERANCE = 0.05


@dataclass
class CalibrationReport:
    """How many conditions, runs or pieces an interval calibration rests on, and whether that is enough.

    ``needed`` is the fewest exchangeable units (conditions, else runs, else pieces) for which a
    conformal quantile at ``level`` is finite; ``nested`` the coverage of a held-out run calibrated
    without it (:meth:`ConformalIntervals.nested_coverage`), None with fewer than 3; ``nested_runs``
    each scored run's own (:meth:`ConformalIntervals.nested_shares`). A run that falls short of
    ``level - TOLERANCE`` there shows, from the training data alone, that a new recording can too: the
    runs are exchangeable, so one falls below the ``short`` worst of ``G`` scored with a chance of about
    ``(short + 1) / (G + 1)`` (:attr:`chance_short`).
    """

    level: float
    runs: int
    conditions: int
    pieces: bool
    needed: int
    nested: float | None
    nested_runs: list[float] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    #: With ``pieces``: the held-out units are whole runs, cut into pieces only for their offsets.
    whole_runs: bool = False

    @property
    def unit(self) -> str:
        if self.conditions >= 2:
            return "conditions"
        return "pieces of runs" if self.pieces and not self.whole_runs else "runs"

    @property
    def units(self) -> int:
        return self.conditions if self.conditions >= 2 else self.runs

    @property
    def short(self) -> int:
        """How many scored runs the nested check covered less than ``level - TOLERANCE`` of."""
        return sum(s < self.level - TOLERANCE for s in self.nested_runs)

    @property
    def chance_short(self) -> float | None:
        """About how likely a new recording falls short as the ``short`` runs did: ``(short + 1) / (G + 1)``
        over the ``G`` scored runs (None: none scored)."""
        return (self.short + 1) / (len(self.nested_runs) + 1) if self.nested_runs else None

    @property
    def enough(self) -> bool:
        """Enough units for the level, a nested coverage within :data:`TOLERANCE` of it and no scored run
        short of that."""
        return (self.units >= self.needed and not self.pieces and self.short == 0
                and (self.nested is None or self.nested >= self.level - TOLERANCE))

    @property
    def reaches(self) -> bool | None:
        """Whether the nested check reaches ``level - TOLERANCE`` (None: too few runs to check)."""
        return None if self.nested is None else self.nested >= self.level - TOLERANCE

    def to_dict(self) -> dict:
        return {"level": self.level, "runs": self.runs, "conditions": self.conditions, "pieces": self.pieces,
                "needed": self.needed, "nested_coverage": self.nested, "nested_runs": self.nested_runs,
                "short": self.short, "chance_short": self.chance_short, "enough": self.enough, "notes": self.notes}

    @classmethod
    def build(cls, level: float, runs: int, conditions: int, pieces: bool, shares=(), *,
              whole_runs: bool = False) -> CalibrationReport:
        """The report and its notes, from the nested check's ``shares`` (each scored run's coverage; its
        mean is ``nested``, None without any). ``pieces``: the calibration rests on pieces of runs, either
        held out as such or (``whole_runs``: whole held-out runs, too few to estimate the offsets between
        recordings from, cut into segments for them)."""
        needed = math.ceil(level / (1 - level) - 1e-9)
        shares = [float(s) for s in shares]
        nested = float(np.mean(shares)) if shares else None
        out = cls(level, runs, conditions, pieces, needed, nested, shares, whole_runs=whole_runs)
        seen = (f"{conditions} conditions left out whole ({runs} runs)" if conditions >= 2 else
                f"{runs} pieces of runs" if out.unit == "pieces of runs" else
                f"{runs} runs of one condition, each left out in turn")
        out.notes.append(f"The calibration saw {seen}.")
        if pieces:
            groups = ("pieces of the same recordings are the calibration groups" if not whole_runs else
                      f"{runs} runs are too few to show how recordings are offset from each other, so the offsets "
                      "are estimated from pieces of the same recordings")
            out.notes.append(f"A weaker assumption than held-out runs: {groups}. The intervals assume the next "
                             "recording differs from the "
                             "training runs no more than their pieces differ from each other (they share their day, "
                             "mounting and drift). Record more runs for intervals that hold across recordings.")
        if out.units < needed:
            what = "conditions" if conditions >= 2 else "runs recorded under other conditions"
            out.notes.append(f"That is too few for a guaranteed {level:.0%}: it needs at least {needed} {what}. "
                             f"The width rests on a model of how runs are offset from each other; on a recording "
                             "made under a condition the training runs do not show, coverage can fall short.")
        if nested is not None:
            verdict = ("reaches" if nested >= level - TOLERANCE else
                       "falls short of") + f" {level - TOLERANCE:.0%}"
            left = ("each condition's runs calibrated without that condition" if conditions >= 2 else
                    "each held-out piece calibrated without it" if out.unit == "pieces of runs" else
                    "each held-out run calibrated without it")
            out.notes.append(f"On {left}, the intervals covered {nested:.1%} on average ({verdict}).")
            if nested < level - TOLERANCE:
                out.notes.append(f"Expect less than {level:.0%} on new recordings: the runs differ from each other "
                                 "more than the calibration can bound. Give more runs, or ask for a lower level.")
        if out.nested_runs:
            g, floor, worst = len(out.nested_runs), f"{level - TOLERANCE:.0%}", min(out.nested_runs)
            if out.short:
                out.notes.append(f"{out.short} of the {g} held-out runs covered less than {floor} calibrated without "
                                 f"them (worst {worst:.0%}): a new recording can fall short as they did, with a "
                                 f"chance of about {out.chance_short:.0%} (the runs taken as exchangeable).")
            else:
                out.notes.append(f"None of the {g} held-out runs covered less than {floor} calibrated without them "
                                 f"(worst {worst:.0%}); with {g}, a new recording can still fall short with a chance "
                                 f"of up to {out.chance_short:.0%}.")
        return out
