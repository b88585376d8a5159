"""Control on exported models: tracking MPC (its settings, one solver class per solver name), closed loop, model inverse.

>>> from physics import Series
>>> from hybrid.export import export_model
>>> from hybrid.control import MPCSettings, TrackingMPC
>>> mpc = TrackingMPC(export_model(Series.from_spec("lag+linear")), MPCSettings(horizon=5, u_bounds=(0.0, 6.0)))
>>> sorted(SOLVERS)
['adjoint-sqp', 'fixed-sqp', 'ipopt', 'sqp']
"""

from ._adjoint_sqp import ADJOINT_TOL, AdjointSQP, AdjointSQPSolver
from ._closed_loop import REFERENCES, ClosedLoopResult, Feedback, reference_signal, run_closed_loop
from ._static import rest_output
from ._controller_c import write_controller
from ._estimator import MovingHorizonEstimator, estimated_states, measurement_mask
from ._fixed_sqp import FixedSQPSolver
from ._mpc import MPCStats, TrackingMPC
from ._mpc_settings import MPCSettings
from ._mpc_problem import COST_SCALE, MPCProblem
from ._mpc_solver import SOLVERS, MPCSolution, MPCSolver, register_solver
from ._nlp import IpoptSolver, NLPSolver, SQPSolver

__all__ = [
    "TrackingMPC", "MPCSettings", "MPCStats", "MPCProblem", "MPCSolution", "MPCSolver", "SOLVERS", "register_solver",
    "SQPSolver", "IpoptSolver", "NLPSolver", "AdjointSQPSolver", "FixedSQPSolver", "AdjointSQP", "ADJOINT_TOL", "COST_SCALE",
    "write_controller", "MovingHorizonEstimator", "estimated_states", "measurement_mask",
    "run_closed_loop", "Feedback", "ClosedLoopResult", "reference_signal", "rest_output", "REFERENCES",
]
