"""The critical path of a fit: which work waits for which, and how far more workers could take it.

A fit is a driver (this process: the stages, the selection's bookkeeping, the final identification)
that hands independent tasks to a pool (the selection's fold fits, the residual's candidates) and
reads their results. Inside :func:`tracing`, every pool (:func:`~identification.discovery.make_pool`)
runs each task here, when it is submitted, and times it, while offering as many workers as
:attr:`Trace.width` says, so the driver submits what a pool that wide would get at once. The
driver's own time is cut into segments at every submit and every read; a task depends on the
segment that submitted it, and the segment that reads its result depends on it. That is the
dependency graph a pool of any width runs:

* ``serial`` is the sum of every segment and every task: the CPU time of the work, one after another;
* ``critical`` is the longest chain through the graph: the wall time of the fit with as many workers
  as it can use, and ``serial / critical`` the most any number of workers could gain (Amdahl);
* :meth:`Trace.makespan` replays the graph on ``n`` workers (the tasks first come, first served, the
  driver on its own core) for the speed-up ``n`` workers could reach.

The fit's choices are those a pool of :attr:`Trace.width` workers makes (the selection submits every
fold of a step before reading one, so its early stops save less than one after another: the serial
time is what that many workers would spend).
"""

from __future__ import annotations

import contextlib
import heapq
import threading
import time
from collections.abc import Iterator
from concurrent.futures import Future
from dataclasses import dataclass, field

__all__ = ["Trace", "tracing", "active_trace", "in_background"]

#: The trace being recorded (None: pools run as asked).
_ACTIVE: list["Trace"] = []


@dataclass
class _Task:
    name: str
    seconds: float
    after: int  # the driver segment that submitted it
    read: int | None = None  # the first driver segment that read its result


@dataclass
class Trace:
    """Segments of the driver (``segments``: seconds, with the stage each ran in) and the pool's tasks.

    Parameters
    ----------
    width : int
        The workers every pool offers while tracing (what the driver submits at once).
    """

    width: int = 64
    segments: list[tuple[float, str]] = field(default_factory=list)
    tasks: list[_Task] = field(default_factory=list)
    stage: str = ""

    def __post_init__(self) -> None:
        self._since = time.perf_counter()

    # ------------------------------------------------------------------ recording
    def _cut(self, now: float | None = None) -> int:
        """Close the driver's current segment at ``now``; returns its index."""
        now = time.perf_counter() if now is None else now
        self.segments.append((now - self._since, self.stage))
        self._since = now
        return len(self.segments) - 1

    def run(self, name: str, fn, *args) -> Future:
        """Run a submitted task here and time it; its future records when the driver reads it."""
        after = self._cut()
        t0 = time.perf_counter()
        future = _TracedFuture(self, len(self.tasks))
        try:
            future.set_result(fn(*args))
        except Exception as exc:  # the task's own error, read where its result is
            future.set_exception(exc)
        t1 = time.perf_counter()
        self.tasks.append(_Task(name, t1 - t0, after))
        self._since = t1  # the driver goes on
        return future

    def _read(self, index: int) -> None:
        task = self.tasks[index]
        if task.read is None:
            task.read = self._cut() + 1

    @contextlib.contextmanager
    def label(self, stage: str) -> Iterator[None]:
        """The driver's segments inside are the ``stage``'s."""
        self._cut()
        previous, self.stage = self.stage, stage
        try:
            yield
        finally:
            self._cut()
            self.stage = previous

    def close(self) -> None:
        self._cut()

    # ------------------------------------------------------------------ reading
    @property
    def serial(self) -> float:
        """Seconds of all the work one after another (driver and tasks)."""
        return sum(s for s, _ in self.segments) + sum(t.seconds for t in self.tasks)

    @property
    def critical(self) -> float:
        """Seconds of the longest chain of dependent work (as many workers as the fit can use)."""
        return self.makespan(None)

    def makespan(self, workers: int | None) -> float:
        """The fit's wall time replayed with ``workers`` pool workers (None: unlimited), the tasks
        started in the order submitted as workers come free, the driver on its own core; a task nobody
        reads (a stopped spec's fold) takes a worker, but the fit does not wait for its end."""
        finish, ends, _ = self._replay(workers)
        return max([ends[-1] if ends else 0.0, *(finish[i] for i in self._read_tasks())])

    def critical_stages(self) -> dict[str, float]:
        """Per stage: the seconds of the critical path spent in it (its driver segments and the tasks they
        submitted), in the order the path runs through them."""
        finish, ends, waited = self._replay(None)
        path: list[tuple[str, float]] = []
        last_task = max(self._read_tasks(), key=finish.__getitem__, default=None)
        k = len(self.segments) - 1
        if last_task is not None and ends and finish[last_task] > ends[-1]:  # a task ends last
            path.append((self.segments[self.tasks[last_task].after][1], self.tasks[last_task].seconds))
            k = self.tasks[last_task].after
        while k >= 0:
            path.append((self.segments[k][1], self.segments[k][0]))
            task = waited[k]
            if task is not None:
                path.append((self.segments[self.tasks[task].after][1], self.tasks[task].seconds))
                k = self.tasks[task].after
            else:
                k -= 1
        out: dict[str, float] = {}
        for stage, seconds in reversed(path):
            if seconds > 0:
                out[stage] = out.get(stage, 0.0) + seconds
        return out

    def _read_tasks(self) -> list[int]:
        """The tasks whose result the driver read (a task nobody reads is killed with the pool)."""
        return [i for i, t in enumerate(self.tasks) if t.read is not None]

    def _replay(self, workers: int | None) -> tuple[dict[int, float], list[float], list[int | None]]:
        """The graph replayed on ``workers`` (None: unlimited): each task's end, each driver segment's end,
        and the task each segment waited for last (None: it began where the segment before it ended)."""
        free: list[float] = [0.0] * (workers or 0)
        reads: dict[int, list[int]] = {}
        submitted: dict[int, list[int]] = {}
        for i, t in enumerate(self.tasks):
            submitted.setdefault(t.after, []).append(i)
            if t.read is not None:
                reads.setdefault(t.read, []).append(i)
        finish: dict[int, float] = {}
        ends: list[float] = []
        waited: list[int | None] = []
        clock = 0.0
        for k, (seconds, _) in enumerate(self.segments):
            last = max(reads.get(k, ()), key=finish.__getitem__, default=None)
            waited.append(last if last is not None and finish[last] > clock else None)
            if waited[-1] is not None:
                clock = finish[last]
            clock += seconds
            ends.append(clock)
            for i in submitted.get(k, ()):
                start = clock if workers is None else max(clock, heapq.heappop(free))
                finish[i] = start + self.tasks[i].seconds
                if workers is not None:
                    heapq.heappush(free, finish[i])
        return finish, ends, waited

    def by_stage(self) -> dict[str, tuple[float, float]]:
        """Per stage: (the driver's seconds, the seconds of the tasks it submitted)."""
        out: dict[str, list[float]] = {}
        for seconds, stage in self.segments:
            out.setdefault(stage, [0.0, 0.0])[0] += seconds
        for t in self.tasks:
            out.setdefault(self.segments[t.after][1], [0.0, 0.0])[1] += t.seconds
        return {k: (v[0], v[1]) for k, v in out.items()}


class _TracedFuture(Future):
    """A finished task's future that tells the trace when the driver first reads it."""

    def __init__(self, trace: Trace, index: int):
        super().__init__()
        self._trace, self._index = trace, index

    def result(self, timeout=None):
        self._trace._read(self._index)
        return super().result(timeout)

    def exception(self, timeout=None):
        self._trace._read(self._index)
        return super().exception(timeout)


def active_trace() -> Trace | None:
    """The trace being recorded, or None."""
    return _ACTIVE[-1] if _ACTIVE else None


@contextlib.contextmanager
def tracing(width: int = 64) -> Iterator[Trace]:
    """Record the work inside as a :class:`Trace` (every pool runs its tasks here, offering ``width``
    workers)."""
    trace = Trace(width)
    _ACTIVE.append(trace)
    try:
        yield trace
    finally:
        _ACTIVE.remove(trace)
        trace.close()


@contextlib.contextmanager
def stage(name: str) -> Iterator[None]:
    """Label the driver's work inside as ``name`` in the active trace (nothing when none is)."""
    trace = active_trace()
    if trace is None:
        yield
        return
    with trace.label(name):
        yield


def in_background(name: str, fn, *args) -> Future:
    """``fn(*args)`` on a thread of its own while the driver goes on: for work that mostly waits on
    something outside Python (a C compiler). Its future holds the result or the error. While tracing,
    a task of the trace (run here, timed, and waited for where it is read)."""
    trace = active_trace()
    if trace is not None:
        return trace.run(name, fn, *args)
    future: Future = Future()

    def run() -> None:
        try:
            future.set_result(fn(*args))
        except BaseException as exc:  # read where the result is
            future.set_exception(exc)

    threading.Thread(target=run, name=name, daemon=True).start()  # a Ctrl-C does not wait for it
    return future
