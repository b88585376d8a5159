"""Fitting physics models to data (CasADi + IPOPT) and finding what they miss.

>>> from identification import identify, discover, FitResult, DiscoveryReport
"""

from ._discover import discover, residual_traces, sensitivities
from ._errors import IdentificationError
from ._estimator import PhysicsEstimator
from ._identify import identify
from ._report import DiscoveryReport, Step, plot_gap, plot_loops, plot_residual_signature
from ._result import FitResult
from ._noise import noise_floor, whiteness
from ._signatures import EFFECTS, Candidate, ResidualTrace, diagnose

__all__ = [
    "identify", "FitResult", "PhysicsEstimator", "IdentificationError",
    "discover", "DiscoveryReport", "Step", "diagnose", "Candidate", "ResidualTrace", "EFFECTS",
    "noise_floor", "whiteness", "residual_traces", "sensitivities",
    "plot_residual_signature", "plot_loops", "plot_gap",
]
