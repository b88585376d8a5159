"""The data layer under the name users know; it lives in :mod:`physics.data`, below every layer that reads data."""

from physics.data import *  # noqa: F401,F403
from physics.data import __all__  # noqa: F401
