"""Experiments: the seed paper's Table I, side-by-side comparisons, ablations, ``fit_model_dir`` and their figures."""

from ._columns import Columns
from ._fit import FittedModelDir, fit_model_dir
from ._fit_outputs import outputs_physics
from ._presets import BUDGETS, Budget, NetworkBudget

__all__ = ["fit_model_dir", "FittedModelDir", "Columns", "BUDGETS", "Budget", "NetworkBudget", "outputs_physics"]
