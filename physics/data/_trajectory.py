"""The :class:`Trajectory` container and small collections of trajectories."""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, NamedTuple, overload

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._atomic import atomic_path
from ._checks import as_float_array, check_rate, first_nonfinite
from ._errors import DataError
from ._resample import resample as _resample

__all__ = ["Trajectory", "Dataset", "DataSplit"]

#: Column names used by :meth:`Trajectory.to_csv`; extra columns may not reuse them.
RESERVED_COLUMNS = ("time", "u", "y")


def _frozen(arr: NDArray[np.float64]) -> NDArray[np.float64]:
    out = np.array(arr, dtype=np.float64, copy=True)
    out.setflags(write=False)
    return out


@dataclass(frozen=True, eq=False)
class Trajectory:
    """One uniformly or irregularly sampled input/output record.

    Arrays are copied to read-only float64 arrays, so a trajectory never
    changes after it is built.

    Parameters
    ----------
    time : array_like, shape (n,)
        Time stamps in seconds, strictly increasing.
    u, y : array_like, shape (n,)
        Input and output samples.
    input_name, output_name : str
        Physical names of ``u`` and ``y`` (e.g. ``"Tendon Disp."``).
    input_unit, output_unit : str
        Their units (e.g. ``"mm"``, ``"deg"``).
    source : str
        Where the data came from (file name, generator, ...).
    extra : dict of str to array_like, shape (n,)
        Further columns of the same length (e.g. true internal states).
    meta : dict
        Free-form metadata (``rate_hz``, ``frequency_hz``, ``set``, ...).

    Raises
    ------
    DataError
        Not 1-D, unequal lengths, NaN/inf (first bad index and array named),
        or time not strictly increasing (index named). Raw data with repeated
        stamps go through :meth:`from_raw` instead.

    Examples
    --------
    >>> t = np.arange(5) * 0.04
    >>> traj = Trajectory(t, u=np.sin(t), y=2 * np.sin(t), input_unit="mm")
    >>> traj.n, round(traj.dt, 3), round(traj.duration, 2)
    (5, 0.04, 0.16)
    >>> traj.swap().input_name
    'y'
    """

    time: NDArray[np.float64]
    u: NDArray[np.float64]
    y: NDArray[np.float64]
    input_name: str = "u"
    output_name: str = "y"
    input_unit: str = ""
    output_unit: str = ""
    source: str = ""
    extra: dict[str, NDArray[np.float64]] = field(default_factory=dict)
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        arrays = {"time": self.time, "u": self.u, "y": self.y}
        if not isinstance(self.extra, Mapping):
            raise DataError(f"extra must be a dict of column name -> array; got {type(self.extra).__name__}.")
        for key in self.extra:
            if not isinstance(key, str) or key in RESERVED_COLUMNS:
                raise DataError(
                    f"extra column name {key!r} is not allowed: names must be strings other than "
                    f"{', '.join(RESERVED_COLUMNS)}. Rename the extra column."
                )
            arrays[f"extra[{key!r}]"] = self.extra[key]
        converted = {name: as_float_array(a, name) for name, a in arrays.items()}
        lengths = {name: a.shape[0] for name, a in converted.items()}
        if len(set(lengths.values())) > 1:
            listing = ", ".join(f"{name} has {n}" for name, n in lengths.items())
            raise DataError(f"Trajectory arrays must have equal lengths; {listing} samples.")
        if lengths["time"] < 1:
            raise DataError("Trajectory needs at least one sample; got empty arrays.")
        for name, a in converted.items():
            i = first_nonfinite(a)
            if i is not None:
                raise DataError(
                    f"Trajectory {name} has a non-finite value ({float(a[i])!r}) at index {i}"
                    f"{_where(self.source)}. Remove or interpolate NaN/inf samples first."
                )
        t = converted["time"]
        bad = np.flatnonzero(np.diff(t) <= 0)
        if bad.size:
            i = int(bad[0]) + 1
            raise DataError(
                f"Trajectory time must be strictly increasing, but time[{i}] = {float(t[i])!r} <= "
                f"time[{i - 1}] = {float(t[i - 1])!r}{_where(self.source)}. For raw data with repeated or "
                "irregular stamps use Trajectory.from_raw(...) or load_csv(..., rate_hz=...) to resample."
            )
        set_ = object.__setattr__
        set_(self, "time", _frozen(t))
        set_(self, "u", _frozen(converted["u"]))
        set_(self, "y", _frozen(converted["y"]))
        set_(self, "extra", {k: _frozen(converted[f"extra[{k!r}]"]) for k in self.extra})
        set_(self, "meta", dict(self.meta))

    # ------------------------------------------------------------------ builders
    @classmethod
    def from_raw(
        cls, time: ArrayLike, u: ArrayLike, y: ArrayLike, rate_hz: float = 25.0, **kwargs: Any
    ) -> Trajectory:
        """Resample raw samples (irregular, possibly repeated stamps) into a trajectory.

        Parameters
        ----------
        time, u, y : array_like, shape (n,)
            Raw samples; ``time`` non-decreasing (a decrease is an error naming
            its index).
        rate_hz : float, default 25.0
            Target rate; see :func:`resample`.
        **kwargs
            Other :class:`Trajectory` fields (names, units, ``extra``, ``meta``).
            ``meta['rate_hz']`` is set to ``rate_hz``.
        """
        extra = dict(kwargs.pop("extra", {}) or {})
        columns = [as_float_array(u, "u"), as_float_array(y, "y")]
        columns += [as_float_array(extra[k], f"extra[{k!r}]") for k in extra]
        t = as_float_array(time, "time")
        lengths = [t.size] + [c.size for c in columns]
        if len(set(lengths)) > 1:
            names = ["time", "u", "y"] + [f"extra[{k!r}]" for k in extra]
            listing = ", ".join(f"{n} has {m}" for n, m in zip(names, lengths))
            raise DataError(f"raw arrays must have equal lengths; {listing} samples.")
        new_t, values = _resample(t, np.column_stack(columns), rate_hz)
        meta = dict(kwargs.pop("meta", {}) or {})
        meta["rate_hz"] = float(rate_hz)
        new_extra = {k: values[:, 2 + j] for j, k in enumerate(extra)}
        return cls(new_t, values[:, 0], values[:, 1], extra=new_extra, meta=meta, **kwargs)

    # ---------------------------------------------------------------- properties
    @property
    def n(self) -> int:
        """Number of samples."""
        return int(self.time.shape[0])

    @property
    def dt(self) -> float:
        """Median time step in seconds (nan for a single sample); of a resampled trajectory, ``1 / rate_hz``
        where its stamps are too coarse to carry it (unix time: 1.7e9 + k/25 steps by 0.04 +/- 2.4e-7)."""
        if self.n < 2:
            return float("nan")
        step = float(np.median(np.diff(self.time)))
        rate = self.meta.get("rate_hz") if isinstance(self.meta, dict) else None
        # only where the stamps' float64 rounding explains the difference (a stale rate_hz is not trusted)
        resolution = 4.0 * float(np.spacing(np.max(np.abs(self.time))))
        if rate and abs(step * float(rate) - 1.0) > 1e-9 and abs(step - 1.0 / float(rate)) <= resolution:
            return 1.0 / float(rate)
        return step

    @property
    def duration(self) -> float:
        """``time[-1] - time[0]`` in seconds."""
        return float(self.time[-1] - self.time[0])

    # ---------------------------------------------------------------- transforms
    def resample(self, rate_hz: float = 25.0) -> Trajectory:
        """Return this trajectory resampled at ``rate_hz`` (see :func:`resample`)."""
        check_rate(rate_hz)
        return Trajectory.from_raw(
            self.time, self.u, self.y, rate_hz=rate_hz,
            input_name=self.input_name, output_name=self.output_name,
            input_unit=self.input_unit, output_unit=self.output_unit,
            source=self.source, extra=self.extra, meta=self.meta,
        )

    def swap(self) -> Trajectory:
        """Return the inverse-model view: input and output (with names and units) swapped."""
        return replace(
            self, u=self.y, y=self.u,
            input_name=self.output_name, output_name=self.input_name,
            input_unit=self.output_unit, output_unit=self.input_unit,
        )

    def segment(self, start: int, stop: int | None = None) -> Trajectory:
        """Samples ``start:stop`` as a trajectory of their own (every column, names and meta kept).

        ``traj.segment(0, k)`` is a warm-up window of ``k`` measured samples and
        ``traj.segment(k)`` the rest, the split :func:`warmup_split` makes.
        """
        n = self.n
        stop = n if stop is None else int(stop)
        start = int(start)
        if not 0 <= start < stop <= n:
            raise DataError(f"A segment needs 0 <= start < stop <= n = {n} samples; got start={start}, "
                            f"stop={stop}{_where(self.source)}.")
        return replace(self, time=self.time[start:stop], u=self.u[start:stop], y=self.y[start:stop],
                       extra={k: v[start:stop] for k, v in self.extra.items()})

    def to_csv(self, path: str | os.PathLike[str]) -> Path:
        """Write ``time,u,y,<extra names>`` to ``path`` atomically and return the path.

        Values are written with 17 significant digits, so :func:`load_csv`
        reads them back exactly. Names, units and ``meta`` are not stored.
        The file is written to a temporary file in the same folder and moved
        into place with :func:`os.replace`, so readers never see half a file.
        """
        path = Path(path)
        for key in self.extra:
            if any(c in key for c in ',"\n\r') or key != key.strip() or not key:
                raise DataError(
                    f"extra column name {key!r} cannot be written as a plain CSV header "
                    "(no commas, quotes, newlines or surrounding spaces). Rename the column."
                )
        header = ",".join(list(RESERVED_COLUMNS) + list(self.extra))
        table = np.column_stack([self.time, self.u, self.y, *self.extra.values()])
        with atomic_path(path) as tmp:
            np.savetxt(tmp, table, fmt="%.17g", delimiter=",", header=header, comments="")
        return path

    def __repr__(self) -> str:
        return (
            f"Trajectory(n={self.n}, duration={self.duration:.3g} s, "
            f"u={self.input_name!r} [{self.input_unit}], y={self.output_name!r} [{self.output_unit}], "
            f"source={self.source!r}, extra={list(self.extra)})"
        )


def _where(source: str) -> str:
    return f" (source {source!r})" if source else ""


class DataSplit(NamedTuple):
    """A train/test pair of :class:`Dataset`."""

    train: Dataset
    test: Dataset


class Dataset(Sequence[Trajectory]):
    """An immutable sequence of :class:`Trajectory` (supports ``len``, iteration, indexing).

    Examples
    --------
    >>> t = np.arange(4.0)
    >>> ds = Dataset([Trajectory(t, t, t, source="a"), Trajectory(t, t, -t, source="b")])
    >>> ds.names
    ('a', 'b')
    >>> train, test = ds.split(test=lambda tr: tr.source == "b")
    >>> len(train), len(test)
    (1, 1)
    """

    __slots__ = ("_items",)

    def __init__(self, trajectories: Iterable[Trajectory] = ()) -> None:
        items = tuple(trajectories)
        for i, item in enumerate(items):
            if not isinstance(item, Trajectory):
                raise DataError(f"Dataset item {i} is a {type(item).__name__}, not a Trajectory.")
        self._items = items

    def __len__(self) -> int:
        return len(self._items)

    @overload
    def __getitem__(self, index: int) -> Trajectory: ...
    @overload
    def __getitem__(self, index: slice) -> Dataset: ...

    def __getitem__(self, index: int | slice) -> Trajectory | Dataset:
        if isinstance(index, slice):
            return Dataset(self._items[index])
        return self._items[index]

    def __iter__(self) -> Iterator[Trajectory]:
        return iter(self._items)

    def __repr__(self) -> str:
        return f"Dataset({len(self)} trajectories: {list(self.names)})"

    @property
    def names(self) -> tuple[str, ...]:
        """The ``source`` of each trajectory."""
        return tuple(t.source for t in self._items)

    def filter(self, keep: Callable[[Trajectory], bool]) -> Dataset:
        """Return the trajectories for which ``keep(trajectory)`` is true."""
        return Dataset(t for t in self._items if keep(t))

    def split(self, test: Callable[[Trajectory], bool] | Sequence[int]) -> DataSplit:
        """Split into ``(train, test)``.

        Parameters
        ----------
        test : callable or sequence of int
            A predicate that is true for test trajectories, or the indices of
            the test trajectories (negative indices allowed).
        """
        if callable(test):
            is_test = [bool(test(t)) for t in self._items]
        else:
            is_test = [False] * len(self)
            for idx in test:
                if isinstance(idx, bool) or not isinstance(idx, (int, np.integer)):
                    raise DataError(f"split(test=...) indices must be integers; got {idx!r}.")
                if not -len(self) <= idx < len(self):
                    raise DataError(
                        f"split(test=...) index {idx} is out of range for a Dataset of {len(self)} trajectories."
                    )
                is_test[int(idx)] = True
        train = Dataset(t for t, flag in zip(self._items, is_test) if not flag)
        tests = Dataset(t for t, flag in zip(self._items, is_test) if flag)
        return DataSplit(train, tests)
