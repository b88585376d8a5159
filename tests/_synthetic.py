"""Synthetic data for the identification tests, made by models with known parameters."""

from types import SimpleNamespace

import numpy as np

from physics import Series

DT = 0.04
NOISE_DEG = 0.15
TRUTH = {
    "lag+boucwen+linear": {"lag.time_constant_s": 0.15, "boucwen.A": 0.5, "boucwen.beta": 1.0,
                           "boucwen.gamma": 0.4, "linear.gain": 10.0, "linear.offset": 30.0},
    "backlash+linear": {"backlash.width": 0.4, "linear.gain": 10.0, "linear.offset": 30.0},
}


def decaying(f: float, c: float, offset: float, cycles: float = 3, dt: float = DT):
    """The paper's decaying sinusoid 3 e^(-tau t)(sin(2 pi f t - pi/2) + c) + offset."""
    t = np.arange(0, cycles / f, dt)
    tau = f * np.log(7 / 6)
    return t, 3 * np.exp(-tau * t) * (np.sin(2 * np.pi * f * t - np.pi / 2) + c) + offset


def make_runs(model: Series, noise: float, seed: int = 0, cycles: float = 3,
              settings=((0.2, 1, 0), (0.35, 0, 3), (0.5, -1, 6))):
    """Trajectories (objects with time, u, y) simulated by ``model`` plus Gaussian noise."""
    rng = np.random.default_rng(seed)
    runs = []
    for f, c, off in settings:
        t, u = decaying(f, c, off, cycles, model.dt)
        y = model.simulate(u) + noise * rng.standard_normal(u.size)
        runs.append(SimpleNamespace(time=t, u=u, y=y, meta={"frequency_hz": f}))
    return runs


def truth_model(spec: str) -> Series:
    return Series.from_spec(spec, dt=DT).set_params(**TRUTH[spec])
