"""Hybrid models: physics plus residual networks, and neural-ODE hybrids (these import torch)."""

from ._domain import ResidualDomain
from ._hybrid import HybridModel
from ._hybrid_tune import FineTuneSettings
from ._neural_ode import NeuralODEHybrid

__all__ = ["HybridModel", "FineTuneSettings", "NeuralODEHybrid", "ResidualDomain"]
