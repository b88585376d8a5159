"""Exporters of the hybrid models, found by ``export_model`` through their type.

The models know nothing of CasADi export; this module reads their fitted state
(physics ``Series``, residual network and scalers, neural-ODE weights) and writes
each as one :class:`ExportedModel`. Each registers here, with the loader of its checkpoints, by its
class's public name, so that importing ``hybrid.export`` never imports torch.
"""

from __future__ import annotations

import casadi as ca

from hybrid.networks._casadi import as_dm, mlp_expr
from physics import THREE_EIGHTHS, rk_step
from physics.data import NotFittedError

from ._export import export_series, register_exporter, symbol
from ._load import register_checkpoint
from ._model import ExportedModel, ExportError
from ._network_export import compose_hybrid, export_network, scaler_range

__all__ = ["export_hybrid", "export_neural_ode"]


def _check_fitted(model, attr: str) -> None:
    if not hasattr(model, attr):
        raise NotFittedError(f"This {type(model).__name__} is not fitted yet. Call fit(trajectories) or "
                             f"{type(model).__name__}.load(path) before exporting it.")


@register_exporter("hybrid.models.HybridModel")
def export_hybrid(model, symbolic: str = "SX", mode: str | None = None) -> ExportedModel:
    """A forward ``HybridModel`` as one CasADi step (``compose_hybrid`` of physics and residual).

    ``mode`` is the residual network's export mode; by default the network's own
    (the one ``predict`` uses, so the export equals it from sample 0). An LSTM
    trained with ``mode="carried"`` gives the cheap recurrent step a controller wants.
    """
    _check_fitted(model, "residual_")
    measured = model.extra_inputs_  # measured inputs (e.g. motor current): the step's input is [u, *measured]
    names = {"u": "u", "physics": "y_phys", **{m: m for m in measured}}
    if model.direction != "forward" or any(f not in names for f in model.feature_names_):
        raise ExportError("Only forward hybrids fed 'u', 'physics' and measured inputs (no physics states) can be "
                          f"exported; this one has direction={model.direction!r}, "
                          f"features={list(model.feature_names_)}.")
    learned, net = model.residual_, model.network_
    res = export_network(learned.module_, learned.input_scaler_, learned.output_scaler_,
                         mode=mode or getattr(net, "mode", None), symbolic=symbolic,
                         network=type(net))
    domain = getattr(model, "domain_", None)
    out = compose_hybrid(export_series(model.physics_, symbolic), res, [names[f] for f in model.feature_names_],
                         measured=measured, weight=None if domain is None else domain.function())
    out.meta["model"] = model.name
    if "u" in model.feature_names_:  # the range the residual was trained on, else the physics'
        out.meta["input_range"] = scaler_range(model.residual_.input_scaler_, model.feature_names_.index("u"))
    elif "input_range" in out.meta["physics"]:
        out.meta["input_range"] = out.meta["physics"]["input_range"]
    return out


@register_exporter("hybrid.models.NeuralODEHybrid")
def export_neural_ode(model, symbolic: str = "SX", mode: str | None = None) -> ExportedModel:
    """A ``NeuralODEHybrid`` as one CasADi step (kind ``"neural-ode"``).

    The state is ``[xc; u_prev]`` (continuous physics states, the input of the
    sample before). The step is the same fixed RK4 steps (``substeps`` per sample) as
    torchdiffeq's ``'rk4'`` (the 3/8 rule) on the same right-hand side, the physics from
    ``Series.ode_function`` and the correction from the network's weights. It equals the
    model's prediction for input changes up to ``meta["max_input_step"]`` per sample (the
    training's fastest), where the prediction takes no finer steps (``_ODE.refinement``); the
    MPC's default rate limit stays under it.
    Its ``approximation`` is the physics ODE alone, for the MPC. ``mode`` has
    no effect (there is no network state).
    """
    _check_fitted(model, "module_")
    m, series = model.module_, model.physics_
    ode, p, dt = series.ode_function(), ca.DM(series.params), m.dt
    names = series.continuous_state_names
    S = symbol(symbolic)
    x, u = S.sym("x", len(names) + 1), S.sym("u")
    xc, u_prev = x[:len(names)], x[len(names)]
    udot = (u - u_prev) / dt
    lo, span, (u_lo, u_span, udot_span) = as_dm(m.x_lo), as_dm(m.x_span), m.u_norm.tolist()

    def rhs(s, xs, corrected):
        us = u_prev + s * udot
        xdot = ode(xs, us, udot, p)[0]
        if not corrected:
            return xdot
        corr = mlp_expr(m.net, ca.vertcat((xs - lo) / span, (us - u_lo) / u_span, udot / udot_span))
        return xdot + (corr * udot if m.gated else corr)

    def step(corrected, name):
        xn, h = xc, dt / m.substeps
        for i in range(m.substeps):
            xn = rk_step(lambda s, xs: rhs(s, xs, corrected), i * h, xn, h, THREE_EIGHTHS)
        return ca.Function(name, [x, u], [ca.vertcat(xn, u), ode(xn, u, 0, p)[1]], ["x", "u"], ["x_next", "y"])

    u0, xp = ca.SX.sym("u0"), ca.SX.sym("xp", series.n_x)
    from_physics = ca.Function("x0_physics", [u0, xp], [ca.vertcat(*[xp[series.state_names.index(n)] for n in names], u0)],
                               ["u0", "xp"], ["x0"])
    x0 = from_physics(u0, export_series(series).x0_base(u0))
    meta = {"spec": series.spec, "parameters": series.param_dict(), "hidden": model.hidden, "gated": model.gated,
            "substeps": m.substeps, "symbolic": symbolic, "input_range": [u_lo, u_lo + u_span],
            "max_input_step": udot_span * dt}
    return ExportedModel(step(True, "step"), tuple(names) + ("u_prev",), ca.Function("x0", [u0], [x0], ["u0"], ["x0"]),
                         dt=dt, kind="neural-ode", meta=meta, approximation=step(False, "approximation"),
                         x0_physics=from_physics)


register_checkpoint("hysteresis-hybrid/hybrid-model", "residual", "hybrid.models.HybridModel")
register_checkpoint("hysteresis-hybrid/hybrid-model", "neural-ode", "hybrid.models.NeuralODEHybrid")
