"""Torch layers as CasADi expressions: the names ``hybrid.export`` has always offered.

They live with the networks that use them (:mod:`hybrid.networks._casadi`, and the
LSTM's in :mod:`hybrid.networks._lstm`); this module re-exports them.
"""

from hybrid.networks._casadi import MAC_BLOCK, as_dm, matvec, mlp_expr
from hybrid.networks._lstm import lstm_state_names, lstm_step_expr

__all__ = ["mlp_expr", "lstm_step_expr", "lstm_state_names", "as_dm", "matvec", "MAC_BLOCK"]
