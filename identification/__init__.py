"""Fitting physics models to data (CasADi + IPOPT) and finding what they miss.

>>> from identification import identify, discover, FitResult, DiscoveryReport
"""

from ._checks import data_scales
from ._errors import IdentificationError
from ._estimator import PhysicsEstimator
from ._identify import fitted_series, identify
from ._outputs import OutputsFit, identify_outputs, output_columns, predict_outputs
from ._ranking import Ranking
from ._result import FitResult
from ._solver_settings import SolverSettings
from .discovery import (EFFECTS, Candidate, DiscoveryReport, DiscoveryThresholds, PhysicsFitError, PhysicsPolicy,
                        PhysicsReport, ResidualTrace, Selection, SelectionSettings, Step, Workers, diagnose, discover,
                        fit_physics, noise_floor, physics_fits, plot_gap, plot_loops, plot_residual_signature,
                        residual_traces, select_physics, sensitivities, whiteness)

__all__ = [
    "identify", "identify_outputs", "OutputsFit", "output_columns", "predict_outputs", "SolverSettings", "fitted_series", "Ranking", "data_scales", "FitResult", "PhysicsEstimator",
    "IdentificationError",
    "discover", "DiscoveryThresholds", "DiscoveryReport", "Step", "diagnose", "Candidate", "ResidualTrace", "EFFECTS",
    "noise_floor", "whiteness", "residual_traces", "sensitivities", "select_physics", "Selection", "SelectionSettings",
    "Workers", "plot_residual_signature", "plot_loops", "plot_gap", "PhysicsPolicy", "PhysicsReport", "PhysicsFitError",
    "fit_physics", "physics_fits",
]
