"""Fixtures shared by the test modules."""

import os

import pytest

from physics.data import DataNotFoundError, data_root


@pytest.fixture(scope="module")
def run_csv(tmp_path_factory):
    """A short run of the virtual catheter as a CSV file (two cycles at 0.4 Hz)."""
    from physics.virtual import DecayingSinusoid, VirtualCatheter

    root = tmp_path_factory.mktemp("data")
    return VirtualCatheter(seed=0).run(DecayingSinusoid(0.4, "mid", cycles=2), name="r").to_csv(root / "r.csv")


@pytest.fixture(scope="module")
def root():
    """The shared measured-data folder; the test is skipped with the reason where it is absent."""
    try:
        return data_root()
    except DataNotFoundError as exc:
        pytest.skip(f"shared data folder not available: {exc}")


def pytest_configure(config):
    """Under pytest-xdist (``make test`` runs ``-n 2``) each worker has a core of its own: torch's
    default of one thread per core would put two threads on each."""
    if os.environ.get("PYTEST_XDIST_WORKER"):
        try:
            import torch
        except ImportError:  # the learning extra is optional
            return
        torch.set_num_threads(1)
