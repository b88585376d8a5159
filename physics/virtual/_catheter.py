"""A virtual single-tendon catheter: known physics plus sensor noise, as 'measured' data."""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import casadi as ca
import numpy as np
from numpy.typing import NDArray

from physics import Arc, Backlash, BoucWen, Delay, Drift, Lag, LinearMap, Poly, PhysicsError, Series
from physics import effects as _vocabulary
from physics import resolve_effect
from physics.data import Settings

from ._signals import DecayingSinusoid, Signal, check_seed, sample_times

if TYPE_CHECKING:
    from physics.data import Trajectory

#: The catheter's block for each effect it can switch on (effect names: ``physics.EFFECTS``), from
#: its :class:`CatheterTruth` ``t``.
_BLOCKS = {
    "actuator_lag": lambda t, rate: Lag(time_constant_s=t.lag_time_constant_s),
    "time_delay": lambda t, rate: Delay(samples=int(round(t.delay_s * rate))),
    "backlash": lambda t, rate: Backlash(width=t.backlash_width_mm, smoothing=0.0),
    "hysteresis": lambda t, rate: BoucWen(A=t.boucwen_A, beta=t.boucwen_beta, gamma=t.boucwen_gamma,
                                          n=t.boucwen_n),
    "static_nonlinearity": lambda t, rate: Poly(c2=t.poly_c2, c3=t.poly_c3, center=3.0),
    "drift": lambda t, rate: Drift(rate=t.drift_deg_per_s),
}

#: The effects a virtual catheter can switch on, in signal order (the one vocabulary of
#: ``physics.EFFECTS``; a block's name or alias such as ``"lag"`` or ``"nonlinearity"`` is accepted too).
EFFECTS = tuple(e for e in _vocabulary() if e in _BLOCKS)

#: Effects of the default catheter: what the real one shows.
DEFAULT_EFFECTS = frozenset({"actuator_lag", "hysteresis", "backlash"})

#: Effects acting before the tendon displacement is measured (the actuator's).
_BEFORE_SENSOR = frozenset({"actuator_lag", "time_delay"})

#: What a trajectory's ``u`` is: the tendon displacement a sensor measures after
#: the actuator (as in the real catheter data), or the motor command before it.
INPUTS = ("measured", "command")

#: Lag whose actuator position peaks at 5.8 mm in the first cycle of the 0.5 Hz
#: 'end' baseline command (0 to 6 mm), as in the seed paper; see :func:`lag_for_peak`.
LAG_TIME_CONSTANT_S = 0.1265


def parse_effects(effects) -> frozenset[str]:
    """Effects from a comma-separated string or an iterable of names, checked against :data:`EFFECTS`.

    Each name is an effect or a block's name or alias (``"lag"`` is ``"actuator_lag"``,
    ``"nonlinearity"`` is ``"static_nonlinearity"``), resolved through the block registry.
    """
    if isinstance(effects, str):
        effects = [e for e in effects.replace(" ", "").split(",") if e]
    names, unknown = set(), []
    for e in effects:
        try:
            names.add(resolve_effect(e))
        except PhysicsError:
            unknown.append(str(e).strip().lower())
    unknown += sorted(names - set(EFFECTS))
    if unknown:
        raise ValueError(f"Unknown effect(s) {', '.join(map(repr, sorted(unknown)))}. "
                         f"Must be among: {', '.join(EFFECTS)}.")
    return frozenset(names)


def _run_seed(seed: int | None, name: str) -> np.random.Generator:
    """Independent, repeatable noise for each run name of a seeded catheter."""
    if seed is None:
        return np.random.default_rng()
    key = int.from_bytes(hashlib.sha256(name.encode()).digest()[:8], "little")
    return np.random.default_rng(np.random.SeedSequence([int(seed), key]))


@dataclass(frozen=True)
class CatheterTruth(Settings):
    """The physical parameters of a :class:`VirtualCatheter`'s chain (its truth), one frozen object.

    The defaults are the catheter of the seed paper's data. Each parameter acts only when its
    effect is on (``VirtualCatheter(effects=...)``); the linear map is always on.

    Parameters
    ----------
    lag_time_constant_s : float, default 0.1265
        Actuator time constant; see :data:`LAG_TIME_CONSTANT_S`.
    delay_s : float, default 0.04
        Transport delay, rounded to whole samples of the integration step.
    backlash_width_mm : float, default 0.2
        Total play of the tendon.
    boucwen_A, boucwen_beta, boucwen_gamma, boucwen_n : float, default 0.45, 1.5, 1, 1
        Bouc-Wen law (``physics.BoucWen``: output ``u - z``, a lagging loop);
        ``|z|`` saturates at ``(A / (beta + gamma))^(1/n)`` = 0.18 mm, and after a
        reversal the output moves at ``1 - A - (beta - gamma) 0.18`` = 0.46 of the
        input's speed (it stays invertible: ``2 A beta / (beta + gamma) < 1``).
        With the play and the gain the loop is about 6.4 deg wide at mid travel.
    poly_c2, poly_c3 : float, default 0, -0.015
        Static nonlinearity ``u + c2 (u-3)^2 + c3 (u-3)^3`` (mm): -0.4 mm at the ends.
    gain_deg_per_mm, offset_deg : float, default 11.4, 30.0
        Tip angle ``gain * v + offset``: 30 to about 95 deg over the 0-6 mm travel.
    drift_deg_per_s : float, default 1/60
        Output drift (1 deg per minute).

    Examples
    --------
    >>> CatheterTruth(lag_time_constant_s=0.2).replace(boucwen_A=0.3).boucwen_A
    0.3
    """

    lag_time_constant_s: float = LAG_TIME_CONSTANT_S
    delay_s: float = 0.04
    backlash_width_mm: float = 0.2
    boucwen_A: float = 0.45
    boucwen_beta: float = 1.5
    boucwen_gamma: float = 1.0
    boucwen_n: float = 1.0
    poly_c2: float = 0.0
    poly_c3: float = -0.015
    gain_deg_per_mm: float = 11.4
    offset_deg: float = 30.0
    drift_deg_per_s: float = 1.0 / 60.0

    def __post_init__(self) -> None:
        if not (np.isfinite(self.delay_s) and self.delay_s >= 0):
            raise ValueError(f"The 'delay_s' of CatheterTruth must be >= 0 s. Got {self.delay_s} instead.")


#: The seed paper's catheter (frozen, so every VirtualCatheter can share it).
DEFAULT_TRUTH = CatheterTruth()


@dataclass(frozen=True)
class TipArc(Settings):
    """Where a :class:`VirtualCatheter`'s tip is: its bending section as a constant-curvature arc
    (:class:`physics.Arc`) from the tip's angle, and the tracker's noise on the position.

    Parameters
    ----------
    length_mm : float, default 75.0
        Arc length of the bending section.
    base_x_mm, base_y_mm : float, default 160.0, 0.0
        The section's base in the tracker's frame.
    base_angle_deg : float, default 0.0
        The tip's angle when the section is straight (the catheter rests at 30 deg: bent).
    heading_deg : float, default 90.0
        The straight section's direction in the tracker's frame.
    noise_std_mm : float, default 0.1
        Standard deviation of the tracker's Gaussian noise on each coordinate.

    Examples
    --------
    >>> TipArc(length_mm=60.0).length_mm
    60.0
    """

    length_mm: float = 75.0
    base_x_mm: float = 160.0
    base_y_mm: float = 0.0
    base_angle_deg: float = 0.0
    heading_deg: float = 90.0
    noise_std_mm: float = 0.1

    def __post_init__(self) -> None:
        for name in ("length_mm", "base_x_mm", "base_y_mm", "base_angle_deg", "heading_deg", "noise_std_mm"):
            if not np.isfinite(getattr(self, name)):
                raise ValueError(f"The '{name}' of TipArc must be a finite number. Got {getattr(self, name)} instead.")
        if self.length_mm <= 0 or self.noise_std_mm < 0:
            raise ValueError(f"A TipArc needs length_mm > 0 and noise_std_mm >= 0. Got {self.length_mm} and "
                             f"{self.noise_std_mm} instead.")

    def block(self, outputs=("angle", "x", "y")) -> Arc:
        """The arc as the model's last block, outputting ``outputs``."""
        return Arc(length=self.length_mm, base_x=self.base_x_mm, base_y=self.base_y_mm,
                   base_angle=self.base_angle_deg, heading=self.heading_deg, outputs=outputs)


class VirtualCatheter:
    """Simulated single-tendon catheter whose output is noisy 'measured' tip angle.

    The chain, in signal order: command (mm) -> ``lag`` (actuator, first order)
    -> ``delay`` -> [measured tendon displacement] -> ``backlash`` (tendon
    slack, sharp play operator) -> ``hysteresis`` (Bouc-Wen, ``u - z``) -> ``nonlinearity`` (static cubic about
    3 mm) -> linear displacement-to-angle map (always on) -> ``drift`` -> plus
    Gaussian sensor noise. An effect that is off is absent from the chain. The
    chain is integrated at ``rate_hz * oversample`` (the command evaluated in
    continuous time) and sampled at ``rate_hz``.

    Settings are stored by ``__init__`` and checked when used (scikit-learn style).

    Parameters
    ----------
    effects : iterable of str or str, default {'actuator_lag', 'hysteresis', 'backlash'}
        Subset of :data:`EFFECTS` (a string is split on commas; block names such
        as ``lag``, ``delay`` and the alias ``nonlinearity`` are accepted).
    input : {'measured', 'command'}, default 'measured'
        What the trajectories' ``u`` is. ``'measured'``: the tendon displacement
        after the actuator's lag and delay, as the real catheter data logs it
        (its loop is then nearly rate independent, like the real one); lag and
        delay act before it and are seen in ``extra['command']``. ``'command'``:
        the motor command, so lag and delay are part of the ``u -> y`` path.
    truth : CatheterTruth, default CatheterTruth()
        The chain's physical parameters (lag, delay, play, Bouc-Wen, nonlinearity, gain and
        offset, drift): ``VirtualCatheter(truth=CatheterTruth(lag_time_constant_s=0.2))``.
    noise_std_deg : float, default 0.15
        Standard deviation of the Gaussian sensor noise.
    seed : int or None, default 0
        Seed of the noise; each run name gets its own stream from it (None: not repeatable).
    rate_hz : float, default 25.0
        Output sample rate.
    oversample : int, default 10
        Integration steps per output sample.
    tip : TipArc or None, default None
        Where the tip is: with a :class:`TipArc` each run also holds the tracked tip position,
        ``extra['Pos x']`` and ``extra['Pos y']`` (mm, with the tracker's noise), and
        ``extra['pos_x_true']``, ``extra['pos_y_true']``. The angle and its noise are those of the same
        catheter without it.

    Examples
    --------
    >>> from hybrid.virtual import VirtualCatheter, DecayingSinusoid
    >>> cath = VirtualCatheter(seed=0)
    >>> traj = cath.run(DecayingSinusoid(frequency_hz=0.5, baseline="end"))
    >>> traj.n, sorted(traj.extra)
    (351, ['command', 'q_actual', 'q_backlash', 'y_true', 'z'])
    >>> bool(abs(np.std(traj.y - traj.extra["y_true"]) - cath.noise_floor) < 0.03)
    True
    """

    def __init__(self, effects=DEFAULT_EFFECTS, *, input: str = "measured", truth: CatheterTruth = DEFAULT_TRUTH,
                 noise_std_deg: float = 0.15, seed: int | None = 0, rate_hz: float = 25.0, oversample: int = 10,
                 tip: TipArc | None = None):
        self.effects = effects
        self.input = input
        self.truth = truth
        self.noise_std_deg = noise_std_deg
        self.seed = seed
        self.rate_hz = rate_hz
        self.oversample = oversample
        self.tip = tip

    _SETTINGS = ("noise_std_deg", "seed", "rate_hz", "oversample")

    def get_params(self) -> dict[str, Any]:
        """All settings, JSON-ready and flat, as every simulated run's ``meta`` holds them: effects as a
        sorted list in signal order, then input, the truth's parameters by name, noise, seed, rates."""
        out: dict[str, Any] = {"effects": [e for e in EFFECTS if e in self.effect_set]}
        out["input"] = self.input
        out.update(self._truth().to_dict())
        out.update({k: getattr(self, k) for k in self._SETTINGS})
        if self.tip is not None:
            out["tip"] = self._tip().to_dict()
        return out

    # -- checks --------------------------------------------------------------------
    @property
    def effect_set(self) -> frozenset[str]:
        return parse_effects(self.effects)

    def _check(self) -> None:
        if self.input not in INPUTS:
            raise ValueError(f"The 'input' of VirtualCatheter must be one of {', '.join(INPUTS)}. "
                             f"Got {self.input!r} instead.")
        check_seed("VirtualCatheter", self.seed, allow_none=True)
        self._truth()
        if not (np.isfinite(self.rate_hz) and self.rate_hz > 0):
            raise ValueError(f"The 'rate_hz' of VirtualCatheter must be > 0. Got {self.rate_hz} instead.")
        if int(self.oversample) != self.oversample or self.oversample < 1:
            raise ValueError(f"The 'oversample' of VirtualCatheter must be a whole number >= 1. "
                             f"Got {self.oversample} instead.")
        if not (np.isfinite(self.noise_std_deg) and self.noise_std_deg >= 0):
            raise ValueError(f"The 'noise_std_deg' of VirtualCatheter must be >= 0. Got {self.noise_std_deg} instead.")

    def _tip(self) -> TipArc:
        if not isinstance(self.tip, TipArc):
            raise ValueError(f"The 'tip' of VirtualCatheter must be a TipArc or None, e.g. TipArc(length_mm=60). "
                             f"Got {self.tip!r} instead.")
        return self.tip

    def _truth(self) -> CatheterTruth:
        if not isinstance(self.truth, CatheterTruth):
            raise ValueError(f"The 'truth' of VirtualCatheter must be a CatheterTruth, e.g. "
                             f"CatheterTruth(lag_time_constant_s=0.2). Got {self.truth!r} instead.")
        return self.truth

    @property
    def noise_floor(self) -> float:
        """Standard deviation (deg) of the sensor noise: the best RMSE any model can reach."""
        return float(self.noise_std_deg)

    # -- the truth ---------------------------------------------------------------
    def truth_model(self, rate_hz: float | None = None, from_command: bool | None = None,
                    pose: bool = False) -> Series:
        """The noise-free ``u -> y`` chain as a ``physics.Series`` sampled at ``rate_hz``.

        ``rate_hz`` defaults to ``self.rate_hz``. ``from_command`` (default: whether
        ``input == 'command'``) includes the actuator's lag and delay. The delay
        becomes ``round(delay_s * rate_hz)`` samples; at 25 Hz the default 0.04 s
        is exactly one sample. ``pose=True`` (a catheter with a ``tip``) ends the chain with the tip's
        arc: its outputs are the angle and the position, ``(angle, x, y)``.
        """
        self._check()
        if pose:
            return Series(*self.truth_model(rate_hz, from_command).blocks, self._tip().block(), dt=1.0 / float(
                self.rate_hz if rate_hz is None else rate_hz))
        rate = float(self.rate_hz if rate_hz is None else rate_hz)
        from_command = self.input == "command" if from_command is None else from_command
        effects = self.effect_set if from_command else self.effect_set - _BEFORE_SENSOR
        truth = self._truth()
        blocks = [_BLOCKS[e](truth, rate) for e in EFFECTS if e in effects]
        blocks.append(LinearMap(gain=truth.gain_deg_per_mm, offset=truth.offset_deg))
        blocks.sort(key=lambda b: b.rank)  # signal order: the output map before the drift
        return Series(*blocks, dt=1.0 / rate)

    # -- simulation --------------------------------------------------------------
    def simulate_fine(self, signal: Signal) -> tuple[NDArray[np.float64], dict[str, NDArray[np.float64]]]:
        """Noise-free signals at the integration rate: ``(time, signals)``.

        ``signals`` maps ``'command'`` and each block's name (``'lag'``, ...,
        ``'linear'``, ``'drift'``) to the signal after it, in signal order, and
        ``'z'`` to the Bouc-Wen state after each sample when hysteresis is on.
        """
        self._check()
        fine_rate = self.rate_hz * int(self.oversample)
        model = self.truth_model(fine_rate, from_command=True)
        n_out = sample_times(signal.duration, self.rate_hz).size
        time = np.arange((n_out - 1) * int(self.oversample) + 1) / fine_rate
        u = signal(time)
        signals, z = _probe(model, u)
        out = {"command": u, **signals}
        if z is not None:
            out["z"] = z
        return time, out

    def run(self, signal: Signal, name: str | None = None) -> Trajectory:
        """Simulate ``signal`` and return the noisy measurement as a :class:`hybrid.data.Trajectory`.

        ``u`` is the measured (or, with ``input='command'``, the commanded)
        tendon displacement (mm) and ``y`` the measured tip angle (deg). ``extra``
        holds at the output rate: ``command`` (motor command), ``q_actual``
        (actuator position after lag and delay), ``q_backlash`` (after the play,
        when on), ``z`` (Bouc-Wen state, when on) and ``y_true`` (noise-free angle).
        The noise comes from ``seed`` and ``name`` (default ``signal.name``):
        runs with different names get independent noise, the same name the same.
        """
        from physics.data import Trajectory

        name = signal.name if name is None else str(name)
        _, sig = self.simulate_fine(signal)
        step = int(self.oversample)
        down = {k: v[::step] for k, v in sig.items()}
        time = np.arange(down["command"].size) / float(self.rate_hz)
        q_actual = down.get("delay", down.get("lag", down["command"]))
        extra = {"command": down["command"], "q_actual": q_actual}
        if "backlash" in down:
            extra["q_backlash"] = down["backlash"]
        if "z" in down:
            extra["z"] = down["z"]
        y_true = down["drift" if "drift" in down else "linear"]
        extra["y_true"] = y_true
        noise = _run_seed(self.seed, name).normal(0.0, self.noise_std_deg, y_true.size)
        if self.tip is not None:
            tip = self._tip()
            arc = tip.block()
            pos = [np.asarray(v, dtype=float).ravel() for v in arc.position(ca.DM(y_true), ca.DM(arc.param_values()))]
            tracker = _run_seed(self.seed, name + "/tip").normal(0.0, tip.noise_std_mm, (2, y_true.size))
            extra.update({"Pos x": pos[0] + tracker[0], "Pos y": pos[1] + tracker[1],
                          "pos_x_true": pos[0], "pos_y_true": pos[1]})
        meta = {"source": "virtual", "name": name, **self.get_params(), **signal.describe(),
                "truth_params": self.truth_model().param_dict()}
        u = down["command"] if self.input == "command" else q_actual
        return Trajectory(time, u, y_true + noise, input_name="Tendon Disp.",
                          output_name="Angle x", input_unit="mm", output_unit="deg",
                          source=name, extra=extra, meta=meta)

    def __repr__(self) -> str:
        return f"VirtualCatheter(effects={sorted(self.effect_set)}, seed={self.seed})"


def _probe(model: Series, u: NDArray[np.float64]):
    """Output after each block of ``model`` along ``u`` (from the blocks' own CasADi
    steps) and the Bouc-Wen state ``z`` after each sample (None without Bouc-Wen)."""
    x = ca.SX.sym("x", model.n_x)
    uk = ca.SX.sym("u")
    p = ca.SX.sym("p", model.n_p)
    signal, ix, ip = uk, 0, 0
    x_next, outputs = [], []
    for block in model.blocks:
        xb, pb = x[ix:ix + block.n_x], p[ip:ip + block.n_p]
        xn, signal = block.step(xb, signal, pb, model.dt)
        x_next.append(xn)
        outputs.append(signal)
        ix, ip = ix + block.n_x, ip + block.n_p
    step = ca.Function("probe", [x, uk, p], [ca.vertcat(*x_next), ca.vertcat(*outputs)],
                       ["x", "u", "p"], ["x_next", "signals"])
    n = u.size
    xs, ys = step.mapaccum("probe_acc", n)(model.steady_state(u[0]), u[None, :],
                                           ca.repmat(ca.DM(model.params), 1, n))
    ys = np.asarray(ys, dtype=float).reshape(len(model.blocks), n)
    signals = {block.name: ys[i] for i, block in enumerate(model.blocks)}
    names = model.state_names
    z = None
    if "boucwen.z" in names:
        z = np.asarray(xs, dtype=float).reshape(model.n_x, n)[names.index("boucwen.z")]
    return signals, z


def lag_for_peak(peak_mm: float = 5.8, frequency_hz: float = 0.5, baseline: str = "end",
                 rate_hz: float = 250.0) -> float:
    """Lag time constant (s) whose actuator position peaks at ``peak_mm`` in the command's first cycle.

    The seed paper's 0.5 Hz 'end' baseline command rises from 0 to 6 mm; the
    actuator reached about 5.8 mm. Solved by bisection on a simulation at ``rate_hz``.
    """
    signal = DecayingSinusoid(frequency_hz=frequency_hz, baseline=baseline)
    time = sample_times(1.0 / frequency_hz, rate_hz)
    u = signal(time)
    target = float(peak_mm)
    if not u[0] < target < u.max():
        raise ValueError(f"peak_mm must lie between the command's start {u[0]:.3g} mm and its "
                         f"first-cycle peak {u.max():.3g} mm. Got {peak_mm} instead.")

    def first_peak(tc: float) -> float:
        return float(Series(Lag(time_constant_s=tc), dt=1.0 / rate_hz).simulate(u).max())

    lo, hi = 1e-3, 5.0
    for _ in range(60):
        mid = math.sqrt(lo * hi)
        lo, hi = (mid, hi) if first_peak(mid) > target else (lo, mid)
    return 0.5 * (lo + hi)
