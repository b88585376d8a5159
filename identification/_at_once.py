"""IPOPT starts of one problem solved at once, each on a thread of its own.

CasADi releases the GIL while a compiled rollout runs, which is most of a start's time, so the starts
of a multi-start run side by side on the cores of the machine the fit's driver runs on. Each thread
solves on a fork of the problem (:meth:`LeastSquaresProblem.fork`: its own Jacobian buffers and IPOPT
instances). A start is the same solve on any thread, so the answer does not depend on how many run at
once. Inside :func:`~identification._trace.tracing` each start is a traced task instead,
for the fit's critical path.
"""

from __future__ import annotations

import queue
import threading
from concurrent.futures import Future, ThreadPoolExecutor

import numpy as np

from ._problem import LeastSquaresProblem, Solve

__all__ = ["AtOnce"]


class AtOnce:
    """Solve starts of ``problem`` on up to ``threads`` threads; a context manager whose exit cancels
    the starts still running (their results are not wanted) and waits for them.

    ``submit(candidate, options)`` returns a future of the :class:`Solve` (None for a start cancelled
    before it began)."""

    def __init__(self, problem: LeastSquaresProblem, threads: int):
        from ._trace import active_trace

        self.problem = problem
        self.idle: queue.SimpleQueue = queue.SimpleQueue()
        self.idle.put(problem)
        self.cancelled = threading.Event()
        self.trace = active_trace()
        self.pool = None if self.trace is not None else ThreadPoolExecutor(threads, thread_name_prefix="ipopt")

    def submit(self, candidate: np.ndarray, options: dict) -> Future:
        if self.trace is not None:
            return self.trace.run("ipopt start", self._solve, candidate, options)
        return self.pool.submit(self._solve, candidate, options)

    def _solve(self, candidate: np.ndarray, options: dict) -> Solve | None:
        if self.cancelled.is_set():
            return None
        try:
            problem = self.idle.get_nowait()
        except queue.Empty:  # every fork busy: one more (at most ``threads`` run at once)
            problem = self.problem.fork()
        try:
            solver = problem.solver(None, False, options)
            solver.stop.cancel = self.cancelled
            try:
                return problem.solve(solver, problem.scaled(candidate))
            finally:
                solver.stop.cancel = None
        finally:
            self.idle.put(problem)

    def __enter__(self) -> "AtOnce":
        return self

    def __exit__(self, *exc) -> None:
        self.cancelled.set()
        if self.pool is not None:
            self.pool.shutdown(wait=True, cancel_futures=True)
