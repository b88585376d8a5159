"""Control on exported models: tracking MPC (full-NLP SQP or adjoint SQP), closed loop, model inverse.

>>> from physics import Series
>>> from hybrid.export import export_model
>>> from hybrid.control import TrackingMPC
>>> mpc = TrackingMPC(export_model(Series.from_spec("lag+linear")), u_bounds=(0.0, 6.0), horizon=5)
"""

from ._adjoint_sqp import AdjointSQP
from ._closed_loop import REFERENCES, ClosedLoopResult, reference_signal, run_closed_loop
from ._static import rest_output
from ._controller_c import write_controller
from ._estimator import MovingHorizonEstimator, estimated_states, measurement_mask
from ._mpc import SOLVERS, MPCStats, TrackingMPC

__all__ = [
    "AdjointSQP", "TrackingMPC", "write_controller", "MovingHorizonEstimator", "estimated_states", "measurement_mask", "MPCStats", "SOLVERS",
    "run_closed_loop", "ClosedLoopResult", "reference_signal", "rest_output", "REFERENCES",
]
