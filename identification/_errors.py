"""Errors raised by the identification layer."""


class IdentificationError(ValueError):
    """The solver did not converge, or the fitting problem is badly posed.

    Pass ``allow_failure=True`` to :func:`identification.identify` to get a
    result flagged ``success=False`` instead of this error.
    """
