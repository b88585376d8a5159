"""Purely learned models: the estimator, its training loop and checkpoints (these import torch)."""

from ._learned import DIRECTIONS, LearnedModel, load_checkpoint, save_checkpoint
from ._training import TrainingHistory, TrainingSettings, train

__all__ = ["LearnedModel", "DIRECTIONS", "TrainingSettings", "TrainingHistory", "train",
           "save_checkpoint", "load_checkpoint"]
