"""A purely learned kinematic model (forward or inverse): scaling, training, prediction."""

from __future__ import annotations

import contextlib
import hashlib
import os
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch
from numpy.typing import ArrayLike, NDArray

from hybrid.networks import AbstractNetwork, LSTMNet
from physics.data import BaseEstimator, DataError, Dataset, MinMaxScaler, NotFittedError, Trajectory, as_warmup

from ._checkpoint import FORMAT, VERSION, from_metadata, metadata, read_blob, write_blob
from ._settings import DEFAULT_TRAINING, TrainingSettings, check_training
from ._training import TrainingHistory, train

__all__ = ["LearnedModel", "DIRECTIONS", "save_checkpoint", "load_checkpoint", "fit_together"]

DIRECTIONS = ("forward", "inverse")


class LearnedModel(BaseEstimator):
    """A network that maps the input history to the output, trained on trajectories.

    ``direction="forward"`` learns tendon displacement -> tip angle (``u -> y``);
    ``"inverse"`` learns tip angle -> displacement on swapped trajectories
    (:meth:`Trajectory.swap`). Inputs and outputs are scaled to [0, 1] with
    min-max scalers fitted on the training data.

    Parameters
    ----------
    network : AbstractNetwork, default LSTMNet()
        :class:`FNNNet`, :class:`FNNHIBNet` or :class:`LSTMNet` settings.
    direction : {"forward", "inverse"}
    features : tuple of str, default ()
        Names of ``Trajectory.extra`` columns fed to the network besides the input.
    outputs : tuple of str, default ()
        A forward model of several outputs (the tip's angle and its position): the names of the columns it
        predicts, each the trajectory's ``y`` (by ``output_name``) or an ``extra`` column; the network then
        ends in one unit per output and :meth:`predict` returns ``(n, len(outputs))``. Empty: ``y`` alone.
    training : TrainingSettings, default TrainingSettings()
        How to train: epochs, batch size, learning rate, validation split, early stopping,
        window stride, seed, progress bar, torch threads (the paper's: 500 epochs, batch 16,
        lr 1e-3). Seen by scikit-learn as ``training__epochs`` etc.

    Attributes
    ----------
    module_ : torch.nn.Module
    input_scaler_, output_scaler_ : MinMaxScaler
    history_ : TrainingHistory
    provenance_ : list of dict
        Source, length, metadata and SHA-256 of each training trajectory.

    Examples
    --------
    >>> from hybrid.virtual import paper_protocol
    >>> from hybrid.networks import FNNHIBNet
    >>> split = paper_protocol(frequencies=(0.5,), tests=(0.45,), baselines=("mid",))
    >>> model = LearnedModel(FNNHIBNet(buffer=10), training=TrainingSettings(epochs=2, progress=False))
    >>> model.fit(split.train).predict(split.test[0]).shape
    (389,)
    >>> model.get_params()["training__epochs"]
    2
    """

    def __init__(self, network: AbstractNetwork | None = None, direction: str = "forward", *,
                 features: Sequence[str] = (), training: TrainingSettings = DEFAULT_TRAINING,
                 outputs: Sequence[str] = ()):
        self.network = network
        self.direction = direction
        self.features = features
        self.training = training
        self.outputs = outputs

    @property
    def network_(self) -> AbstractNetwork:
        """The network spec in use (``LSTMNet()`` when none was given)."""
        return LSTMNet() if self.network is None else self.network

    # ------------------------------------------------------------------ fit
    def fit(self, data: Trajectory | Iterable[Trajectory]) -> LearnedModel:
        """Train on one trajectory or a collection of them; returns ``self``."""
        net, settings, trajs, x, y = self._windows(data)
        with _threads(settings.threads):
            module = self._new_module(net, settings)
            history = train(module, x, y, settings, desc=f"{net.name} {self.direction}")
        return self._trained(module, history, trajs)

    def _windows(self, data):
        """The checked network and settings, the oriented runs and the scaled training windows and
        targets ``(net, settings, trajs, x, y)``; the scalers are fitted here."""
        net, settings = self._check_settings()
        trajs = [self._orient(t) for t in _as_trajectories(data)]
        for t in trajs:
            if t.n < net.history:
                raise DataError(
                    f"training trajectory {t.source or '?'!r} has {t.n} samples but {net!r} needs at least "
                    f"{net.history} (its history length). Use longer trajectories or a shorter buffer/seq_len."
                )
        inputs = [self._inputs(t) for t in trajs]
        targets = [self._targets(t) for t in trajs]
        columns = np.concatenate(inputs)
        MinMaxScaler().fit(columns[:, 0])  # the input itself must vary (a clear error otherwise); a feature
        self.input_scaler_ = MinMaxScaler(constant="keep").fit(columns)  # may not (a physics output of a constant)
        self.output_scaler_ = MinMaxScaler().fit(np.concatenate(targets))
        x = np.concatenate([net.windows(self.input_scaler_.transform(f))[::settings.stride] for f in inputs])
        y = np.concatenate([self.output_scaler_.transform(t)[::settings.stride] for t in targets])
        self.n_features_in_ = inputs[0].shape[1]
        return net, settings, trajs, x, y.astype(np.float32)

    def _new_module(self, net: AbstractNetwork, settings: TrainingSettings) -> torch.nn.Module:
        """The untrained module, its initial weights drawn from the training seed."""
        torch.manual_seed(settings.seed)
        return net.build(self.n_features_in_, self.n_outputs_)

    def _trained(self, module, history: TrainingHistory, trajs) -> LearnedModel:
        self.history_: TrainingHistory = history
        self.module_ = module.eval()
        self.provenance_ = [_provenance(t) for t in trajs]
        return self

    # -------------------------------------------------------------- predict
    def predict(self, data: Trajectory | ArrayLike, mode: str | None = None, warmup=None) -> NDArray[np.float64]:
        """Predict the whole output of a trajectory (or of an input array), sample by sample causally.

        Parameters
        ----------
        data : Trajectory or array_like, shape (n,) or (n, n_features)
            A trajectory (its input is chosen by ``direction``) or the model's
            input in physical units.
        mode : str, optional
            Prediction scheme of the network (LSTM: "window" or "carried");
            default the network's ``mode``.
        warmup : Trajectory or (array, array), optional
            Measured samples just before ``data`` (:func:`physics.data.as_warmup`). The network reads
            only inputs, so its state comes from the window's inputs: the LSTM runs over them, the
            FNN-HIB's history buffer holds them. Without one, the network starts at rest at the first
            input (the buffer and the LSTM's run filled with it).
        """
        mode = self._check_mode(mode)
        window = as_warmup(warmup, inverse=self.direction == "inverse")
        if window is not None:
            return self.predict(window.joined(data), mode=mode)[window.n:]
        features = self._scaled_inputs(data)
        out = self.output_scaler_.inverse_transform(self.module_.sequence(self._tensor(features), mode=mode).double().numpy())
        return out[:, 0] if self.n_outputs_ == 1 else out

    def initial_state(self, u0: ArrayLike, mode: str | None = None):
        """State before the first sample ``u0`` (the input the robot rests at)."""
        mode = self._check_mode(mode)
        return self.module_.initial_state(self._scaled_row(u0), mode=mode)

    def step(self, state, u: ArrayLike) -> tuple[Any, float | NDArray[np.float64]]:
        """One controller step: ``(state, u) -> (state, y)`` in physical units (``y`` one value per output of a
        model of several)."""
        self._check_fitted()
        state, y = self.module_.step(state, self._scaled_row(u))
        y = self.output_scaler_.inverse_transform(y.double().numpy().reshape(1, -1))[0]
        return state, (float(y[0]) if self.n_outputs_ == 1 else y)

    @property
    def n_outputs_(self) -> int:
        """Outputs the fitted network predicts: one per name in ``outputs``, else one."""
        return max(len(tuple(self.outputs)), 1)

    # ----------------------------------------------------------- checkpoint
    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write weights, scalers, settings and data provenance to ``path`` (``.pt``) and the
        metadata to ``path.with_suffix('.json')``; :meth:`load` gives back identical predictions."""
        self._check_fitted()
        path = Path(path)
        write_blob(path, metadata(self), {"state_dict": self.module_.state_dict()})
        return path

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> LearnedModel:
        """A model written by :meth:`save` (loaded safely: ``weights_only=True``)."""
        blob = read_blob(path, FORMAT, VERSION, saved_by="LearnedModel.save")
        return from_metadata(cls, blob, blob["state_dict"])

    # -------------------------------------------------------------- helpers
    def _check_settings(self) -> tuple[AbstractNetwork, TrainingSettings]:
        net = self.network_
        if not isinstance(net, AbstractNetwork):
            from hybrid.networks import NETWORKS

            raise DataError(f"network must be a network spec (an AbstractNetwork, e.g. LSTMNet()); "
                            f"make_network(name) builds one from a name in {list(NETWORKS)}. Got {net!r}.")
        if self.direction not in DIRECTIONS:
            raise DataError(f"The 'direction' parameter of LearnedModel must be one of {list(DIRECTIONS)}. "
                            f"Got {self.direction!r} instead.")
        outputs = tuple(self.outputs)
        if outputs:
            if not all(isinstance(o, str) and o for o in outputs) or len(set(outputs)) != len(outputs):
                raise DataError(f"The 'outputs' of LearnedModel must be distinct column names. Got {self.outputs!r}.")
            if self.direction != "forward":
                raise DataError("outputs= names the columns a forward model predicts; an inverse model predicts the "
                                "one input. Leave outputs out.")
            if set(outputs) & set(self.features):
                raise DataError(f"{sorted(set(outputs) & set(self.features))} cannot be both an output and a feature "
                                "the network reads.")
        return net, check_training(self.training, "LearnedModel")

    def _check_fitted(self) -> None:
        if not hasattr(self, "module_"):
            raise NotFittedError(f"This LearnedModel ({self.network_.name}, {self.direction}) is not fitted yet. "
                                 "Call fit(trajectories) or LearnedModel.load(path) first.")

    def _check_mode(self, mode: str | None) -> str:
        self._check_fitted()
        net = self.network_
        mode = getattr(net, "mode", net.modes[0]) if mode is None else mode
        if mode not in net.modes:
            raise DataError(f"{type(net).__name__} predicts with mode in {list(net.modes)}; got {mode!r}.")
        return mode

    def _orient(self, traj: Trajectory) -> Trajectory:
        return traj.swap() if self.direction == "inverse" else traj

    def _targets(self, traj: Trajectory) -> NDArray[np.float64]:
        """The columns the network learns, ``(n, n_outputs_)``: ``y``, or the named outputs."""
        if not tuple(self.outputs):
            return np.asarray(traj.y, dtype=float)[:, None]
        from identification import output_columns

        return output_columns(traj, self.outputs, error=DataError)

    def _inputs(self, traj: Trajectory) -> NDArray[np.float64]:
        missing = [k for k in self.features if k not in traj.extra]
        if missing:
            raise DataError(f"trajectory {traj.source!r} lacks the feature column(s) {missing}; "
                            f"it has {sorted(traj.extra)}.")
        return np.column_stack([traj.u, *(traj.extra[k] for k in self.features)])

    def _scaled_inputs(self, data) -> NDArray[np.float64]:
        if isinstance(data, Trajectory):
            arr = self._inputs(self._orient(data))
        else:
            arr = np.asarray(data, dtype=np.float64)
            arr = arr[:, None] if arr.ndim == 1 else arr
            if arr.ndim != 2 or arr.shape[0] == 0 or arr.shape[1] != self.n_features_in_:
                raise DataError(f"input must have shape (n,) or (n, {self.n_features_in_}) with n >= 1; "
                                f"got {np.shape(data)}.")
            if not np.all(np.isfinite(arr)):
                i = int(np.flatnonzero(~np.isfinite(arr).all(axis=1))[0])
                raise DataError(f"input has a non-finite value (NaN or inf) at sample {i}. "
                                "Remove or interpolate it before predicting.")
        return self.input_scaler_.transform(arr)

    def _scaled_row(self, u: ArrayLike) -> torch.Tensor:
        row = np.atleast_1d(np.asarray(u, dtype=np.float64))
        return self._tensor(self._scaled_inputs(row[None])[0])

    def _tensor(self, arr: NDArray[np.float64]) -> torch.Tensor:
        """``arr`` in the module's precision (float32 as trained; float64 after ``module_.double()``)."""
        return torch.from_numpy(arr).to(next(self.module_.parameters()).dtype)

    def __repr__(self) -> str:
        fitted = "" if hasattr(self, "module_") else ", unfitted"
        return f"LearnedModel({self.network_!r}, direction={self.direction!r}{fitted})"


def fit_together(models: Sequence[LearnedModel], data: Trajectory | Iterable[Trajectory]) -> list[LearnedModel]:
    """Fit ``models`` (:class:`LearnedModel` s that differ only in their training seed) on the same
    runs, their networks trained as one batched pass (:func:`~hybrid.learning._together.train_together`):
    each ends as its own ``fit`` would leave it, to float tolerance. Returns them, fitted.

    Examples
    --------
    >>> from hybrid.learning import LearnedModel, TrainingSettings, fit_together
    >>> from hybrid.networks import FNNHIBNet
    >>> from physics.virtual import paper_protocol
    >>> split = paper_protocol(frequencies=(0.5,), tests=(0.45,), baselines=("mid",))
    >>> seeds = [LearnedModel(FNNHIBNet(buffer=10), training=TrainingSettings(epochs=2, seed=s, progress=False))
    ...          for s in range(3)]
    >>> [m.predict(split.test[0]).shape for m in fit_together(seeds, split.train)]
    [(389,), (389,), (389,)]
    """
    from ._together import train_together

    models = list(models)
    if not models or not all(isinstance(m, LearnedModel) for m in models):
        raise DataError("fit_together fits LearnedModel estimators; got "
                        f"{sorted({type(m).__name__ for m in models}) or 'none'}.")
    data = _as_trajectories(data)
    prepared = [m._windows(data) for m in models]
    net, first, _, x, y = prepared[0]
    for m, (other, _, _, xm, ym) in zip(models[1:], prepared[1:]):
        if (other != net or m.direction != models[0].direction or tuple(m.features) != tuple(models[0].features)
                or not (np.array_equal(xm, x) and np.array_equal(ym, y))):
            raise DataError("fit_together fits models that differ only in their training seed (one network, "
                            "direction and features on the same runs); fit the others one by one.")
    with _threads(first.threads):
        modules = [m._new_module(net, p[1]) for m, p in zip(models, prepared)]
        histories = train_together(modules, x, y, [p[1] for p in prepared], desc=f"{net.name} {models[0].direction}")
    return [m._trained(module, history, p[2]) for m, module, history, p in zip(models, modules, histories, prepared)]


def _as_trajectories(data) -> list[Trajectory]:
    # a 1-d object array of trajectories too: what scikit-learn's model selection hands each fit
    many = isinstance(data, (Dataset, list, tuple)) or (isinstance(data, np.ndarray) and data.ndim == 1)
    items = [data] if isinstance(data, Trajectory) else list(data) if many else None
    if items is None:
        raise DataError(f"fit needs a Trajectory, a Dataset or a list of Trajectory; got {type(data).__name__}. "
                        "For a DataSplit pass split.train.")
    if not items:
        raise DataError("fit needs at least one training trajectory; got none.")
    for i, t in enumerate(items):
        if not isinstance(t, Trajectory):
            raise DataError(f"training item {i} is a {type(t).__name__}, not a Trajectory.")
    return items


def _provenance(traj: Trajectory) -> dict[str, Any]:
    digest = hashlib.sha256(np.ascontiguousarray(np.stack([traj.time, traj.u, traj.y])).tobytes()).hexdigest()
    meta = {k: (v if isinstance(v, (str, int, float, bool)) or v is None else str(v)) for k, v in traj.meta.items()}
    return {"source": traj.source, "n": traj.n, "input": traj.input_name, "output": traj.output_name,
            "input_unit": traj.input_unit, "output_unit": traj.output_unit, "meta": meta, "sha256": digest}


@contextlib.contextmanager
def _threads(n: int | None):
    if n is None:
        yield
        return
    old = torch.get_num_threads()
    torch.set_num_threads(int(n))
    try:
        yield
    finally:
        torch.set_num_threads(old)


def save_checkpoint(model: LearnedModel, path: str | os.PathLike[str]) -> Path:
    """``model.save(path)``."""
    return model.save(path)


def load_checkpoint(path: str | os.PathLike[str]) -> LearnedModel:
    """``LearnedModel.load(path)``."""
    return LearnedModel.load(path)
