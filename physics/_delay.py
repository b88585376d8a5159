"""Pure transport delay of a whole number of samples."""

from __future__ import annotations

import casadi as ca
import numpy as np

from ._block import AbstractBlock
from ._signature import Signature


def delay_shapes(v: np.ndarray, dt: float, delays: np.ndarray) -> np.ndarray:
    """``v(t - d) - v(t)`` for each delay (linear interpolation; ``v[0]`` before the start)."""
    t = np.arange(v.size) * dt
    return np.stack([np.interp(t - d, t, v, left=v[0]) for d in delays], axis=1) - v[:, None]


def _estimate(e):
    samples = max(1, int(round(e.grid["delay_s"] / e.dt)))
    return {}, {"samples": samples, "delay_s": e.grid["delay_s"]}


class Delay(AbstractBlock):
    """``y_k = u_{k - samples}``: a shift register of the last ``samples`` inputs.

    The delay is structural (a whole number of samples at the model's rate), not
    a fitted parameter. A delay has no causal inverse; ``Series.inverse``
    handles it by advancing the wanted output path instead.
    """

    name = "delay"
    parameters = ()
    effect = "time_delay"
    rank = 1
    selectable = False  # its length counts samples: the selection would fit its folds at the runs' own rate
    searched_setting = "samples"
    pure_delay = True
    signature = Signature(
        family="rate", terms=("dv/dt", "d2v/dt2"),
        # the block delays by whole samples
        grid=lambda dt, span: [{"delay_s": float(g)} for g in np.arange(1, int(round(0.6 / dt)) + 1) * dt],
        shapes=lambda v, dt, grid: delay_shapes(v, dt, np.array([g["delay_s"] for g in grid])),
        estimate=_estimate,
        describe=lambda p, s: f"{s['samples']} samples ({s['delay_s']:.3g} s)",
    )

    @property
    def delay_samples(self) -> int:
        return self.samples

    def __init__(self, samples: int = 1):
        if int(samples) != samples or samples < 0:
            raise ValueError(f"Delay samples must be a whole number >= 0. Got {samples} instead.")
        self.samples = int(samples)

    @property
    def state_names(self):
        return tuple(f"u_lag{self.samples - i}" for i in range(self.samples))

    def step(self, x, u, p, dt):
        if self.samples == 0:
            return ca.DM.zeros(0, 1), u
        return ca.vertcat(*[x[i] for i in range(1, self.samples)], u), x[0]

    def steady_state(self, u0, p):
        return ca.repmat(ca.vertcat(u0), self.samples, 1)

    continuous_states = None

    def inverse_output(self, x, y, p, dt):
        raise NotImplementedError("a delay has no causal inverse; use Series.inverse")

    def summary(self, dt):
        return {"samples": self.samples, "delay_s": self.samples * dt}

    def describe(self, dt):
        return f"{self.samples} samples ({self.samples * dt:.3g} s)"

    def __repr__(self):
        return f"Delay(samples={self.samples})"
