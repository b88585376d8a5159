"""Fixtures shared by the test modules."""

import pytest

from physics.data import DataNotFoundError, data_root


@pytest.fixture(scope="module")
def root():
    """The shared measured-data folder; the test is skipped with the reason where it is absent."""
    try:
        return data_root()
    except DataNotFoundError as exc:
        pytest.skip(f"shared data folder not available: {exc}")
