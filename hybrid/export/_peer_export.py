"""A linear ARX (:class:`hybrid.peers.LinearARX`) as an exported step: the peer a selection may choose."""

from __future__ import annotations

import casadi as ca

from ._export import register_exporter, register_window_init, symbol
from ._load import register_json_model
from ._model import ExportedModel, ExportError

__all__ = ["export_arx", "arx_init"]


@register_exporter("hybrid.peers.LinearARX")
def export_arx(model, symbolic: str = "SX") -> ExportedModel:
    """The fitted ARX as one CasADi step ``(x, u) -> (x_next, y)`` in physical units, its state the past
    outputs ``y[t-1..t-na]`` then inputs ``u[t-1..t-m]`` (``m = nk + nb - 1``), newest first; ``x0``
    holds the input at ``u0`` and the outputs at the ARX's rest output there, as ``predict`` without a
    window does. Its warm-up ``init`` is :func:`arx_init`."""
    if model.direction != "forward" or model.outputs:
        raise ExportError("Only a forward LinearARX of one output exports as a step (u -> y).")
    S, na, m, nk, nb = symbol(symbolic), int(model.na), model.past_inputs, int(model.nk), int(model.nb)
    x, u = S.sym("x", na + m), S.sym("u")
    y_n = (x[:na] - model.y_mean_) / model.y_std_
    recent = ca.vertcat(u, x[na:]) if m else u  # u[t], u[t-1], ..., u[t-m]
    u_n = (recent[nk:nk + nb] - model.u_mean_) / model.u_std_
    y = model.y_mean_ + model.y_std_ * (model.c_ + ca.dot(ca.DM(model.a_), y_n) + ca.dot(ca.DM(model.b_), u_n))
    shifted = [y, *(x[i] for i in range(na - 1))][:na] + [u, *(x[na + i] for i in range(m - 1))][:m]
    step = ca.Function("step", [x, u], [ca.vertcat(*shifted) if shifted else S(0, 1), y],
                       ["x", "u"], ["x_next", "y"])
    u0 = ca.SX.sym("u0")
    x0 = ca.vertcat(ca.repmat(model.rest_output(u0), na, 1), ca.repmat(u0, m, 1))
    names = [f"arx.y[k-{i}]" for i in range(1, na + 1)] + [f"arx.u[k-{i}]" for i in range(1, m + 1)]
    return ExportedModel(step=step, state_names=tuple(names), x0_base=ca.Function("x0", [u0], [x0], ["u0"], ["x0"]),
                         kind="arx", meta={"peer": "linear ARX", "na": na, "nb": nb, "nk": nk, "symbolic": symbolic})


@register_window_init("hybrid.peers.LinearARX")
def arx_init(model, k: int) -> ca.Function:
    """``Function('init', [u_w, y_w], [x])``: the state after a window of ``k`` measured samples, its last
    outputs and inputs (the first sample repeated where the window is shorter), as ``predict`` with a
    warm-up window sets it."""
    na, m = int(model.na), model.past_inputs
    u_w, y_w = ca.MX.sym("u_w", 1, k), ca.MX.sym("y_w", 1, k)
    newest = lambda w, n: [w[0, max(k - i, 0)] for i in range(1, n + 1)]  # noqa: E731
    x = ca.vertcat(*newest(y_w, na), *newest(u_w, m)) if na + m else ca.MX(0, 1)
    return ca.Function("init", [u_w, y_w], [x], ["u_w", "y_w"], ["x"])


register_json_model("hysteresis-hybrid/linear-arx/1", "hybrid.peers.LinearARX")
