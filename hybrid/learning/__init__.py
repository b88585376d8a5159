"""Purely learned models: the estimator, its training loop and checkpoints (these import torch)."""
