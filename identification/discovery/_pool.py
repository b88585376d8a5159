"""Where the selection's fold fits run: here, in local worker processes, or on a Dask cluster.

A pool takes ``submit(fn, *args)`` and hands back futures; :meth:`Pool.first` waits for one to finish.
Every fold fit is a function of plain data whose answer is the same in any process, so the pool
changes when a number arrives, never the number (:class:`identification.discovery._select._Scorer`
reads each spec's folds in order whatever order they finish in).
"""

from __future__ import annotations

import atexit
import os
import shutil
import tempfile
from concurrent.futures import FIRST_COMPLETED, Future, wait
from dataclasses import dataclass
from typing import Any

from identification._errors import IdentificationError
from physics.data._checks import check_device

__all__ = ["Workers", "make_pool", "check_jobs", "driver_threads"]


@dataclass(frozen=True)
class Workers:
    """Where a selection's fold fits run: here, in ``n_jobs`` local worker processes, or on a Dask cluster.

    It changes when the numbers arrive, never the numbers: every fold fit is a function of plain data
    whose answer is the same in any process. ``select_physics(workers=...)``, and ``compare`` or
    ``fit_model_dir`` through their physics policy (``PhysicsPolicy(select_options={"workers": ...})``).

    Parameters
    ----------
    n_jobs : int
        Local worker processes (joblib's loky executor; -1: one per core; 1: here, one after another).
    scheduler : str or dask.distributed.Client, optional
        Run the fits on the workers of a running Dask cluster instead: its address
        (``tcp://host:8786``) or a ``Client``.
    device : {"cpu", "auto", "cuda", "cuda:N"}
        Where the networks of a fit or a comparison train (``TrainingSettings.device``: ``"auto"`` a CUDA
        GPU where torch sees one); the fold fits of the physics run on the CPU.

    Examples
    --------
    >>> from identification.discovery import Workers
    >>> Workers(n_jobs=4)
    Workers(n_jobs=4, scheduler=None, device='cpu')
    """

    n_jobs: int = 1
    scheduler: Any = None
    device: str = "cpu"

    def __post_init__(self) -> None:
        check_jobs(self.n_jobs)
        check_device(self.device, IdentificationError)
        if self.scheduler is not None and not (isinstance(self.scheduler, str) and self.scheduler.strip()) \
                and not hasattr(self.scheduler, "submit"):
            raise IdentificationError(f"scheduler must be a Dask scheduler's address such as 'tcp://host:8786', or a "
                                      f"dask.distributed.Client. Got {self.scheduler!r} instead.")

    def to_dict(self) -> dict[str, Any]:
        """``{"n_jobs": ..., "scheduler": ..., "device": ...}`` as a run records it (a Client as its text)."""
        return {"n_jobs": self.n_jobs, "scheduler": None if self.scheduler is None else str(self.scheduler),
                "device": self.device}


def check_jobs(n_jobs) -> int:
    """``n_jobs`` as a count of worker processes (-1: one per core)."""
    if isinstance(n_jobs, bool) or not isinstance(n_jobs, int) or n_jobs == 0 or n_jobs < -1:
        raise IdentificationError(f"n_jobs must be a whole number >= 1, or -1 for one per core. Got {n_jobs!r} instead.")
    if n_jobs == -1:
        return max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1)
    return int(n_jobs)


class _Serial:
    """Each fit runs when submitted, in this process."""

    workers = 1
    #: A folder the workers share compiled libraries through (``_sensitivity.shared_compiles``), or None.
    shared = None

    def submit(self, fn, *args) -> Future:
        future: Future = Future()
        try:
            future.set_result(fn(*args))
        except Exception as exc:  # the fit's own error, read where its result is (a Ctrl-C goes on up)
            future.set_exception(exc)
        return future

    def first(self, futures) -> Future:
        return next(iter(futures))

    def cancel(self, futures) -> None:
        pass

    def abort(self, futures) -> None:
        """Stop on an interrupt: the fits in flight are not waited for."""
        self.cancel(futures)

    def close(self) -> None:
        pass


#: The workers' BLAS and OpenMP run one thread each: the workers already take every core, and two
#: workers of two threads each on two cores spent twice the time per fit (NiTi's selection: 25.5 s
#: in 2 workers against 21.1 s serial; 13.7 s with one thread each). Dask's workers start so too.
ONE_THREAD = {name: "1" for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")}


class _Traced(_Serial):
    """Inside :func:`~identification._trace.tracing`: each task runs here when submitted and is
    timed, while the pool offers the trace's ``width`` workers (the driver submits what that many get)."""

    def __init__(self, trace):
        self.trace, self.workers = trace, trace.width

    def submit(self, fn, *args) -> Future:
        what = next((a for a in args if isinstance(a, str)), "")  # a fold's spec, a candidate's name
        return self.trace.run(f"{fn.__name__} {what}".strip(), fn, *args)


#: The local workers' TMPDIR: one folder of this process, removed when it exits and emptied when its
#: workers are killed, so the scratch folders of a compile they ran (``hyst_jit_*``, ``hyst_cc_*``) go
#: with them (a killed worker runs no clean-up of its own).
_WORKER_TMP: list[str] = []


def _worker_tmp() -> str:
    if not _WORKER_TMP or not os.path.isdir(_WORKER_TMP[0]):
        _WORKER_TMP[:] = [tempfile.mkdtemp(prefix="hyst_workers_")]
        atexit.register(shutil.rmtree, _WORKER_TMP[0], True)
    return _WORKER_TMP[0]




def _worker_start() -> None:
    """A local worker's set-up: its progress bars (tqdm, whose default lock is a named semaphore the
    stdlib's resource tracker keeps) take a lock of the worker's own, so a worker killed on a Ctrl-C or
    SIGTERM leaves no semaphore behind, nor the tracker's "leaked semaphore objects" warning under the
    command's message."""
    import threading

    from tqdm import tqdm

    tqdm.set_lock(threading.RLock())


#: The local workers' executor (loky's reusable one), for :func:`end_local_workers`.
_EXECUTORS: list = []


def end_local_workers() -> None:
    """Stop this process's local workers now and remove their TMPDIR: a command that ends calls it, so
    loky's exit hook, which would otherwise wait for them as the interpreter exits, has nothing left to
    wait for (a Ctrl-C there printed a KeyboardInterrupt traceback after the command's output)."""
    for executor in _EXECUTORS:
        executor.shutdown(wait=True, kill_workers=True)
    _EXECUTORS.clear()
    if _WORKER_TMP:
        shutil.rmtree(_WORKER_TMP[0], ignore_errors=True)


class _Local(_Serial):
    """Worker processes on this machine (joblib's loky executor, reused between calls)."""

    def __init__(self, workers: int):
        from joblib.externals.loky import get_reusable_executor

        self.workers = workers
        # the same env every time (or loky would start new workers): one TMPDIR for this process's workers
        self.executor = get_reusable_executor(max_workers=workers, env={**ONE_THREAD, "TMPDIR": _worker_tmp()},
                                              initializer=_worker_start)
        _EXECUTORS[:] = [self.executor]
        self._unread: list[Future] = []  # cancelled fits that were already running
        # one worker compiles a spec's steps, the others load them (a compile costs about a fold's fit)
        self._folder = tempfile.TemporaryDirectory(prefix="hyst_select_")
        self.shared = self._folder.name

    def submit(self, fn, *args) -> Future:
        return self.executor.submit(fn, *args)

    def first(self, futures) -> Future:
        done, _ = wait(list(futures), return_when=FIRST_COMPLETED)
        return next(f for f in futures if f in done)  # the earliest submitted of those done

    def cancel(self, futures) -> None:
        # a fit already running cannot be cancelled: it runs on, unread, and is remembered for close()
        self._unread = [f for f in self._unread if not f.done()]
        self._unread += [f for f in futures if not f.cancel()]

    def abort(self, futures) -> None:
        """A Ctrl-C: the workers are killed with the fits they run (the next selection starts new ones)."""
        self.cancel(futures)
        self._kill()

    def _kill(self) -> None:
        """Kill the workers with the fits they run (the next pool starts new ones), and what they left in
        their TMPDIR with them (the folder itself stays for the next workers)."""
        self.executor.shutdown(wait=True, kill_workers=True)  # killed: nothing left to wait for
        folder = _worker_tmp()
        shutil.rmtree(folder, ignore_errors=True)
        os.makedirs(folder, exist_ok=True)  # the same path: the workers' env, so loky reuses the executor

    def close(self) -> None:
        """The executor is kept for the next selection (loky stops idle workers itself), unless a fit nobody
        will read still runs in it (a spec stopped while its next fold was running): then its workers are
        killed, so that fit does not take a core from what follows (the final fit on all runs)."""
        if any(not f.done() for f in self._unread):
            self._kill()
        self._unread = []
        self._folder.cleanup()


class _Cluster(_Serial):
    """The workers of a running Dask scheduler (``tcp://host:8786``), or of a given ``Client``."""

    def __init__(self, scheduler):
        try:
            from dask.distributed import Client
        except ImportError:
            raise IdentificationError("scheduler= needs Dask: pip install 'hysteresis-hybrid[distributed]'.") from None
        self.own = not isinstance(scheduler, Client)
        try:
            self.client = Client(scheduler, timeout=10) if self.own else scheduler
        except (OSError, TimeoutError) as exc:
            raise IdentificationError(f"No Dask scheduler answers at {scheduler!r} ({exc}). Start one (`dask scheduler`) "
                                      "or leave scheduler out to fit here.") from None
        self.workers = max(1, sum(self.client.nthreads().values()))

    def submit(self, fn, *args):
        return self.client.submit(fn, *args, pure=False)

    def first(self, futures):
        from dask.distributed import wait as dask_wait

        done, _ = dask_wait(list(futures), return_when="FIRST_COMPLETED")
        return next(f for f in futures if f in done)

    def cancel(self, futures) -> None:
        if futures:
            self.client.cancel(list(futures), force=True)

    def close(self) -> None:
        if self.own:
            self.client.close()


def make_pool(workers: Workers | None = None):
    """The pool the fold fits run on (:class:`Workers`): a Dask cluster when its ``scheduler`` (an address
    or a ``Client``) is given, else its ``n_jobs`` local worker processes (1: here, one after another)."""
    workers = Workers() if workers is None else workers
    if not isinstance(workers, Workers):
        raise IdentificationError(f"workers must be an identification.discovery.Workers, e.g. Workers(n_jobs=4). "
                                  f"Got {type(workers).__name__} instead.")
    from .._trace import active_trace

    if active_trace() is not None:  # measuring the critical path: every task here, timed
        return _Traced(active_trace())
    if workers.scheduler is not None:
        return _Cluster(workers.scheduler)
    n = check_jobs(workers.n_jobs)
    return _Serial() if n == 1 else _Local(n)


def driver_threads(workers: Workers | None) -> int:
    """Threads the driver may use for work of its own that the pool waits for (the final fit's starts,
    solved at once): as many as the local workers (their cores idle meanwhile), this machine's cores with
    a Dask cluster, one for ``n_jobs=1`` or no ``workers``, and the trace's width while tracing."""
    from .._trace import active_trace

    if active_trace() is not None:
        return active_trace().width
    if workers is None or not isinstance(workers, Workers):
        return 1
    return check_jobs(-1 if workers.scheduler is not None else workers.n_jobs)
