"""Noise level and whiteness of a residual (defined in ``identification._noise``, which the fitting uses too)."""

from identification._noise import noise_floor, whiteness

__all__ = ["noise_floor", "whiteness"]
