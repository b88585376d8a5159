"""``export_model``: each model kind provides its own export, found by type or a ``to_casadi`` method.

The protocol is small: a model exports itself when it has a ``to_casadi(**options)``
method returning an :class:`ExportedModel`; otherwise the exporter registered
for its type (or a base type) with :func:`register_exporter` is used. Each exporter
registers itself in its own module: physics ``Series`` here, the learned, hybrid and
peer models in ``_network_export``, ``_model_export`` and ``_peer_export``, by the
public name of their class (``"hybrid.models.HybridModel"``), matched once that
package is imported, so that importing hybrid.export never imports torch.
"""

from __future__ import annotations

import sys
from dataclasses import replace
from typing import Any, Callable

import casadi as ca
import numpy as np

from ._model import ExportedModel, ExportError

__all__ = ["export_model", "register_exporter", "register_window_init", "EXPORTERS", "WINDOW_INITS",
           "export_series", "symbol"]

#: Model class, or the public "package.Name" of one -> exporter ``f(model, **options) -> ExportedModel``.
EXPORTERS: dict[type | str, Callable[..., ExportedModel]] = {}
#: Model class (or public name) whose state is its measured past -> ``f(model, k)`` giving
#: ``init(u_w, y_w) -> x`` over ``k`` samples, used instead of the generic window fit.
WINDOW_INITS: dict[type | str, Callable[..., Any]] = {}


def register_exporter(cls: type | str):
    """Decorator: ``@register_exporter(MyModel)`` makes ``export_model`` call the function for it.

    ``cls`` may be the class's public name, ``"package.Name"``: the exporter then applies once that
    package is imported (a model's exporter need not import the model, nor torch)."""
    def decorate(fn):
        EXPORTERS[_key(cls)] = fn
        return fn
    return decorate


def register_window_init(cls: type | str):
    """Decorator: ``@register_window_init(MyModel)`` gives ``export_model(..., warmup=k)`` the model's own
    ``init(u_w, y_w) -> x`` (``f(model, k)``), for a model whose state is its measured past."""
    def decorate(fn):
        WINDOW_INITS[_key(cls)] = fn
        return fn
    return decorate


def _key(cls: type | str) -> type | str:
    if isinstance(cls, type) or (isinstance(cls, str) and "." in cls.strip(".")):
        return cls
    raise ExportError(f"register a model class or its public name 'package.Name'. Got {cls!r} instead.")


def _lookup(model: Any, table: dict) -> Callable | None:
    """The function ``table`` holds for ``model``'s class or its nearest base that has one."""
    for cls in type(model).__mro__:
        if cls in table:
            return table[cls]
        for key, fn in table.items():
            if isinstance(key, str):
                module, _, name = key.rpartition(".")
                if module in sys.modules and getattr(sys.modules[module], name, None) is cls:
                    return fn
    return None


def export_model(model: Any, warmup: int | None = None, init_outputs=None, **options: Any) -> ExportedModel:
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
    init_outputs : sequence of int, optional
        A physics model of several outputs: ``init`` fits the state on these outputs' windows (default:
        the one its predictions fit it on, the tip's angle).
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
               else with_init(out, physics_of(model), warmup, init_outputs))
    elif init_outputs is not None:
        raise ExportError("init_outputs= says which outputs the warm-up window's init reads; give warmup= too.")
    return out


def _export(model: Any, **options: Any) -> ExportedModel:
    to_casadi = getattr(model, "to_casadi", None)
    if callable(to_casadi):
        out = to_casadi(**options)
        if not isinstance(out, ExportedModel):
            raise ExportError(f"{type(model).__name__}.to_casadi must return an ExportedModel; "
                              f"got {type(out).__name__}.")
        return out
    found = _lookup(model, EXPORTERS)
    if found:
        return found(model, **options)
    known = ", ".join(sorted(k.__name__ if isinstance(k, type) else k.rsplit(".", 1)[1] for k in EXPORTERS))
    raise ExportError(f"No exporter for {type(model).__name__}. Must be one of: {known}, or an object "
                      "with a to_casadi() method (see hybrid.export.register_exporter).")


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
