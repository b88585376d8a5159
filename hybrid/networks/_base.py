"""The abstract network spec: settings, training windows, its torch module and its CasADi step.

A spec is a small frozen dataclass holding settings only (no weights). One file
per network holds everything about it: the spec, the torch module that learns
(``module_class``, ``build``) and the CasADi step written from that module's
weights (``casadi_step``). Nothing elsewhere tests a network's name: training,
hybrids and export read the facts a spec declares (``history``, ``modes``,
``carries_state``) and call its hooks.

The module holds the weights and runs the network two ways: batched over a
whole trajectory (``sequence``) and one sample at a time with explicit state
(``initial_state`` / ``step``), the way a controller calls it. Torch is imported
only when a module class is first asked for, so importing the specs stays light.
"""

from __future__ import annotations

import abc
import dataclasses
from typing import Any, Callable, ClassVar

import numpy as np
from numpy.typing import NDArray

from physics.data import DataError

__all__ = ["AbstractNetwork", "CasadiStep"]

#: Windows per batch in a module's ``sequence``; bounds memory on long trajectories.
CHUNK = 4096


@dataclasses.dataclass
class CasadiStep:
    """A built network written in CasADi, in physical units (``hybrid.export`` wraps it).

    Attributes
    ----------
    step : casadi.Function
        ``(x, u) -> (x_next, y)``, inputs named ``'x', 'u'``, outputs ``'x_next', 'y'``.
    state_names : tuple of str
        One name per entry of ``x``.
    x0 : casadi.Function
        ``(u0) -> x``: the state before the first sample ``u0`` of a run, the one the
        torch module's ``initial_state`` starts from (so export equals predict from sample 0).
    kind : str
        The network's registry name (``ExportedModel.kind``).
    meta : dict
        JSON-ready settings kept with the export (mode, buffer length, ...).
    """

    step: Any
    state_names: tuple[str, ...]
    x0: Any
    kind: str = ""
    meta: dict[str, Any] = dataclasses.field(default_factory=dict)


class AbstractNetwork(abc.ABC):
    """Base of every network spec (:class:`FNNNet`, :class:`FNNHIBNet`, :class:`LSTMNet`; never subclass those).

    A new network subclasses this once, in one file, and is added to
    ``hybrid.networks.NETWORKS`` (:func:`hybrid.networks.register_network`).
    """

    #: Registry name ("fnn", "fnn-hib", "lstm").
    name: ClassVar[str]
    #: Name in tables and figures ("FNN-HIB"); empty: the registry name (:func:`network_label`).
    label: ClassVar[str] = ""
    #: Prediction schemes the module supports; the first is the default. ``"window"``: each
    #: output from its own window of the last ``history`` inputs; ``"carried"``: a recurrent
    #: state carried from sample to sample.
    modes: ClassVar[tuple[str, ...]] = ("window",)
    #: True for a network that ``residual="auto"`` (``hyst fit``, :func:`hybrid.experiments.fit_model_dir`)
    #: trains and compares with the physics alone; any registered network can be named instead.
    auto_residual: ClassVar[bool] = False

    @property
    def carries_state(self) -> bool:
        """Whether the module can carry a recurrent state between samples (mode ``"carried"``):
        the cheap step a controller wants, what a hybrid exports by default."""
        return "carried" in self.modes

    def for_control(self) -> "AbstractNetwork":
        """This spec as a controller steps it, one sample at a time: what a model folder
        (``hyst fit``) trains and exports. Default: the spec itself; a recurrent network returns
        its carried-state form (:class:`LSTMNet`: ``mode="carried"``, one cell step per sample)."""
        return self

    @property
    @abc.abstractmethod
    def history(self) -> int:
        """Samples of input history one output depends on in training (1 for a plain FNN)."""

    @abc.abstractmethod
    def windows(self, features: NDArray[np.float64]) -> NDArray[np.float32]:
        """Training inputs, one window per sample: shape (n, history, n_features), oldest first."""

    @classmethod
    @abc.abstractmethod
    def module_class(cls) -> type:
        """The torch module class (defined on the first call, which imports torch)."""

    @abc.abstractmethod
    def build(self, n_features: int, n_outputs: int = 1):
        """A fresh torch module for ``n_features`` inputs and ``n_outputs`` outputs.

        The module is an instance of :meth:`module_class` carrying ``n_features`` and
        ``n_outputs`` attributes and every setting :meth:`casadi_step` needs.
        """

    @classmethod
    @abc.abstractmethod
    def casadi_step(cls, module, inputs, outputs, mode: str | None, sym) -> CasadiStep:
        """The built ``module`` as one CasADi step in physical units.

        Parameters
        ----------
        module : torch.nn.Module
            An instance of :meth:`module_class` (float64 weights give torch's float64 values).
        inputs, outputs : scale
            Affine maps between physical and scaled (network) units, one entry per
            column: arrays ``lo`` and ``span`` (scaled = (v - lo) / span),
            ``to_scaled(v)``, ``to_physical(v)`` on CasADi vectors and
            ``value_to_physical(s)`` on a float; the step folds them in.
        mode : str or None
            One of :attr:`modes` (None: the network's export default).
        sym : casadi.SX or casadi.MX
            The symbol class to build the step in.
        """

    # ---------------------------------------------------------------- shared
    def to_dict(self) -> dict[str, Any]:
        """JSON-serialisable settings; :func:`network_from_dict` rebuilds the spec."""
        return {"name": self.name, **dataclasses.asdict(self)}  # type: ignore[call-overload]

    def check_features(self, features: NDArray[np.float64]) -> NDArray[np.float64]:
        arr = np.asarray(features, dtype=np.float64)
        if arr.ndim == 1:
            arr = arr[:, None]
        if arr.ndim != 2 or arr.shape[0] == 0:
            raise DataError(
                f"{type(self).__name__} needs a feature matrix of shape (n, n_features) with n >= 1; "
                f"got shape {arr.shape}."
            )
        if not np.all(np.isfinite(arr)):
            i = int(np.flatnonzero(~np.isfinite(arr).all(axis=1))[0])
            raise DataError(f"features have a non-finite value at sample {i}. Remove or interpolate NaN/inf first.")
        return arr


def check_int(owner: str, name: str, value: object, minimum: int = 1) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise DataError(f"The {name!r} parameter of {owner} must be an integer >= {minimum}. Got {value!r} instead.")


def padded_windows(features, length: int, pad: str | float):
    """(n, f) tensor -> (n, length, f): the window ending at each sample, oldest first.

    ``pad`` fills the window before the first sample: ``"edge"`` repeats the first row,
    a number is that value.
    """
    import torch

    if length > 1:
        head = features[:1].expand(length - 1, -1) if pad == "edge" else features.new_full(
            (length - 1, features.shape[1]), float(pad))
        features = torch.cat([head, features], dim=0)
    return features.unfold(0, length, 1).transpose(1, 2)


def in_chunks(forward: Callable, windows):
    """``forward`` over ``windows`` in batches of :data:`CHUNK`, concatenated."""
    import torch

    return torch.cat([forward(windows[i:i + CHUNK]) for i in range(0, windows.shape[0], CHUNK)])
