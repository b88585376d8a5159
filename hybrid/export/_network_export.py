"""Exporters of learned models: torch modules plus min-max scalers, and physics + residual hybrids.

These take plain torch modules and scaler objects, so that the exporter of any
model class (``_model_export``) can call them. A scaler is anything with arrays ``min_`` and
``max_`` (``hybrid.data.MinMaxScaler``): the network sees ``(v - min_) / (max_ - min_)``
and its output is mapped back with ``y_s (max_ - min_) + min_``. ``None`` means
no scaling. Both are folded into the exported step, whose input and output are
in physical units.
"""

from __future__ import annotations

from typing import Any, Sequence

import casadi as ca
import numpy as np

from hybrid.networks import NETWORKS, AbstractNetwork, CasadiStep, network_of
from hybrid.networks._fnn import buffer_mlp_step
from hybrid.networks._lstm import flagged_lstm_step
from physics.data import DataError
from ._export import register_exporter, symbol
from ._load import register_checkpoint
from ._model import ExportedModel, ExportError

__all__ = ["export_buffer_mlp", "export_lstm", "export_network", "export_learned", "compose_hybrid"]


class _Scale:
    """Affine map between physical and scaled units for ``k`` columns."""

    def __init__(self, scaler, k: int, what: str):
        if scaler is None:
            self.lo, self.span = np.zeros(k), np.ones(k)
            return
        try:
            lo = np.asarray(scaler.min_, dtype=float).ravel()
            hi = np.asarray(scaler.max_, dtype=float).ravel()
        except AttributeError:
            raise ExportError(f"The {what} scaler must be fitted and have min_ and max_ arrays "
                              f"(hybrid.data.MinMaxScaler); got {type(scaler).__name__}.") from None
        if lo.size != k or hi.size != k or np.any(hi <= lo):
            raise ExportError(f"The {what} scaler must have {k} columns with max_ > min_; "
                              f"got min_={lo.tolist()}, max_={hi.tolist()}.")
        self.lo, self.span = lo, hi - lo

    def to_scaled(self, v):
        return (v - ca.DM(self.lo)) / ca.DM(self.span)

    def to_physical(self, v):
        return v * ca.DM(self.span) + ca.DM(self.lo)

    def value_to_physical(self, s: float) -> np.ndarray:
        return s * self.span + self.lo

    def to_dict(self) -> dict[str, list]:
        return {"min": self.lo.tolist(), "max": (self.lo + self.span).tolist()}


def scaler_range(scaler, column: int = 0) -> list[float]:
    """``[min, max]`` of one column of a fitted min-max scaler (the data it was fitted on)."""
    return [float(np.ravel(scaler.min_)[column]), float(np.ravel(scaler.max_)[column])]


def _meta(kind, in_s, out_s, **more):
    return {"network": kind, "input_scaler": in_s.to_dict(), "output_scaler": out_s.to_dict(), **more}


def _exported(s: CasadiStep, in_s: _Scale, out_s: _Scale) -> ExportedModel:
    return ExportedModel(s.step, tuple(s.state_names), s.x0, kind=s.kind,
                         meta=_meta(s.kind, in_s, out_s, **s.meta))


def export_buffer_mlp(net, buffer: int, in_scaler=None, out_scaler=None, pad: str | float = "edge",
                      n_features: int | None = None, symbolic: str = "SX") -> ExportedModel:
    """An MLP ``net`` (``nn.Sequential``) on the last ``buffer`` inputs (FNN-HIB; ``buffer=1``: the plain FNN).

    The state is the previous ``buffer - 1`` inputs in physical units, oldest first;
    ``pad`` fills the buffer before the start as in training. The maths is
    :func:`hybrid.networks._fnn.buffer_mlp_step` (``BufferMLP``'s CasADi step).
    """
    first = next((m for m in net.modules() if hasattr(m, "in_features")), None)
    if first is None:
        raise ExportError("The MLP has no Linear layer.")
    n_f = int(n_features) if n_features is not None else first.in_features // int(buffer)
    if buffer < 1 or n_f * buffer != first.in_features:
        raise ExportError(f"The MLP's first layer takes {first.in_features} inputs, which is not "
                          f"buffer ({buffer}) x n_features ({n_f}).")
    S = symbol(symbolic)
    in_s, out_s = _Scale(in_scaler, n_f, "input"), _Scale(out_scaler, _n_out(net), "output")
    return _exported(buffer_mlp_step(net, int(buffer), n_f, pad, in_s, out_s, S), in_s, out_s)


def _n_out(module) -> int:
    last = [m for m in module.modules() if hasattr(m, "out_features")]
    if not last:
        raise ExportError("The network has no Linear layer.")
    return int(last[-1].out_features)


def export_lstm(lstm, head, in_scaler=None, out_scaler=None, mode: str = "carried", seq_len: int = 50,
                flag: float = -1.0, symbolic: str = "SX") -> ExportedModel:
    """A stacked ``nn.LSTM`` with a ``head`` (``FlaggedLSTM``: ``.lstm``, ``.head``).

    ``mode="carried"``: the state is ``(h, c)`` of every layer (:func:`lstm_state_names`),
    carried from sample to sample, from the state after ``seq_len - 1`` flags (the
    start of every run, as in training). ``mode="window"`` (the paper's scheme):
    the state is the buffer of the previous ``seq_len - 1`` inputs and each step reruns
    the LSTM over the window (exact, ``seq_len`` times dearer; MX whatever ``symbolic``
    says). The maths is :func:`hybrid.networks._lstm.flagged_lstm_step`.
    """
    S = symbol(symbolic)
    in_s, out_s = _Scale(in_scaler, lstm.input_size, "input"), _Scale(out_scaler, _n_out(head), "output")
    try:
        step = flagged_lstm_step(lstm, head, in_s, out_s, mode=mode, seq_len=int(seq_len), flag=float(flag), sym=S)
    except DataError as err:
        raise ExportError(str(err)) from None
    return _exported(step, in_s, out_s)


def export_network(module, in_scaler=None, out_scaler=None, mode: str | None = None,
                   symbolic: str = "SX", network: type[AbstractNetwork] | None = None) -> ExportedModel:
    """A built network's torch module as one CasADi step in physical units.

    The module's spec class (``network``; default: the registered one whose module
    ``module`` is, :func:`hybrid.networks.network_of`) writes the step
    (:meth:`AbstractNetwork.casadi_step`) from the module's weights and settings; its
    ``n_features`` and ``n_outputs`` size the scalers. ``mode`` is one of the spec's
    ``modes`` (None: the spec's export default). A bare ``nn.Sequential`` or
    ``nn.Linear`` is exported as a memoryless FNN.
    """
    import torch.nn as nn

    S = symbol(symbolic)
    network = network or network_of(module)
    if network is None:
        if isinstance(module, (nn.Sequential, nn.Linear)):
            return export_buffer_mlp(module, 1, in_scaler, out_scaler, symbolic=symbolic)
        raise ExportError(f"No network exporter for {type(module).__name__}: expected the module of a network in "
                          f"hybrid.networks.NETWORKS ({list(NETWORKS)}) or an nn.Sequential.")
    in_s = _Scale(in_scaler, int(module.n_features), "input")
    out_s = _Scale(out_scaler, int(module.n_outputs), "output")
    try:
        step = network.casadi_step(module, in_s, out_s, mode, S)
    except DataError as err:  # the network says what is wrong; the export reports it
        raise ExportError(str(err)) from None
    return _exported(step, in_s, out_s)


@register_exporter("hybrid.learning.LearnedModel")
def export_learned(model, mode: str | None = None, symbolic: str = "SX", dt: float | None = None) -> ExportedModel:
    """A fitted ``hybrid.LearnedModel`` (``module_``, ``input_scaler_``, ``output_scaler_``).

    A model that reads measured columns besides the command (``features``, e.g. the motor
    current) steps on the input vector ``[u, *features]`` (``meta["inputs"]``). ``mode``
    defaults to the network's own (LSTM ``"window"``: exact, ``seq_len`` LSTM
    steps per sample; ``"carried"`` is the cheap recurrent state for MPC).
    """
    if not hasattr(model, "module_"):
        raise ExportError("The learned model is not fitted; call fit() or load a checkpoint first.")
    if getattr(model, "direction", "forward") != "forward":
        raise ExportError(f"Only forward models can be exported; got direction={model.direction!r}.")
    net = model.network_
    mode = mode or getattr(net, "mode", None)
    out = export_network(model.module_, model.input_scaler_, model.output_scaler_, mode=mode, symbolic=symbolic,
                         network=type(net))
    out.dt = dt
    out.meta["settings"] = net.to_dict()
    out.meta["inputs"] = ["u", *getattr(model, "features", ())]
    if model.input_scaler_ is not None:  # the command's range on the training data
        out.meta["input_range"] = scaler_range(model.input_scaler_)
    return out


def compose_hybrid(physics: ExportedModel, residual: ExportedModel,
                   features: Sequence[str] = ("u",), combine: str = "add",
                   measured: Sequence[str] = (), weight: ca.Function | None = None) -> ExportedModel:
    """Physics plus a residual network: ``y = y_phys + y_res`` (``combine="add"``).

    The residual's input vector is made of ``features``, each ``"u"`` (the command),
    ``"y_phys"`` (the physics output at the same sample, every output of a model of several) or one of the ``measured`` inputs
    (e.g. the motor current), in that order. The step's input is ``[u, *measured]``: the
    physics sees ``u``, the residual all of them (a controller treats ``measured`` as
    measured disturbances). The state is ``[physics states; residual states]``, named
    ``"physics.*"`` and ``"residual.*"``. ``weight``, a function of the residual's input vector
    (``ResidualDomain.function``), scales the residual: ``y = y_phys + weight(v) y_res``.
    """
    allowed = {"u", "y_phys", *measured}
    if not features or set(features) - allowed:
        raise ExportError(f"Residual features must be among {sorted(allowed)}. Got {list(features)}.")
    if combine != "add":
        raise ExportError(f"combine must be 'add'. Got {combine!r} instead.")
    width = sum(physics.n_y if f == "y_phys" else 1 for f in features)  # y_phys: every physics output
    if residual.n_u != width:
        raise ExportError(f"The residual takes {residual.n_u} inputs but the features named ({list(features)}) "
                          f"make {width}.")
    if residual.n_y != physics.n_y:
        raise ExportError(f"The physics has {physics.n_y} output(s) and the residual {residual.n_y}; a residual "
                          "corrects each physics output.")
    sym = ca.MX if "MX" in (physics.step.class_name()[:2], residual.step.class_name()[:2]) else ca.SX
    inputs = ("u", *measured)
    xp, xr, u = sym.sym("xp", physics.n_x), sym.sym("xr", residual.n_x), sym.sym("u", len(inputs))
    xp_next, y_phys = physics.step(xp, u[0])
    v = ca.vertcat(*[y_phys if f == "y_phys" else u[inputs.index(f)] for f in features])
    xr_next, y_res = residual.step(xr, v)
    if weight is not None:
        y_res = (weight.expand() if sym is ca.SX else weight)(v) * y_res
    x = ca.vertcat(xp, xr)
    step = ca.Function("step", [x, u], [ca.vertcat(xp_next, xr_next), y_phys + y_res],
                       ["x", "u"], ["x_next", "y"])
    u0, xp0 = ca.SX.sym("u0", len(inputs)), ca.SX.sym("xp0", physics.n_x)
    _, yp0 = physics.step(xp0, u0[0])  # the residual at rest at the first row its input has
    v0 = ca.vertcat(*[yp0 if f == "y_phys" else u0[inputs.index(f)] for f in features])
    from_physics = ca.Function("x0_physics", [u0, xp0], [ca.vertcat(xp0, residual.x0_base(v0))], ["u0", "xp"], ["x0"])
    base = ca.Function("x0", [u0], [from_physics(u0, physics.x0_base(u0[0]))], ["u0"], ["x0"])
    names = tuple(f"physics.{n}" for n in physics.state_names) + tuple(f"residual.{n}" for n in residual.state_names)
    meta: dict[str, Any] = {"physics": physics.meta, "residual": residual.meta, "features": list(features),
                            "inputs": list(inputs),
                            "combine": combine, "weighted": weight is not None}
    # the physics alone on the hybrid's state: the MPC's cheap Jacobian model
    approx = ca.Function("approximation", [x, u], [ca.vertcat(xp_next, xr), y_phys], ["x", "u"], ["x_next", "y"])
    return ExportedModel(step, names, base, dt=physics.dt, kind="hybrid", meta=meta, approximation=approx,
                         x0_physics=from_physics if physics.x0_physics is not None else None)


register_checkpoint("hysteresis-hybrid/learned-model", None, "hybrid.learning.LearnedModel")
