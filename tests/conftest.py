"""Fixtures shared by the test modules."""

import os
import signal

import pytest

from physics.data import DataNotFoundError, data_root


@pytest.fixture(scope="module")
def run_csv(tmp_path_factory):
    """A short run of the virtual catheter as a CSV file (two cycles at 0.4 Hz)."""
    from physics.virtual import DecayingSinusoid, VirtualCatheter

    root = tmp_path_factory.mktemp("data")
    return VirtualCatheter(seed=0).run(DecayingSinusoid(0.4, "mid", cycles=2), name="r").to_csv(root / "r.csv")


@pytest.fixture(scope="module")
def fitted_linear(tmp_path_factory):
    """A folder holding a 16 s simulated run at 25 Hz (``run.csv``) and a physics-only model folder
    fitted on it with ``hyst fit --physics linear`` (``model``)."""
    from hybrid.cli import main

    root = tmp_path_factory.mktemp("linear")
    assert main(["simulate", "--duration", "16", "--out", str(root / "run.csv")]) == 0
    assert main(["fit", str(root / "run.csv"), "--physics", "linear", "--residual", "none", "--no-progress",
                 "--out", str(root / "model")]) == 0
    return root


@pytest.fixture(scope="module")
def pose_runs():
    """Three runs of the virtual catheter with its tip (``Angle x``, ``Pos x``, ``Pos y``): 0.2 Hz from the zero
    baseline, 0.5 Hz from the end one, 0.3 Hz from the middle."""
    from hybrid.virtual import DecayingSinusoid, TipArc, VirtualCatheter

    cath = VirtualCatheter(seed=3, tip=TipArc())
    return [cath.run(DecayingSinusoid(frequency_hz=f, baseline=b)) for f, b in ((0.2, "zero"), (0.5, "end"), (0.3, "mid"))]


@pytest.fixture(scope="module")
def root():
    """The shared measured-data folder; the test is skipped with the reason where it is absent."""
    try:
        return data_root()
    except DataNotFoundError as exc:
        pytest.skip(f"shared data folder not available: {exc}")


def pytest_configure(config):
    """Under pytest-xdist (``make test`` runs ``-n 2``) each worker has a core of its own: torch's
    default of one thread per core would put two threads on each.

    Ctrl-C reaches the tests however the suite was started: a shell without job control starts what it
    puts in the background (``make test &``) with SIGINT ignored, which Python and every process it
    starts keep, and the tests that press Ctrl-C would see nothing."""
    if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    if os.environ.get("PYTEST_XDIST_WORKER"):
        try:
            import torch
        except ImportError:  # the learning extra is optional
            return
        torch.set_num_threads(1)
