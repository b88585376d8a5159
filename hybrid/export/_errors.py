"""The export layer's one error type."""


class ExportError(ValueError):
    """A model, file or option that cannot be exported or loaded (the message says how to fix it)."""
