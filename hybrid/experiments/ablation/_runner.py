"""Run an ablation on Dask: skip finished runs, isolate failures, record each run as it finishes.

One code path for a laptop and a cluster: without a scheduler address a ``LocalCluster`` of
``workers`` single-threaded processes is started; with one, the client connects to it. The data
are loaded once here and sent to the workers; the workers return records and this process writes
them, one atomic JSON file per run, so workers need no shared file system.
"""

from __future__ import annotations

import contextlib
import hashlib
import importlib.metadata
import os
import platform
import socket
import subprocess
import time
import traceback
import uuid
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from physics.data.io import write_json
from physics.data._checks import check_device
from ._config import AblationConfig, ConfigError, RunSpec
from ._run import execute_group, failed_record, seed_group

__all__ = ["AblationResult", "run_ablation", "run_path", "error_path"]


@dataclass
class AblationResult:
    """What :func:`run_ablation` did: the table (one row per run) and what ran, was skipped or failed."""

    out: Path
    table: list[dict[str, Any]]
    ran: list[str] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)
    failed: list[str] = field(default_factory=list)
    figures: list[Path] = field(default_factory=list)
    seconds: float = 0.0

    @property
    def n_runs(self) -> int:
        return len(self.table)


def run_ablation(config: AblationConfig | str | os.PathLike[str], out: str | os.PathLike[str], *,
                 workers: int | None = None, scheduler: str | None = None, progress: bool | None = None,
                 figures: bool = True, device: str = "cpu") -> AblationResult:
    """Run every grid point of ``config`` that has no result in ``out/runs`` yet; write the summary.

    Parameters
    ----------
    config : AblationConfig or path to a TOML file
    out : path
        Writes ``out/runs/<run_id>.json`` per finished run (``<run_id>.error.json`` per failed
        one, with the traceback), ``out/results.csv``, ``out/ablation.json`` and
        ``out/figures/*.png``. Finished runs are skipped on a rerun; failed ones are retried.
    workers : int, optional
        Processes of the local Dask cluster (default: the number of CPU cores).
    scheduler : str, optional
        Address of a running Dask scheduler (``tcp://host:port``) to use instead; its workers
        need this package installed.
    progress : bool or None
        tqdm bar over runs; None: only when stderr is a terminal.
    figures : bool
        Write the summary figures.
    device : {"cpu", "auto", "cuda", "cuda:N"}
        Where each run's network trains (``TrainingSettings.device``; not part of a run's settings or
        id: a finished run is not run again on another device). Recorded in the provenance.
    """
    from ._summary import plot_summary, table_rows, write_results_csv

    start = time.perf_counter()
    if not isinstance(config, AblationConfig):
        config = AblationConfig.from_toml(config)
    out = Path(out)
    specs = config.runs()
    todo = [s for s in specs if not _finished(out, s)]
    result = AblationResult(out, [], skipped=[s.run_id for s in specs if s not in todo])
    context = {**provenance(config), "device": check_device(device)}
    if todo:
        split = config.data.load()  # once, here: bad data fail before anything is scheduled
        context["data"]["digest"] = data_digest(split)
        with _client(workers, scheduler) as client:
            result.ran, result.failed = _schedule(client, todo, split, out, context, progress, device)
    result.table = table_rows(specs, out, config.metrics)
    write_results_csv(result.table, out / "results.csv")
    if figures:
        result.figures = plot_summary(result.table, out / "figures", config.metrics)
    result.seconds = time.perf_counter() - start
    failed = [r["run_id"] for r in result.table if r["status"] != "ok"]
    write_json(out / "ablation.json", {
        "config": config.to_dict(), "provenance": context, "runs": [s.run_id for s in specs],
        "failed": failed, "figures": [p.name for p in result.figures]})
    return result


def run_path(out: Path, run_id: str) -> Path:
    return Path(out) / "runs" / f"{run_id}.json"


def error_path(out: Path, run_id: str) -> Path:
    return Path(out) / "runs" / f"{run_id}.error.json"


# ---------------------------------------------------------------- scheduling
@contextlib.contextmanager
def _client(workers: int | None, scheduler: str | None) -> Iterator[Any]:
    from dask.distributed import Client, LocalCluster

    if scheduler:
        with Client(scheduler) as client:
            yield client
        return
    n = (os.cpu_count() or 1) if workers is None else workers
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise ConfigError(f"workers must be an integer >= 1. Got {workers!r} instead.")
    # dashboard on a free port: a fixed 8787 warns when another cluster holds it.
    cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=":0")
    try:
        with Client(cluster) as client:
            yield client
    finally:
        with _quiet("distributed.nanny"):
            cluster.close()


@contextlib.contextmanager
def _quiet(logger_name: str) -> Iterator[None]:
    """Only errors from ``logger_name`` inside the block.

    Used while the local cluster closes: a worker that has run torch can take more than the
    nanny's 4 s to finalise on a busy machine and is then killed with a warning; every result
    is saved by then, so nothing is lost.
    """
    import logging

    logger = logging.getLogger(logger_name)
    level = logger.level
    logger.setLevel(logging.ERROR)
    try:
        yield
    finally:
        logger.setLevel(level)


def _schedule(client, todo: Sequence[RunSpec], split, out: Path, context: dict[str, Any],
              progress: bool | None, device: str = "cpu") -> tuple[list[str], list[str]]:
    from dask.distributed import as_completed
    from tqdm.auto import tqdm

    data = client.scatter(split, broadcast=True)
    token = uuid.uuid4().hex[:8]  # fresh keys: a long-lived scheduler must not serve an old result
    futures = {client.submit(_worker_group, group, data, device, key=f"ablate-{group[0].run_id}-{token}"): group
               for group in seed_groups(todo)}
    ran, failed = [], []
    bar = tqdm(total=len(todo), desc="ablation", unit="run", disable=None if progress is None else not progress)
    try:
        for future in as_completed(futures):
            group = futures[future]
            try:
                records = future.result()
            except Exception as exc:  # the worker died or the task could not run: not the runs' own error
                records = [_error_record(spec, exc, "".join(traceback.format_exception(exc))) for spec in group]
            for spec, record in zip(group, records):
                _save(out, spec, record, context)
                (ran if record["status"] == "ok" else failed).append(spec.run_id)
                if record["status"] != "ok":
                    bar.write(f"run {spec.run_id} failed: {record['error']['type']}: {record['error']['message']}")
                bar.update()
            bar.set_postfix(failed=len(failed))
    finally:
        bar.close()
        client.cancel(list(futures))
    return ran, failed


def seed_groups(todo: Sequence[RunSpec]) -> list[list[RunSpec]]:
    """The tasks of a sweep: the runs of one :func:`~._run.seed_group` together (their networks train as
    one batched pass), every other run alone; in the order of the grid."""
    groups: dict[str, list[RunSpec]] = {}
    tasks: list[list[RunSpec]] = []
    for spec in todo:
        key = seed_group(spec)
        if key is None:
            tasks.append([spec])
        elif key in groups:
            groups[key].append(spec)
        else:
            groups[key] = [spec]
            tasks.append(groups[key])
    return tasks


def _worker_group(group: Sequence[RunSpec], split, device: str = "cpu") -> list[dict[str, Any]]:
    """On the worker: the records of a task's runs (:func:`seed_groups`), or their error records (a
    failure never raises)."""
    try:
        records = execute_group(group, split, device)
    except Exception as exc:
        return [_error_record(spec, exc, traceback.format_exc()) for spec in group]
    for record in records:
        record["worker"] = _host_info()
    return records


def _error_record(spec: RunSpec, exc: BaseException, tb: str) -> dict[str, Any]:
    return {**failed_record(spec, exc, tb), "worker": _host_info()}


def _save(out: Path, spec: RunSpec, record: dict[str, Any], context: dict[str, Any]) -> None:
    record = {**record, "provenance": {**context, "seed": spec.settings["seed"]}}
    if record["status"] == "ok":
        write_json(run_path(out, spec.run_id), record)
        with contextlib.suppress(FileNotFoundError):
            error_path(out, spec.run_id).unlink()
    else:
        write_json(error_path(out, spec.run_id), record)


def _finished(out: Path, spec: RunSpec) -> bool:
    from ._summary import read_record

    record = read_record(run_path(out, spec.run_id))
    return record is not None and record.get("run_id") == spec.run_id and record.get("status") == "ok"


# ---------------------------------------------------------------- provenance
def provenance(config: AblationConfig) -> dict[str, Any]:
    """Package version, git commit (when run from a checkout), Python, and the data description."""
    try:
        version = importlib.metadata.version("hysteresis-hybrid")
    except importlib.metadata.PackageNotFoundError:
        version = None
    return {"package": "hysteresis-hybrid", "version": version, **_git_info(),
            "python": platform.python_version(), "host": socket.gethostname(),
            "data": config.data.to_dict()}


def data_digest(split) -> str:
    """SHA-256 over every trajectory (time, u, y), train then test: the exact data the runs saw."""
    h = hashlib.sha256()
    for traj in (*split.train, *split.test):
        h.update(np.ascontiguousarray(np.stack([traj.time, traj.u, traj.y])).tobytes())
    return h.hexdigest()


def _git_info() -> dict[str, Any]:
    root = Path(__file__).resolve().parents[2]
    try:
        commit = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True, text=True,
                                timeout=5, check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=5, check=True).stdout.strip() != ""
    except (OSError, subprocess.SubprocessError):
        return {"git_commit": None}
    return {"git_commit": commit, "git_dirty": dirty}


def _host_info() -> dict[str, Any]:
    import sys

    info: dict[str, Any] = {"host": socket.gethostname(), "pid": os.getpid()}
    if "torch" in sys.modules:
        info["torch"] = sys.modules["torch"].__version__
    return info
