"""Prediction intervals that hold, and flags where a model leaves its data.

:class:`ConformalModel` wraps any forward model: fitted on folds of whole runs, calibrated on the
runs each fold left out (split-conformal, runs as the exchangeable unit), ``predict(run,
interval=0.9)`` gives the prediction, its bounds and a per-sample flag where the input leaves the
training data (:class:`DataDistance`). :class:`AdaptiveIntervals` narrows or widens the band online from the
residuals measured now and then (adaptive conformal inference). Needs no torch.
"""

from ._adaptive import AdaptiveIntervals, AdaptiveState
from ._conditions import condition_folds, run_conditions
from ._conformal import ConformalIntervals, HeldOut, Interval, check_level, coverage, per_output_from_dict, per_output_to_dict
from ._forecast import ErrorForecast, error_forecast
from ._report import CalibrationReport
from ._distance import DataDistance, input_rows
from ._envelope import Envelope
from ._model import ConformalModel, held_out_predictions, predict_with

__all__ = ["AdaptiveIntervals", "AdaptiveState", "CalibrationReport", "ConformalIntervals", "ConformalModel", "ErrorForecast", "HeldOut", "DataDistance", "Envelope", "Interval", "check_level",
           "condition_folds", "coverage", "error_forecast", "held_out_predictions", "input_rows", "per_output_from_dict", "per_output_to_dict", "predict_with",
           "run_conditions"]
