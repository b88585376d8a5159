"""``export_model``: each model kind provides its own export, found by type or a ``to_casadi`` method.

The protocol is small: a model exports itself when it has a ``to_casadi(**options)``
method returning an :class:`ExportedModel`; otherwise the exporter registered
for its type (or a base type) with :func:`register_exporter` is used. Physics
``Series`` are registered here; the learned and hybrid models' exporters
(``_network_export``, ``_model_export``) by class path, imported on first use.
"""

from __future__ import annotations

import importlib
from dataclasses import replace
from typing import Any, Callable

import casadi as ca
import numpy as np

from ._model import ExportedModel, ExportError

__all__ = ["export_model", "register_exporter", "EXPORTERS", "LAZY_EXPORTERS", "export_series", "symbol"]

#: type -> exporter ``f(model, **options) -> ExportedModel``.
EXPORTERS: dict[type, Callable[..., ExportedModel]] = {}

#: "module.QualName" of a model class -> "module:function" of its exporter, imported on first
#: use so that importing hybrid.export never imports torch.
LAZY_EXPORTERS: dict[str, str] = {
    "hybrid.learning._learned.LearnedModel": "hybrid.export._network_export:export_learned",
    "hybrid.models._hybrid.HybridModel": "hybrid.export._model_export:export_hybrid",
    "hybrid.models._neural_ode.NeuralODEHybrid": "hybrid.export._model_export:export_neural_ode",
    "hybrid.peers._arx.LinearARX": "hybrid.export._peer_export:export_arx",
}
#: "module.QualName" of a model class whose state is its measured past -> "module:function" giving
#: ``init(u_w, y_w) -> x`` over ``k`` samples (``f(model, k)``), used instead of the generic window fit.
WINDOW_INITS: dict[str, str] = {"hybrid.peers._arx.LinearARX": "hybrid.export._peer_export:arx_init"}


def register_exporter(cls: type):
    """Decorator: ``@register_exporter(MyModel)`` makes ``export_model`` call the function for it."""
    def decorate(fn):
        EXPORTERS[cls] = fn
        return fn
    return decorate


def export_model(model: Any, warmup: int | None = None, **options: Any) -> ExportedModel:
    """The model as a pure CasADi step in physical units (see :class:`ExportedModel`).

    Parameters
    ----------
    model
        A ``physics.Series``, an object with ``to_casadi(**options)``, or any type
        with a registered exporter.
    warmup : int, optional
        Also export ``init(u_w, y_w) -> x``, the state after ``warmup`` measured samples
        (:mod:`hybrid.export._init`; a model whose state is its measured past, such as a linear ARX,
        gives its own: :data:`WINDOW_INITS`), so a controller starts from the measured state.
    **options
        Passed to the exporter, e.g. ``symbolic="SX"`` or ``"MX"``.
    """
    if isinstance(model, ExportedModel):
        return model
    out = _export(model, **options)
    if warmup is not None:
        from ._init import physics_of, with_init

        own = _lookup(model, WINDOW_INITS)  # a model whose state is its measured past (an ARX) sets it so
        out = (replace(out, init=own(model, int(warmup)), meta={**out.meta, "warmup": int(warmup)}) if own
               else with_init(out, physics_of(model), warmup))
    return out


def _export(model: Any, **options: Any) -> ExportedModel:
    to_casadi = getattr(model, "to_casadi", None)
    if callable(to_casadi):
        out = to_casadi(**options)
        if not isinstance(out, ExportedModel):
            raise ExportError(f"{type(model).__name__}.to_casadi must return an ExportedModel; "
                              f"got {type(out).__name__}.")
        return out
    for cls in type(model).__mro__:
        if cls in EXPORTERS:
            return EXPORTERS[cls](model, **options)
        lazy = _named(LAZY_EXPORTERS.get(f"{cls.__module__}.{cls.__qualname__}"))
        if lazy:
            return lazy(model, **options)
    known = ", ".join(sorted([c.__name__ for c in EXPORTERS] + [k.rsplit(".", 1)[1] for k in LAZY_EXPORTERS]))
    raise ExportError(f"No exporter for {type(model).__name__}. Must be one of: {known}, or an object "
                      "with a to_casadi() method (see hybrid.export.register_exporter).")


def _named(target: str | None) -> Callable | None:
    """The function a "module:function" string names, imported now (None for None)."""
    if not target:
        return None
    module, _, name = target.partition(":")
    return getattr(importlib.import_module(module), name)


def _lookup(model: Any, table: dict[str, str]) -> Callable | None:
    """The function ``table`` names for ``model``'s class or its nearest base that has one."""
    for cls in type(model).__mro__:
        found = _named(table.get(f"{cls.__module__}.{cls.__qualname__}"))
        if found:
            return found
    return None


def symbol(symbolic: str):
    """``casadi.SX`` or ``casadi.MX`` from its name."""
    if symbolic not in ("SX", "MX"):
        raise ExportError(f"symbolic must be 'SX' or 'MX'. Got {symbolic!r} instead.")
    return ca.SX if symbolic == "SX" else ca.MX


def _register_physics() -> None:
    from physics import Series

    register_exporter(Series)(export_series)


def export_series(model, symbolic: str = "SX") -> ExportedModel:
    """A physics ``Series`` with its current parameters folded in as constants."""
    S = symbol(symbolic)
    x, u = S.sym("x", model.n_x), S.sym("u")
    p = ca.DM(model.params) if model.n_p else ca.DM.zeros(0, 1)
    x_next, y = model.step_expr(x, u, p)
    step = ca.Function("step", [x, u], [x_next, y], ["x", "u"], ["x_next", "y"])
    # rest state: the model's one symbolic rule (Series.steady_state_expr)
    u0 = ca.SX.sym("u0")
    try:
        x0, _ = model.steady_state_expr(u0, p)
    except (TypeError, RuntimeError, NotImplementedError) as exc:
        raise ExportError(f"The rest state of '{model.spec}' cannot be written symbolically ({exc}); "
                          "make its blocks' steady_state accept a symbolic input.") from exc
    x0_base = ca.Function("x0", [u0], [ca.SX(x0)], ["u0"], ["x0"])
    meta = {"spec": model.spec, "parameters": model.param_dict(), "symbolic": symbolic}
    if getattr(model, "input_range", None) is not None:
        meta["input_range"] = list(model.input_range)
    xp = ca.SX.sym("xp", model.n_x)
    return ExportedModel(step=step, state_names=tuple(model.state_names), x0_base=x0_base,
                         dt=model.dt, kind="physics", meta=meta,
                         x0_physics=ca.Function("x0_physics", [u0, xp], [xp], ["u0", "xp"], ["x0"]))


_register_physics()
