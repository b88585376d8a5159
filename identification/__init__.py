"""Fitting physics models to data: CasADi + IPOPT, with standard errors.

>>> from identification import identify, FitResult, PhysicsEstimator, IdentificationError
"""

from ._errors import IdentificationError
from ._estimator import PhysicsEstimator
from ._identify import identify
from ._result import FitResult

__all__ = ["identify", "FitResult", "PhysicsEstimator", "IdentificationError"]
