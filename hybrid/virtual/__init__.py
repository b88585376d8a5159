"""The virtual catheter under the name users know; it lives in :mod:`physics.virtual`."""

from physics.virtual import *  # noqa: F401,F403
from physics.virtual import __all__  # noqa: F401
