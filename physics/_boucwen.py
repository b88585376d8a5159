"""Bouc-Wen rate-independent hysteresis."""

from __future__ import annotations

import itertools

import casadi as ca
import numpy as np

from ._block import AbstractBlock, Parameter, clip_to_bounds, smooth_abs
from ._integrate import rk_step
from ._signature import Signature

#: Starting initial slopes and saturation factors tried by identification.
BOUCWEN_A = (0.2, 0.4, 0.6, 0.8)
SATURATION_FACTORS = (0.5, 1.0)


def boucwen_shapes(v: np.ndarray, beta: np.ndarray, gamma: np.ndarray) -> np.ndarray:
    """Bouc-Wen ``-z`` (A = 1, n = 1) for each ``(beta, gamma)``: the block's ``y - u``.

    Along a monotone input step ``dz/dh = s - (beta + s gamma sgn z) z`` is
    linear in ``z`` and is integrated exactly (two halves per sample so that a
    crossing of ``z = 0`` is followed).
    """
    z = np.zeros(beta.size)
    out = np.empty((v.size, beta.size))
    prev = v[0]
    for k, uk in enumerate(v):
        du = uk - prev
        prev = uk
        if du != 0.0:
            s, h = np.sign(du), abs(du) / 2
            for _ in range(2):
                b = beta + s * gamma * np.sign(z)
                safe = np.where(np.abs(b) > 1e-12, b, 1.0)
                zinf = s / safe
                z = np.where(np.abs(b) > 1e-12, zinf + (z - zinf) * np.exp(-safe * h), z + s * h)
        out[k] = -z
    return out


def _grid(dt, span):
    # saturation 1/(beta+gamma) from 0.3% to 40% of the travel, three loop shapes
    sat = np.geomspace(0.003, 0.4, 24) * span
    lam = np.repeat(1.0 / sat, 3)
    rho = np.tile([0.0, 0.25, 0.5], sat.size)
    beta, gamma = lam * (1 + rho) / 2, lam * (1 - rho) / 2
    return [{"beta": float(b), "gamma": float(g)} for b, g in zip(beta, gamma)]


def _shapes(v, dt, grid):
    return boucwen_shapes(v, np.array([g["beta"] for g in grid]), np.array([g["gamma"] for g in grid]))


def _estimate(e):
    k = float(e.coef[0]) / e.gain  # the data's z is k times the shape's (A = 1); for n = 1 that is A = k
    if abs(k) < 1e-9:
        return None
    sat = abs(k) / (e.grid["beta"] + e.grid["gamma"])
    return ({"A": k, "beta": e.grid["beta"], "gamma": e.grid["gamma"] * float(np.sign(k))},
            {"saturation": float(sat)})


def _build(params, settings, max_step):
    # keep RK4 stable along a sample's input step: (beta + gamma) * step / substeps small
    lam = abs(params["beta"]) + abs(params["gamma"])
    substeps = int(np.clip(np.ceil(lam * max_step / 0.5), 2, 8))
    return BoucWen(**clip_to_bounds(BoucWen, params), substeps=substeps)


#: ``|c| ds`` above which a substep is the exponential step rather than RK4 (RK4 is accurate to
#: 2e-4 below it, and the substeps chosen for a fit keep the training data below it).
LARGE_DECAY = 0.5

#: Smoothing of |x| for an input of unit scale (``BoucWen.eps=None``).
EPS = 1e-6


class BoucWen(AbstractBlock):
    """Bouc-Wen hysteresis ``y = u - z`` with

    ``dz = A du - beta |du| |z|^(n-1) z - gamma du |z|^n``.

    ``z`` is the motion lost to friction: with ``A > 0`` it grows while the input
    rises, so the rising branch lies below the falling one, as a tendon-driven
    catheter's tip angle lags its tendon (``A < 0`` turns the loop the other way).
    The output keeps moving with the input (and the block stays invertible) while
    ``dz/du < 1``; for ``n = 1`` that is ``2 A beta / (beta + gamma) < 1``
    (``A = 1, beta = gamma`` is the limit: a flat zone after each reversal).

    The law is rate independent, so each step integrates ``dz/du`` along the
    straight input segment from ``u_{k-1}`` to ``u_k`` (``substeps`` RK4 steps in
    the path parameter; a jump far larger than the data's, where RK4 would blow up, takes
    exponential steps instead, exact for ``n = 1``). The loop saturates at ``|z| = (A / (beta + gamma))^(1/n)``
    (input units). The absolute values are smoothed (``sqrt(x^2 + eps^2)``; ``eps``
    None is 1e-6 of the input's order of magnitude, set when the block is fitted, 1e-6
    until then) so that gradients exist everywhere.

    The state is ``(z_{k-1}, u_{k-1})``. ``n`` is held fixed when identifying
    unless asked for: with ``n`` free the problem is poorly conditioned.
    """

    name = "boucwen"
    identity = {"A": 0.0}  # z stays 0: y = u
    parameters = (
        Parameter("A", 0.5, -100.0, 100.0, "-", "initial slope of z after a reversal"),
        Parameter("beta", 1.0, 0.0, 1e3, "1/unit^n", "loop shape", scaling=(-1, 0)),  # n = 1
        Parameter("gamma", 0.5, -1e3, 1e3, "1/unit^n", "loop shape", scaling=(-1, 0)),
        Parameter("n", 1.0, 1.0, 10.0, "-", "sharpness of the transition", fit=False),
    )
    effect = "hysteresis"
    closes_minor_loops = False  # minor loops drift (the Bouc-Wen law's known ratchet)
    rank = 3
    selection_order = 30
    starts = 3  # prone to local minima: multi-start by default
    takes_loop_width = True
    signature = Signature(
        family="reversal", terms=("sgn(dv)", "sgn(dv)*exp(-d/w)"), scale="free", signal="hysteresis",
        grid=_grid, shapes=_shapes, estimate=_estimate, build=_build,
        describe=lambda p, s: f"loop half-width {s['saturation']:.3g} (input units)",
    )

    def __init__(self, A=None, beta=None, gamma=None, n=None, substeps: int = 2, eps: float | None = None):
        self._init_parameters({"A": A, "beta": beta, "gamma": gamma, "n": n})
        self.substeps = int(substeps)
        if eps is not None and not eps > 0:
            raise ValueError(f"BoucWen eps must be > 0 (or None). Got {eps} instead.")
        self.eps = None if eps is None else float(eps)

    def for_scale(self, s_in):
        return self if self.eps is not None else self.with_settings(eps=EPS * s_in)

    @property
    def state_names(self):
        return ("z", "u_prev")

    def _rate(self, z, h, p):
        A, beta, gamma, n = p[0], p[1], p[2], p[3]
        eps = EPS if self.eps is None else self.eps
        zz = z * z + eps * eps
        return A * h - beta * smooth_abs(h, eps) * z * zz ** ((n - 1) / 2) - gamma * h * zz ** (n / 2)

    def _decay(self, z, h, p):
        """``c`` of the rate written ``A h - c z`` (negative while ``z`` runs back towards 0 with
        ``gamma > beta``)."""
        beta, gamma, n = p[1], p[2], p[3]
        eps = EPS if self.eps is None else self.eps
        zz = z * z + eps * eps
        return zz ** ((n - 1) / 2) * (beta * smooth_abs(h, eps) + gamma * h * z / ca.sqrt(zz))

    def _advance(self, z, h, p):
        """``substeps`` steps along the input segment ``h``: RK4 while ``c ds`` (the decay of ``z``
        over the step) is small, as on the data a block is fitted on; beyond :data:`LARGE_DECAY` (an
        input jump far larger than the fit saw, where RK4 blows up) the exponential step with ``c``
        held, exact for ``n = 1`` between crossings of ``z = 0``."""
        ds = 1.0 / self.substeps
        drive = p[0] * h * ds  # the A h part of the rate, over a substep

        def exponential(z0, c, share=1.0):  # z after a share of the substep with the decay c held there
            # c < 0 (gamma > beta, moving back towards z = 0) held over a whole substep would grow z
            # past the crossing exponentially: there it is a plain step of the drive; the floor also
            # keeps 0/0 out of the branch not taken and out of its gradient
            c = ca.fmax(c, 1e-3) * share
            return z0 + (share * drive - c * z0) * (-ca.expm1(-c) / c)

        for _ in range(self.substeps):
            c = self._decay(z, h, p) * ds
            # held at its value half-way, for n != 1 and for a crossing of z = 0 within the substep
            c_mid = self._decay(exponential(z, c, 0.5), h, p) * ds
            large = ca.fmax(ca.fabs(c), ca.fabs(c_mid)) > LARGE_DECAY
            z = ca.if_else(large, exponential(z, c_mid),
                           rk_step(lambda s, zs: self._rate(zs, h, p), 0.0, z, ds))
        return z

    continuous_states = ("z",)

    def derivative(self, xc, u, udot, p):
        zdot = self._rate(xc[0], udot, p)
        return zdot, u - xc[0], udot - zdot

    def step(self, x, u, p, dt):
        z = self._advance(x[0], u - x[1], p)
        return ca.vertcat(z, u), u - z

    def steady_state(self, u0, p):
        return ca.vertcat(0, u0)

    def inverse_guess(self, x, y, p):
        return y + x[0]

    def initial_grid(self, data, values, free):
        if not (free["A"] and free["beta"] and free["gamma"]):
            return []
        n = values["n"]
        base = max(abs(data.loop_width) * data.loop_share / 2, 1e-3 * data.input_scale)
        out = []
        for a, f in itertools.product(BOUCWEN_A, SATURATION_FACTORS):
            zs = (base * f) ** n
            if data.loop_width >= 0:  # output lags: rising branch below
                out.append({"A": a, "beta": a / (2 * zs), "gamma": a / (2 * zs)})
            else:
                out.append({"A": -a, "beta": a / zs, "gamma": 0.0})
        return out

    def describe(self, dt):
        sat = abs(self.A) / max(abs(self.beta + self.gamma), 1e-12)
        return f"loop half-width {sat:.3g} (A {self.A:.3g})"
