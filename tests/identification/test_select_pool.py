"""The selection's fold fits on a pool: here, two local worker processes, or a Dask cluster, with the same
choice and the same numbers; a Ctrl-C during a selection on a cluster cancels its fits there."""

import _thread
import os
import threading
import time

import numpy as np
import pytest

from identification import IdentificationError, Workers, select_physics
from physics import Series
from _synthetic import drifting_runs

DT = 0.1
BLOCKS = ("lag", "backlash", "resonance")


def _runs():
    """Four runs of a lag and a play: the search scores seven specs on four folds, some stopped early."""
    truth = Series.from_spec("lag+backlash+linear", dt=DT).set_params(**{
        "lag.time_constant_s": 0.4, "backlash.width": 0.3, "linear.gain": 10.0})
    return drifting_runs(truth, 240, 0.05)


@pytest.fixture(scope="module")
def cluster():
    distributed = pytest.importorskip("distributed", reason="the Dask cluster tests need dask[distributed]")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0") as c:
        yield c


def _same(a, b):
    assert (a.spec, a.path, a.stopped, a.failed) == (b.spec, b.path, b.stopped, b.failed)
    assert a.cv_rmse == b.cv_rmse and a.fold_rmse == b.fold_rmse and a.train_rmse == b.train_rmse


def test_serial_two_workers_and_a_local_cluster_give_the_same_choice_and_numbers(cluster):
    runs = _runs()
    serial = select_physics(runs, blocks=BLOCKS, refinements={}, warmup=5)
    assert "backlash" in serial.spec and serial.stopped, serial.table()  # the play is found; some specs stop early
    _same(select_physics(runs, blocks=BLOCKS, refinements={}, warmup=5, workers=Workers(n_jobs=2)), serial)
    _same(select_physics(runs, blocks=BLOCKS, refinements={}, warmup=5,
                         workers=Workers(scheduler=cluster.scheduler_address)), serial)
    with pytest.raises(IdentificationError, match="n_jobs"):
        select_physics(runs, candidates=["linear"], workers=Workers(n_jobs=0))
    with pytest.raises(IdentificationError, match="scheduler"):
        select_physics(runs, candidates=["linear"], workers=Workers(scheduler=3))


def test_ctrl_c_during_a_selection_on_a_cluster_cancels_its_fits_there(cluster):
    from distributed import Client

    watcher = Client(cluster.scheduler_address)
    busy = threading.Event()

    def press_once_busy():  # Ctrl-C as soon as the cluster is fitting folds
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and not any(watcher.processing().values()):
            time.sleep(0.02)
        busy.set()
        _thread.interrupt_main()

    presser = threading.Thread(target=press_once_busy, daemon=True)
    presser.start()
    with pytest.raises(KeyboardInterrupt):
        select_physics(_runs(), blocks=BLOCKS, refinements={}, warmup=5,
                       workers=Workers(scheduler=cluster.scheduler_address))
    presser.join()
    assert busy.is_set()
    deadline = time.monotonic() + 30  # a fit already running ends (a second or so); nothing new starts
    while time.monotonic() < deadline and (any(watcher.processing().values()) or watcher.who_has()):
        time.sleep(0.1)
    assert not any(watcher.processing().values()), watcher.processing()
    assert len(watcher.scheduler_info()["workers"]) == 2  # the workers are the cluster's and stay up
    watcher.close()


def test_worker_processes_share_a_compiled_step_through_the_pools_folder(tmp_path, monkeypatch):
    # one worker compiles a spec's step and leaves the library in the folder; another loads it, with the
    # same numbers, instead of compiling it again
    from identification import _sensitivity

    if not _sensitivity.jit_available():
        pytest.skip("needs a C compiler")
    monkeypatch.setenv("HYST_JIT_CACHE", "off")  # no library kept between runs: the pool's folder shares them
    model = Series.from_spec("lag+backlash+linear", dt=DT)
    u = np.linspace(0.0, 2.0, 50)[None, :]
    monkeypatch.setattr(_sensitivity, "_JIT_CACHE", {})
    monkeypatch.setattr(_sensitivity, "_ROLLOUTS", {})
    with _sensitivity.shared_compiles(tmp_path):
        first = np.asarray(_sensitivity.plain_rollout(model, 50)(np.zeros(model.n_x), u, model.params)[1])
    assert len(list(tmp_path.glob("*.so"))) == 1
    monkeypatch.setattr(_sensitivity, "_JIT_CACHE", {})  # another process: nothing compiled in it yet
    monkeypatch.setattr(_sensitivity, "_ROLLOUTS", {})

    def no_compile(*args, **kwargs):
        raise AssertionError("compiled again although the folder holds the library")

    monkeypatch.setattr(_sensitivity, "compile_function", no_compile)
    with _sensitivity.shared_compiles(tmp_path):
        again = np.asarray(_sensitivity.plain_rollout(model, 50)(np.zeros(model.n_x), u, model.params)[1])
    np.testing.assert_array_equal(again, first)
    assert np.array_equal(first, np.asarray(model.rollout(50)(np.zeros(model.n_x), u, model.params)[1]))


def _loky_workers(psutil) -> list:
    """This process's loky workers (not its resource tracker); a worker that exits while it is listed
    or read is left out (under load one can go between the two: ``psutil.NoSuchProcess``)."""
    out = []
    for p in psutil.Process().children(recursive=True):
        try:
            if "LokyProcess" in " ".join(p.cmdline()):
                out.append(p)
        except psutil.Error:
            pass
    return out


def test_ctrl_c_during_a_selection_in_local_workers_leaves_no_worker_running():
    psutil = pytest.importorskip("psutil")

    def workers():
        return _loky_workers(psutil)

    def busy(p):
        try:
            return p.cpu_percent(0.05) > 0
        except psutil.Error:  # exited since listed
            return False

    def press_once_fitting():  # Ctrl-C once the workers fit folds
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and not any(busy(p) for p in workers()):
            pass
        _thread.interrupt_main()

    presser = threading.Thread(target=press_once_fitting, daemon=True)
    presser.start()
    with pytest.raises(KeyboardInterrupt):
        select_physics(_runs(), blocks=BLOCKS, refinements={}, warmup=5, workers=Workers(n_jobs=2))
    presser.join()
    gone, alive = psutil.wait_procs(workers(), timeout=20)
    assert not alive, [p.cmdline() for p in alive]
    # the killed workers ran no clean-up: what they left in their TMPDIR (a compile's hyst_jit_*, hyst_cc_*)
    # is removed with them, and the folder stays for the next workers
    from identification.discovery import _pool

    assert os.path.isdir(_pool._WORKER_TMP[0]) and not os.listdir(_pool._WORKER_TMP[0])
    again = select_physics(_runs()[:3], candidates=["linear", "lag+linear"], workers=Workers(n_jobs=2))  # new workers
    assert again.spec == "lag+linear"


def test_a_compiled_step_is_kept_between_runs_in_the_jit_cache(tmp_path, monkeypatch):
    # a second process (nothing compiled in it) loads the library the first kept, with the same numbers;
    # a library that does not load is compiled again
    from identification import _sensitivity

    if not _sensitivity.jit_available():
        pytest.skip("needs a C compiler")
    monkeypatch.setenv("HYST_JIT_CACHE", str(tmp_path / "jit"))
    model = Series.from_spec("lag+gpi+linear", dt=DT)
    u = np.linspace(0.0, 2.0, 50)[None, :]

    def rollout():
        monkeypatch.setattr(_sensitivity, "_JIT_CACHE", {})
        monkeypatch.setattr(_sensitivity, "_ROLLOUTS", {})
        return np.asarray(_sensitivity.plain_rollout(model, 50)(np.zeros(model.n_x), u, model.params)[1])

    first = rollout()
    kept = list((tmp_path / "jit").glob("*.so"))
    assert len(kept) == 1
    compile_function = _sensitivity.compile_function
    monkeypatch.setattr(_sensitivity, "compile_function", lambda *a, **k: pytest.fail("compiled again"))
    np.testing.assert_array_equal(rollout(), first)
    other = tmp_path / "other"  # a cache whose library of this step is damaged
    other.mkdir()
    (other / kept[0].name).write_bytes(b"not a library")
    monkeypatch.setenv("HYST_JIT_CACHE", str(other))
    monkeypatch.setattr(_sensitivity, "compile_function", compile_function)
    np.testing.assert_array_equal(rollout(), first)
    assert (other / kept[0].name).read_bytes()[:4] == b"\x7fELF"  # compiled and kept again
    monkeypatch.setenv("HYST_JIT_CACHE", "off")
    assert _sensitivity.jit_cache() is None


def _sleep(seconds):
    time.sleep(seconds)
    return seconds


def test_a_fit_nobody_will_read_is_not_left_running_after_the_pool_closes():
    """A fold fit already running when its spec is stopped cannot be cancelled; closing the pool kills
    its workers instead of leaving it to take a core from the final fit (a fit that was read is kept)."""
    psutil = pytest.importorskip("psutil")
    from identification.discovery._pool import make_pool


    def workers():
        return _loky_workers(psutil)

    pool = make_pool(Workers(n_jobs=2))
    assert pool.submit(_sleep, 0.0).result() == 0.0  # workers up; a finished fit is no reason to kill them
    pool.close()
    kept = workers()
    assert kept and all(p.is_running() for p in kept)
    pool = make_pool(Workers(n_jobs=2))
    late = pool.submit(_sleep, 60.0)
    deadline = time.monotonic() + 30
    while not late.running() and time.monotonic() < deadline:
        time.sleep(0.05)
    pool.cancel([late])  # running: cannot be cancelled
    running = workers()
    t0 = time.monotonic()
    pool.close()
    gone, alive = psutil.wait_procs(running, timeout=20)
    assert not alive and time.monotonic() - t0 < 30, [p.cmdline() for p in alive]
    again = make_pool(Workers(n_jobs=2))  # the next selection starts new workers
    assert again.submit(_sleep, 0.0).result() == 0.0
    again.close()


def _blas_threads():
    from threadpoolctl import threadpool_info

    return [info["num_threads"] for info in threadpool_info() if info["user_api"] == "blas"]


def test_local_workers_run_blas_and_openmp_on_one_thread_each():
    # the workers already take every core: two workers of two BLAS threads each on two cores spent twice
    # the time per fit (NiTi's selection 25.5 s in 2 workers, 13.7 s with one thread each)
    pytest.importorskip("threadpoolctl")
    from identification.discovery._pool import make_pool

    pool = make_pool(Workers(n_jobs=2))
    try:
        threads = pool.submit(_blas_threads).result()
    finally:
        pool.close()
    assert threads and set(threads) == {1}


def _bar_holds_a_named_semaphore() -> bool:
    from multiprocessing.synchronize import SemLock

    from tqdm import tqdm

    for _ in tqdm(range(2), disable=True):  # as a network's training does, with its bar off
        pass
    lock = tqdm.get_lock()
    return any(isinstance(lk, SemLock) for lk in (lock, getattr(lock, "mp_lock", None)))


def test_a_workers_progress_bar_keeps_no_named_semaphore_a_kill_would_leak():
    # tqdm's default lock is a multiprocessing semaphore, registered with the stdlib's resource tracker: a
    # worker killed on Ctrl-C left it, and the tracker printed "There appear to be 2 leaked semaphore
    # objects" under hyst's own message. The workers' bars take a thread lock instead.
    from identification.discovery._pool import make_pool

    pool = make_pool(Workers(n_jobs=2))
    try:
        assert pool.submit(_bar_holds_a_named_semaphore).result() is False
    finally:
        pool.close()


def _scratch_then_sleep(seconds):
    """A worker's compile, as far as its scratch goes: a hyst_jit_ folder in its TMPDIR, removed only if
    the worker lives to its ``finally``."""
    import shutil
    import tempfile

    folder = tempfile.mkdtemp(prefix="hyst_jit_")
    try:
        time.sleep(seconds)
        return folder
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def test_workers_killed_mid_compile_leave_no_scratch_folder(tmp_path, monkeypatch):
    """Issue 54 item 5: a Ctrl-C or SIGTERM kills the local workers with the fits they run, and a killed
    worker runs no ``finally``: its hyst_jit_* and hyst_cc_* folders stayed in $TMPDIR. The workers'
    TMPDIR is now a folder of this process, emptied when they are killed and removed at exit."""
    from identification.discovery import _pool
    from identification.discovery._pool import make_pool

    monkeypatch.setenv("TMPDIR", str(tmp_path))  # where the scratch used to be left
    pool = make_pool(Workers(n_jobs=2))
    futures = [pool.submit(_scratch_then_sleep, 60.0) for _ in range(2)]
    worker_tmp = _pool._WORKER_TMP[0]
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline and len([p for p in os.listdir(worker_tmp) if p.startswith("hyst_jit_")]) < 2:
        time.sleep(0.05)
    assert len([p for p in os.listdir(worker_tmp) if p.startswith("hyst_jit_")]) == 2  # both mid-compile
    t0 = time.monotonic()
    pool.abort(futures)  # what a Ctrl-C does
    assert time.monotonic() - t0 < 10 and os.listdir(worker_tmp) == []
    assert not [p for p in os.listdir(tmp_path) if p.startswith(("hyst_jit_", "hyst_cc_"))]
    pool.close()
    again = make_pool(Workers(n_jobs=2))  # the next workers find their TMPDIR
    assert again.submit(_sleep, 0.0).result() == 0.0
    again.close()
