"""The discrepancy workflow: where a physics model and data disagree, which effect is missing.

>>> from identification.discovery import discover, diagnose, noise_floor
"""

from ._discover import discover, residual_traces, sensitivities
from ._thresholds import DiscoveryThresholds
from ._noise import noise_floor, whiteness
from ._folds import Holdout, holdout, next_folds, reversals, run_folds
from ._select import (CV_IDENTIFY, SELECT_BLOCKS, SELECT_REFINEMENTS, Selection, diverges, evidence, select_physics,
                      spread_of)
from ._pool import Workers, make_pool
from ._selection_settings import SelectionSettings
from ._several import select_outputs, select_outputs_chain
from ._policy import (AUTO, DEFAULT_SPECS, FALLBACK, PhysicsFitError, PhysicsPolicy, PhysicsReport, fit_physics,
                      physics_fits, substitution)
from ._report import DiscoveryReport, Step, plot_gap, plot_loops, plot_residual_signature
from ._signatures import EFFECTS, Candidate, ResidualTrace, diagnose

__all__ = [
    "discover", "DiscoveryThresholds", "DiscoveryReport", "Step", "diagnose", "Candidate", "ResidualTrace", "EFFECTS",
    "noise_floor", "whiteness", "residual_traces", "sensitivities", "select_physics", "select_outputs", "select_outputs_chain", "Selection",
    "SelectionSettings",
    "Workers", "run_folds", "holdout", "Holdout", "next_folds", "reversals",
    "SELECT_BLOCKS", "SELECT_REFINEMENTS", "plot_residual_signature", "plot_loops", "plot_gap",
    # the selection's rules, shared with the model folder and the scores: its fits' options, its folds
    # (holdout), a diverged fold, the evidence behind a choice
    "CV_IDENTIFY", "diverges", "spread_of", "evidence",
    "PhysicsPolicy", "PhysicsReport", "PhysicsFitError", "fit_physics", "physics_fits", "AUTO", "FALLBACK",
    "DEFAULT_SPECS", "substitution",
    # where independent fits run (here, local workers, a Dask cluster): the selection's and compare's
    "make_pool",
]
