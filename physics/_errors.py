"""Errors raised by the physics layer."""


class PhysicsError(ValueError):
    """Bad model specification, parameter or input for a physics model."""
