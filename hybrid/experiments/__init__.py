"""Experiments: the seed paper's Table I, side-by-side comparisons, ablations, ``fit_model_dir`` and their figures."""

from ._columns import Columns
from ._fit import FittedModelDir, fit_model_dir

__all__ = ["fit_model_dir", "FittedModelDir", "Columns"]
