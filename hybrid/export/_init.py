"""``init``: an exported model's state from a window of measured samples, beside its ``step``.

``init(u_w, y_w) -> x`` is the state after a window of ``K`` measured inputs and outputs, where a
controller's or a prediction's next sample starts. The model's physics states before the window
are fitted to it (the window fit of :mod:`physics._warmup`, a fixed number of Levenberg-Marquardt
iterations, its scales folded in as constants), every other state (a network's) starts at rest at
the window's first input, and the model's own step then runs through the window: what
``predict(data, warmup=...)`` of the fitted model does, as one pure CasADi function.
"""

from __future__ import annotations

from dataclasses import replace

import casadi as ca
import numpy as np

from ._model import ExportedModel, ExportError

__all__ = ["with_init", "physics_of"]


def physics_of(model):
    """The physics ``Series`` inside a fitted model (the model itself for a Series), or None."""
    from physics import Series

    if isinstance(model, Series):
        return model
    physics = getattr(model, "physics_", None)
    return physics if isinstance(physics, Series) else None


def with_init(exported: ExportedModel, series, k: int, outputs=None) -> ExportedModel:
    """A copy of ``exported`` with ``init`` over windows of ``k`` samples (``series``: its physics, or None for a
    network alone, whose state comes from running through the window). A model of several outputs takes every
    output's window (``y_w``: n_y x k) and fits its state on the one :func:`~identification._outputs.primary_view`
    names (``meta["init_output"]``: the tip's angle, or the first output), as its predictions do; or, given
    ``outputs`` (their indices), on those outputs' windows at once, each over its own scale (``meta["init_outputs"]``;
    the other rows of ``y_w`` are not read): a camera that sees the tip's position and not its angle."""
    from physics._warmup import init_function, scales

    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or k < 1:
        raise ExportError(f"The warm-up window of an export must be an integer >= 1 samples. Got {k!r} instead.")
    k = int(k)
    outputs = _outputs(outputs, exported, series)
    u_w, y_w = ca.MX.sym("u_w", exported.n_u, k), ca.MX.sym("y_w", exported.n_y, k)
    x = exported.x0_base(u_w[:, 0])
    read, meta = y_w, {}
    if outputs is not None:
        read, meta = ca.vertcat(*[y_w[j, :] for j in outputs]), {"init_outputs": list(outputs)}
    elif series is not None and series.n_y > 1:  # the state is fitted on one output's window (the tip's angle)
        from identification._outputs import primary_view

        series, j = primary_view(series)
        read, meta = y_w[j, :], {"init_output": j}
    if series is not None and exported.x0_physics is not None:
        p = series.params
        lo, hi = series.input_range or exported.input_range or (0.0, 1.0)
        if outputs is None:
            s_x, s_y = scales(series, np.array([lo, hi]), np.zeros(2), p)
            fit = init_function(series, k, False)
        else:  # the states' scales are the chain's; each output its own
            per = [scales(series.output_view(j), np.array([lo, hi]), np.zeros(2), p) for j in outputs]
            s_x, s_y = per[0][0], np.array([s for _, s in per])
            fit = init_function(series, k, False, read=outputs)
        _, xp, _ = fit(u_w[0, :], read, p, s_x, s_y)
        x = exported.x0_physics(u_w[:, 0], xp)
    xs, _ = exported.step.mapaccum("window", k)(x, u_w)
    init = ca.Function("init", [u_w, y_w], [xs[:, k - 1]], ["u_w", "y_w"], ["x"])
    return replace(exported, init=init, meta={**exported.meta, "warmup": k, **meta})


def _outputs(outputs, exported: ExportedModel, series) -> tuple[int, ...] | None:
    """``outputs`` checked: None, or the distinct indices of outputs of a physics model of several."""
    if outputs is None:
        return None
    if series is None or exported.n_y == 1:
        raise ExportError("outputs= picks the measured outputs of a physics model of several; this one has "
                          f"{exported.n_y} output(s){'' if series is not None else ' and no physics'}. Leave it out.")
    try:
        picked = tuple(int(j) for j in outputs)
    except (TypeError, ValueError):
        picked = ()
    if not picked or len(set(picked)) != len(picked) or not all(0 <= j < exported.n_y for j in picked) \
            or any(isinstance(j, bool) or int(j) != j for j in outputs):
        raise ExportError(f"outputs= names the measured outputs by index, each once, in 0..{exported.n_y - 1}. "
                          f"Got {outputs!r}.")
    return tuple(sorted(picked))
