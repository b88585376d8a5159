"""One ablation run: choose the training data, build the model, fit it, score it on the test set.

:func:`execute_run` is what a Dask worker calls. It imports torch only for learned and hybrid
runs (the ``"dummy"`` test model is numpy only) and keeps torch to one thread while it runs:
workers already run in parallel, one per core.
"""

from __future__ import annotations

import contextlib
import functools
import json
import time
import traceback
from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from physics import Series
from physics.data import DataError, Dataset, DataSplit, Trajectory, history_windows
from .._scoring import score_model
from ._config import DUMMY, RunSpec, network_settings

__all__ = ["execute_run", "execute_group", "failed_record", "seed_group", "select_training", "build_model", "build_hybrid"]


def execute_run(spec: RunSpec, split: DataSplit | None = None, device: str = "cpu") -> dict[str, Any]:
    """Fit and score one grid point; returns the JSON-ready run record (without provenance).

    Parameters
    ----------
    spec : RunSpec
    split : DataSplit, optional
        The data, already loaded (the runner loads it once and ships it to the workers);
        default ``spec.data.load()``.
    device : str
        Where the network trains (``TrainingSettings.device``).

    Returns
    -------
    dict
        ``run_id``, ``kind``, ``settings``, ``data``, ``train`` (names of the training
        trajectories used), ``metrics`` (``rmse``, ``nrmse`` pooled over every test sample,
        ``fit_seconds``, ``per_test``: one entry per test trajectory) and ``timings`` (s).
    """
    start = time.perf_counter()
    split = spec.data.load() if split is None else split
    s = spec.settings
    train = select_training(split.train, s["data_fraction"], s["seed"])
    with _torch_threads(1 if spec.kind != DUMMY else None):
        model = build_model(spec, dt=train[0].dt if train[0].n > 1 else 0.04, device=device)
        t_fit = time.perf_counter()
        model.fit(train)
        t_predict = time.perf_counter()
        per_test = _per_test(model, split, s)
    end = time.perf_counter()
    return _record(spec, split, train, per_test, {"data_s": t_fit - start, "fit_s": t_predict - t_fit,
                                                  "predict_s": end - t_predict, "total_s": end - start})


def _per_test(model, split: DataSplit, s: dict[str, Any]) -> list[dict[str, Any]]:
    """The fitted ``model``'s scores on each test run, then pooled (the last entry)."""
    return [{"test": r.test, "rmse": r.rmse, "nrmse": r.nrmse, "n": r.n}
            for r in score_model(model, split.test, s["model"], direction=s["direction"])]


def _record(spec: RunSpec, split: DataSplit, train, per_test: list[dict], timings: dict[str, float]) -> dict[str, Any]:
    s = spec.settings
    pooled = per_test.pop()
    return {
        "run_id": spec.run_id, "status": "ok", "kind": spec.kind, "settings": dict(s),
        "data": spec.data.to_dict(), "train": [t.source for t in train], "n_train": len(train),
        "unit": _output_unit(split.test[0], s["direction"]),
        "metrics": {"rmse": pooled["rmse"], "nrmse": pooled["nrmse"], "fit_seconds": timings["fit_s"],
                    "per_test": per_test},
        "timings": timings,
    }


def seed_group(spec: RunSpec) -> str | None:
    """The key of the runs whose networks train as one batched pass with ``spec``'s
    (:func:`~hybrid.learning.fit_together`): a learned run on all the training runs whose network
    ``vmap`` batches (an MLP: FNN, FNN-HIB) shares it with the runs that differ from it only in their
    seed. None: it trains alone (a hybrid, a recurrent network, a fraction of the data chosen by seed)."""
    s = spec.settings
    all_runs = isinstance(s["data_fraction"], float) and s["data_fraction"] == 1.0  # an int is a number of runs
    if spec.kind != "learned" or not all_runs or \
            not _batches(s["model"], json.dumps(network_settings(s), sort_keys=True)):
        return None
    return json.dumps({"data": spec.data.to_dict(), **{k: v for k, v in s.items() if k != "seed"}}, sort_keys=True)


@functools.cache
def _batches(model: str, settings: str) -> bool:
    from hybrid.learning._together import _batchable
    from hybrid.networks import make_network

    net = make_network(model, **json.loads(settings))
    with _torch_threads(1):
        return _batchable(net.build(1, 1), net.windows(np.zeros((net.history + 2, 1))))


def execute_group(specs: Sequence[RunSpec], split: DataSplit | None = None, device: str = "cpu") -> list[dict[str, Any]]:
    """Fit and score runs of one :func:`seed_group` with their networks trained as one pass; each record
    as :func:`execute_run` gives it, its ``fit_seconds`` the pass's share (the pass over the runs) and
    ``trained_with`` the runs it shared the pass with. One run alone: :func:`execute_run`."""
    from hybrid.learning import fit_together

    if len(specs) == 1:
        return [execute_run(specs[0], split, device)]
    start = time.perf_counter()
    split = specs[0].data.load() if split is None else split
    s = specs[0].settings
    train = select_training(split.train, s["data_fraction"], s["seed"])
    with _torch_threads(1):
        models = [build_model(spec, device=device) for spec in specs]
        t_fit = time.perf_counter()
        fit_together(models, train)
        t_predict = time.perf_counter()
        records = []
        for spec, model in zip(specs, models):
            t0 = time.perf_counter()
            try:  # one run's scoring failing is that run's failure alone
                per_test = _per_test(model, split, s)
            except Exception as exc:
                records.append(failed_record(spec, exc, traceback.format_exc()))
                continue
            share, scored = (t_predict - t_fit) / len(specs), time.perf_counter() - t0
            records.append(_record(spec, split, train, per_test, {
                "data_s": t_fit - start, "fit_s": share, "predict_s": scored,
                "total_s": (t_fit - start) + share + scored}))
            records[-1]["trained_with"] = [o.run_id for o in specs if o is not spec]
    return records


def failed_record(spec: RunSpec, exc: BaseException, tb: str) -> dict[str, Any]:
    """The record of a run that failed: its settings and the error (type, message, traceback)."""
    return {"run_id": spec.run_id, "status": "failed", "kind": spec.kind, "settings": dict(spec.settings),
            "data": spec.data.to_dict(),
            "error": {"type": type(exc).__name__, "message": str(exc), "traceback": tb}}


def select_training(train: Sequence[Trajectory], fraction: int | float, seed: int) -> Dataset:
    """The training trajectories a run uses: all, a fraction (float) or a number (int) of them.

    The subset is the first k of a permutation drawn with ``seed``, so for one seed a smaller
    fraction is always a subset of a larger one.
    """
    n = len(train)
    k = fraction if isinstance(fraction, int) else max(1, round(fraction * n))
    if k > n:
        raise DataError(f"data_fraction = {fraction} asks for {k} training trajectories but the data has {n}. "
                        f"Use at most {n} or a fraction such as 0.5.")
    if k == n:
        return Dataset(train)
    keep = np.sort(np.random.default_rng(seed).permutation(n)[:k])
    return Dataset(train[int(i)] for i in keep)


# -------------------------------------------------------------------- models
def build_model(spec: RunSpec, dt: float = 0.04, device: str = "cpu"):
    """The unfitted estimator of a run (``fit(trajectories)``, ``predict(trajectory)``)."""
    s = spec.settings
    if spec.kind == DUMMY:
        return LinearHistoryModel(buffer=s["buffer"], direction=s["direction"])
    from hybrid.networks import make_network

    from hybrid.learning import TrainingSettings

    network = make_network(s["model"], **network_settings(s))
    training = TrainingSettings(epochs=s["epochs"], batch_size=s["batch_size"], lr=s["lr"], validation=s["validation"],
                                patience=s["patience"] or None, stride=s["stride"], seed=s["seed"], progress=False,
                                threads=1, device=device)
    if spec.kind == "hybrid":
        return build_hybrid(s["physics"], network, s["direction"], training, dt)
    from hybrid.learning import LearnedModel

    return LearnedModel(network, s["direction"], training=training)


def build_hybrid(physics: str, network, direction: str, training, dt: float):
    """A hybrid run's estimator: physics model ``physics`` (a spec) plus a residual ``network``."""
    from hybrid.models import HybridModel

    return HybridModel(physics=Series.from_spec(physics, dt=dt), residual=network, direction=direction,
                       training=training)


class LinearHistoryModel:
    """Test-only run type (``model = "dummy"``): least-squares map from the last ``buffer`` inputs.

    Fast and torch-free, for testing scheduling, resuming and failures; it fails like the
    networks do when a training trajectory is shorter than the buffer.
    """

    def __init__(self, buffer: int = 10, direction: str = "forward"):
        self.buffer = buffer
        self.direction = direction

    def fit(self, trajectories: Sequence[Trajectory]) -> LinearHistoryModel:
        trajs = [self._orient(t) for t in trajectories]
        for t in trajs:
            if t.n < self.buffer:
                raise DataError(f"training trajectory {t.source!r} has {t.n} samples but buffer = {self.buffer} "
                                "needs at least that many. Use a shorter buffer.")
        x = np.concatenate([self._features(t.u) for t in trajs])
        y = np.concatenate([t.y for t in trajs])
        self.coef_ = np.linalg.lstsq(x, y, rcond=None)[0]
        return self

    def predict(self, traj: Trajectory) -> NDArray[np.float64]:
        return self._features(self._orient(traj).u) @ self.coef_

    def _features(self, u: NDArray[np.float64]) -> NDArray[np.float64]:
        windows = history_windows(u, self.buffer, pad="edge")
        return np.column_stack([windows, np.ones(len(u))])

    def _orient(self, traj: Trajectory) -> Trajectory:
        return traj.swap() if self.direction == "inverse" else traj


# ------------------------------------------------------------------- helpers
def _output_unit(traj: Trajectory, direction: str) -> str:
    return traj.input_unit if direction == "inverse" else traj.output_unit


@contextlib.contextmanager
def _torch_threads(n: int | None) -> Iterator[None]:
    """torch at ``n`` CPU threads inside the block (restored after); None: leave torch alone."""
    if n is None:
        yield
        return
    import torch

    old = torch.get_num_threads()
    torch.set_num_threads(n)
    try:
        yield
    finally:
        torch.set_num_threads(old)
