"""Tendon-displacement commands as functions of continuous time.

Every signal is a small immutable object: ``signal(t)`` evaluates the command
(mm) at any times (s) in ``[0, signal.duration]``, so a simulator can integrate
finer than it samples, and ``signal.sample(rate_hz)`` returns the ``(time, q)``
arrays at a rate.
"""

from __future__ import annotations

import abc
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

#: Baselines of the seed paper's decaying sinusoid: name -> (c, q_offset in mm).
BASELINES: dict[str, tuple[float, float]] = {"zero": (1.0, 0.0), "mid": (0.0, 3.0), "end": (-1.0, 6.0)}

#: Physical travel of the tendon (mm) that multisines and random steps stay within by default.
TRAVEL_MM = (0.0, 6.0)


class Signal(abc.ABC):
    """Abstract command ``q(t)`` (mm) on ``0 <= t <= duration`` (s)."""

    @property
    @abc.abstractmethod
    def duration(self) -> float:
        """Length of the command in seconds."""

    @abc.abstractmethod
    def __call__(self, t: ArrayLike) -> NDArray[np.float64]:
        """Command (mm) at the times ``t`` (s)."""

    @property
    @abc.abstractmethod
    def name(self) -> str:
        """A short, file-name-safe description (e.g. ``'decaying_f0.10_mid'``)."""

    def describe(self) -> dict[str, Any]:
        """The signal's settings, for a trajectory's ``meta``."""
        return {"signal": type(self).__name__, "duration_s": self.duration}

    def sample(self, rate_hz: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """``(time, q)`` at ``rate_hz``, from 0 up to and including the last whole sample."""
        time = sample_times(self.duration, rate_hz)
        return time, self(time)


def sample_times(duration: float, rate_hz: float) -> NDArray[np.float64]:
    """``0, 1/rate, ...`` up to ``duration`` (inclusive, to within 1e-9 of a sample)."""
    if not (np.isfinite(rate_hz) and rate_hz > 0):
        raise ValueError(f"The sample rate must be > 0 Hz. Got {rate_hz} instead.")
    n = int(math.floor(duration * rate_hz + 1e-9)) + 1
    return np.arange(n) / float(rate_hz)


def _positive(name: str, value: float, unit: str) -> float:
    value = float(value)
    if not (np.isfinite(value) and value > 0):
        raise ValueError(f"The '{name}' of the signal must be > 0 {unit}. Got {value} instead.")
    return value


def check_seed(owner: str, seed: object, allow_none: bool = False) -> None:
    """Refuse a ``seed`` numpy's generators cannot take (a negative number, a fraction, a bool), naming it
    and ``owner`` (numpy's own message, "expected non-negative integer", names neither)."""
    from numbers import Integral

    if seed is None and allow_none:
        return
    if isinstance(seed, bool) or not isinstance(seed, Integral) or seed < 0:
        what = "a whole number >= 0" + (", or None for fresh randomness" if allow_none else "")
        raise ValueError(f"The 'seed' of {owner} must be {what}. Got {seed!r} instead.")


def _interval(name: str, pair, unit: str, positive: bool = False) -> tuple[float, float]:
    lo, hi = (float(v) for v in pair)
    if not (np.isfinite(lo) and np.isfinite(hi) and lo <= hi) or (positive and lo <= 0):
        need = "0 < low <= high" if positive else "low <= high"
        raise ValueError(f"The '{name}' of the signal must be (low, high) {unit} with {need}. "
                         f"Got {pair!r} instead.")
    return lo, hi


@dataclass(frozen=True)
class DecayingSinusoid(Signal):
    """The seed paper's training command.

    ``q(t) = q_max exp(-tau t) (sin(2 pi f t - pi/2) + c) + q_offset`` with
    ``tau = f ln(7/6)`` over ``cycles`` periods. The baseline sets ``(c, q_offset)``:
    ``'zero'`` (1, 0 mm), ``'mid'`` (0, 3 mm), ``'end'`` (-1, 6 mm). With the
    paper's ``q_max = 3`` mm each starts at rest at 0 mm and stays within [0, 6] mm;
    ``q_max_mm`` scales the amplitude (the offsets stay) for out-of-range tests.

    Examples
    --------
    >>> s = DecayingSinusoid(frequency_hz=0.5, baseline="end")
    >>> s.duration, float(s(0.0)), float(s(1.0))
    (14.0, 0.0, 6.0)
    """

    frequency_hz: float = 0.1
    baseline: str = "zero"
    q_max_mm: float = 3.0
    cycles: float = 7.0

    def __post_init__(self) -> None:
        _positive("frequency_hz", self.frequency_hz, "Hz")
        _positive("q_max_mm", self.q_max_mm, "mm")
        _positive("cycles", self.cycles, "")
        if self.baseline not in BASELINES:
            raise ValueError(f"Unknown baseline '{self.baseline}'. Must be one of: {', '.join(BASELINES)}.")

    @property
    def tau(self) -> float:
        """Decay rate (1/s): ``f ln(7/6)``."""
        return self.frequency_hz * math.log(7.0 / 6.0)

    @property
    def duration(self) -> float:
        return self.cycles / self.frequency_hz

    @property
    def name(self) -> str:
        scale = "" if self.q_max_mm == 3.0 else f"_q{self.q_max_mm:g}"
        return f"decaying_f{self.frequency_hz:.2f}_{self.baseline}{scale}"

    def __call__(self, t: ArrayLike) -> NDArray[np.float64]:
        t = np.asarray(t, dtype=float)
        c, offset = BASELINES[self.baseline]
        phase = 2 * np.pi * self.frequency_hz * t - np.pi / 2
        return self.q_max_mm * np.exp(-self.tau * t) * (np.sin(phase) + c) + offset

    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "frequency_hz": self.frequency_hz, "baseline": self.baseline,
                "q_max_mm": self.q_max_mm, "cycles": self.cycles}


@dataclass(frozen=True)
class Multisine(Signal):
    """A sum of ``n_tones`` sines spread evenly over ``band_hz`` with seeded random phases.

    The sum is shifted and scaled so that it spans exactly ``range_mm`` over its
    duration (default the tendon's travel, 0-6 mm). Tone frequencies are whole
    multiples of ``1 / duration_s`` so the command is periodic over its duration.

    Examples
    --------
    >>> s = Multisine(duration_s=30, seed=1)
    >>> _, q = s.sample(25.0)
    >>> bool(q.min() >= 0.0 and q.max() <= 6.0)
    True
    """

    duration_s: float = 60.0
    band_hz: tuple[float, float] = (0.05, 0.5)
    n_tones: int = 8
    range_mm: tuple[float, float] = TRAVEL_MM
    seed: int = 0
    _tones: NDArray[np.float64] = field(init=False, repr=False, compare=False)
    _phases: NDArray[np.float64] = field(init=False, repr=False, compare=False)
    _shift: float = field(init=False, repr=False, compare=False)
    _scale: float = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        _positive("duration_s", self.duration_s, "s")
        check_seed("Multisine", self.seed)
        lo, hi = _interval("band_hz", self.band_hz, "Hz", positive=True)
        _interval("range_mm", self.range_mm, "mm")
        if int(self.n_tones) != self.n_tones or self.n_tones < 1:
            raise ValueError(f"The 'n_tones' of the signal must be a whole number >= 1. Got {self.n_tones} instead.")
        base = 1.0 / self.duration_s
        harmonics = np.unique(np.round(np.linspace(lo, hi, int(self.n_tones)) / base).clip(min=1))
        tones = harmonics * base
        phases = np.random.default_rng(self.seed).uniform(0, 2 * np.pi, tones.size)
        set_ = object.__setattr__
        set_(self, "_tones", tones)
        set_(self, "_phases", phases)
        raw = self._raw(np.linspace(0.0, self.duration_s, int(self.duration_s * 200 * hi) + 2001))
        span = raw.max() - raw.min()
        set_(self, "_shift", float(raw.min()))
        set_(self, "_scale", float((self.range_mm[1] - self.range_mm[0]) / span))

    def _raw(self, t: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.sin(2 * np.pi * self._tones * t[..., None] + self._phases).sum(axis=-1)

    @property
    def duration(self) -> float:
        return float(self.duration_s)

    @property
    def name(self) -> str:
        return f"multisine_s{self.seed}"

    def __call__(self, t: ArrayLike) -> NDArray[np.float64]:
        t = np.asarray(t, dtype=float)
        q = self.range_mm[0] + self._scale * (self._raw(t) - self._shift)
        return np.clip(q, *self.range_mm)  # the grid's min/max may miss the true extremes by ~1e-4

    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "band_hz": list(self.band_hz), "n_tones": int(self.n_tones),
                "range_mm": list(self.range_mm), "seed": self.seed,
                "tones_hz": self._tones.tolist()}


@dataclass(frozen=True)
class RandomSteps(Signal):
    """Piecewise-constant command: levels uniform in ``levels_mm``, held for times uniform in ``hold_s``.

    Examples
    --------
    >>> s = RandomSteps(duration_s=20, seed=3)
    >>> bool(len(np.unique(s.sample(25.0)[1])) > 3)
    True
    """

    duration_s: float = 60.0
    hold_s: tuple[float, float] = (1.0, 4.0)
    levels_mm: tuple[float, float] = TRAVEL_MM
    seed: int = 0
    _switch_s: NDArray[np.float64] = field(init=False, repr=False, compare=False)
    _levels: NDArray[np.float64] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        _positive("duration_s", self.duration_s, "s")
        check_seed("RandomSteps", self.seed)
        h_lo, h_hi = _interval("hold_s", self.hold_s, "s", positive=True)
        q_lo, q_hi = _interval("levels_mm", self.levels_mm, "mm")
        rng = np.random.default_rng(self.seed)
        holds = []
        while sum(holds) <= self.duration_s:
            holds.append(rng.uniform(h_lo, h_hi))
        object.__setattr__(self, "_switch_s", np.cumsum(holds)[:-1])
        object.__setattr__(self, "_levels", rng.uniform(q_lo, q_hi, len(holds)))

    @property
    def duration(self) -> float:
        return float(self.duration_s)

    @property
    def name(self) -> str:
        return f"steps_s{self.seed}"

    def __call__(self, t: ArrayLike) -> NDArray[np.float64]:
        t = np.asarray(t, dtype=float)
        return self._levels[np.searchsorted(self._switch_s, t, side="right")]

    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "hold_s": list(self.hold_s), "levels_mm": list(self.levels_mm),
                "seed": self.seed}


@dataclass(frozen=True, eq=False)
class Command(Signal):
    """A user-supplied command ``q`` (mm) at times ``time`` (s), interpolated linearly.

    Time is counted from ``time[0]``, so ``command(0)`` is ``q[0]``.

    Examples
    --------
    >>> c = Command([0.0, 1.0, 2.0], [0.0, 2.0, 1.0])
    >>> float(c(0.5)), float(c(1.5)), c.duration
    (1.0, 1.5, 2.0)
    """

    time: NDArray[np.float64]
    q: NDArray[np.float64]
    label: str = "command"

    def __post_init__(self) -> None:
        t = np.array(self.time, dtype=float)
        q = np.array(self.q, dtype=float)
        if t.ndim != 1 or q.shape != t.shape or t.size < 2:
            raise ValueError(f"A command needs 1-D time and q of equal length >= 2; got shapes {t.shape} and {q.shape}.")
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(q))):
            raise ValueError("A command's time and q must be finite; interpolate or drop NaN/inf samples first.")
        bad = np.flatnonzero(np.diff(t) <= 0)
        if bad.size:
            raise ValueError(f"A command's time must be strictly increasing; time[{bad[0] + 1}] <= time[{bad[0]}].")
        t = t - t[0]
        t.setflags(write=False)
        q.setflags(write=False)
        object.__setattr__(self, "time", t)
        object.__setattr__(self, "q", q)

    @property
    def duration(self) -> float:
        return float(self.time[-1])

    @property
    def name(self) -> str:
        return self.label

    def __call__(self, t: ArrayLike) -> NDArray[np.float64]:
        return np.interp(np.asarray(t, dtype=float), self.time, self.q)
