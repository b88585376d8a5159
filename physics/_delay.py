"""Pure transport delay of a whole number of samples."""

from __future__ import annotations

import casadi as ca

from ._block import AbstractBlock


class Delay(AbstractBlock):
    """``y_k = u_{k - samples}``: a shift register of the last ``samples`` inputs.

    The delay is structural (a whole number of samples at the model's rate), not
    a fitted parameter. A delay has no causal inverse; ``Series.inverse``
    handles it by advancing the wanted output path instead.
    """

    name = "delay"
    parameters = ()

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

    def __repr__(self):
        return f"Delay(samples={self.samples})"
