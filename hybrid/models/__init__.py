"""Hybrid models: physics plus residual networks, and neural-ODE hybrids (these import torch)."""
