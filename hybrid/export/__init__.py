"""Fitted models as pure CasADi functions (physical units in and out), and C code.

Controllers built on them (MPC, closed loop, model inverse) live in :mod:`hybrid.control`.

>>> from physics import Series
>>> from hybrid.export import export_model
>>> m = export_model(Series.from_spec("lag+boucwen+linear"))
>>> m.step.name_in(), m.step.name_out()
(['x', 'u'], ['x_next', 'y'])
"""

from ._codegen import codegen, compile_c_demo, has_compiler, load_compiled, write_c_demo
from ._export import EXPORTERS, export_model, export_series, register_exporter, register_window_init
from ._load import load, register_checkpoint, register_json_model
from ._model import ExportedModel, ExportError
from ._network_export import compose_hybrid, export_buffer_mlp, export_learned, export_lstm, export_network
from ._model_export import export_hybrid, export_neural_ode
from ._peer_export import arx_init, export_arx
from hybrid.networks._casadi import mlp_expr
from hybrid.networks._lstm import lstm_state_names, lstm_step_expr

__all__ = [
    "ExportedModel", "ExportError", "load", "export_model", "export_series", "register_exporter", "EXPORTERS",
    "register_window_init", "register_checkpoint", "register_json_model", "export_arx", "arx_init",
    "export_network", "export_buffer_mlp", "export_lstm", "export_learned", "compose_hybrid",
    "export_hybrid", "export_neural_ode",
    "mlp_expr", "lstm_step_expr", "lstm_state_names",
    "codegen", "load_compiled", "has_compiler", "write_c_demo", "compile_c_demo",
]
