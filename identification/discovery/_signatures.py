"""Effect signatures: name what a model is missing from the shape of its residual.

The residual ``measured - simulated`` of a fitted model is regressed, with
pysindy's sequentially thresholded least squares (STLSQ), on a library of terms
each labelled by the family of effects it signals:

======================  ==============================  ==================================
family                  library terms                   effects
======================  ==============================  ==================================
``rate``                ``dv/dt``, ``d2v/dt2``          ``actuator_lag``, ``time_delay``
``reversal``            ``sgn(dv)``, ``sgn(dv) e^-d/w`` ``backlash``, ``hysteresis``
``static``              ``x^2``, ``x^3``                ``static_nonlinearity``
``drift``               ``t``                           ``drift``
======================  ==============================  ==================================

``v`` is the signal where the missing block would enter (the command after the
model's own lag and delay), ``d`` the distance ``v`` has travelled since its
last reversal, ``x`` the centred and scaled input of the static map and ``t``
the time since the trajectory's start. The model's own refit directions (an
offset and its gain) are projected out first. STLSQ keeps the families whose
terms are above a noise-based threshold; then, within each kept family, exact
block shapes tell the members apart and give first parameter estimates:

* lag or delay: the output of a first-order lag ``LF_T(v) - v`` against a shift
  ``v(t - d) - v(t)`` over grids of ``T`` and ``d``. To first order in
  frequency both are ``-T dv/dt``; the lag also loses amplitude, the delay not.
* backlash or hysteresis: the play operator ``P_w(v) - v`` (a linear ramp over
  the width right after a reversal, then flat) against Bouc-Wen's ``-z``
  (a smooth saturating exponential), over grids of widths and loop shapes.

Each candidate's score is the share of the residual's variance that its best
shape explains beyond the other kept families. Rate-dependent and
rate-independent effects are told apart because several trajectories at
different frequencies are stacked into one regression.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np
import pysindy as ps

from ._noise import noise_floor
from ._shapes import backlash_shapes, boucwen_shapes, delay_shapes, direction, lag_shapes, since_reversal

#: The vocabulary of effects, in signal order.
EFFECTS = ("actuator_lag", "time_delay", "backlash", "hysteresis", "static_nonlinearity", "drift")

#: Block spec name that models each effect.
BLOCK_OF = {"actuator_lag": "lag", "time_delay": "delay", "backlash": "backlash",
            "hysteresis": "boucwen", "static_nonlinearity": "poly", "drift": "drift"}

#: Families of effects that share library terms.
FAMILIES = {"rate": ("actuator_lag", "time_delay"), "reversal": ("backlash", "hysteresis"),
            "static": ("static_nonlinearity",), "drift": ("drift",)}

FAMILY_OF = {e: fam for fam, members in FAMILIES.items() for e in members}


@dataclass(frozen=True)
class ResidualTrace:
    """One trajectory's residual and the model's internal signals along it.

    Parameters
    ----------
    time : array, shape (n,)
        Seconds since the trajectory's start.
    residual : array, shape (n,)
        Measured minus simulated output (output units).
    drive : array, shape (n,)
        Input of a new lag, delay or backlash block: the command after the
        model's own lag and delay (input units).
    hysteresis_input, static_input : array, shape (n,), optional
        Input of a new hysteresis block (after the model's backlash) and of a
        static map (after its hysteresis). Default: ``drive``.
    gain : float
        Output units per input unit at the static map's output (the model's
        linear gain); converts residual coefficients into block parameters.
    sensitivities : array, shape (n, k), optional
        Derivatives of the model's output with respect to its ``k`` fitted
        parameters (the same parameters, in the same order, on every trace).
        Their span is projected out of the residual: a new block is judged
        together with the re-fit of the blocks the model already has.
    """

    time: np.ndarray
    residual: np.ndarray
    drive: np.ndarray
    hysteresis_input: np.ndarray | None = None
    static_input: np.ndarray | None = None
    gain: float = 1.0
    sensitivities: np.ndarray | None = None

    def __post_init__(self) -> None:
        n = np.asarray(self.time).size
        for name in ("time", "residual", "drive", "hysteresis_input", "static_input"):
            value = getattr(self, name)
            if value is None:
                continue
            arr = np.asarray(value, dtype=float)
            if arr.ndim != 1 or arr.size != n or not np.all(np.isfinite(arr)):
                raise ValueError(f"ResidualTrace.{name} must be a finite 1-D array of {n} samples; "
                                 f"got shape {arr.shape}.")
            object.__setattr__(self, name, arr)
        if self.sensitivities is not None:
            sens = np.asarray(self.sensitivities, dtype=float).reshape(n, -1)
            if not np.all(np.isfinite(sens)):
                raise ValueError("ResidualTrace.sensitivities must be finite.")
            object.__setattr__(self, "sensitivities", sens)
        if n < 8:
            raise ValueError(f"A residual trace needs at least 8 samples; got {n}.")
        if not (np.isfinite(self.gain) and self.gain != 0):
            raise ValueError(f"ResidualTrace.gain must be finite and non-zero. Got {self.gain} instead.")

    @property
    def dt(self) -> float:
        return float(np.median(np.diff(self.time)))

    @property
    def hyst(self) -> np.ndarray:
        return self.drive if self.hysteresis_input is None else self.hysteresis_input

    @property
    def static(self) -> np.ndarray:
        return self.hyst if self.static_input is None else self.static_input


@dataclass(frozen=True)
class Candidate:
    """A missing effect named by its signature.

    Attributes
    ----------
    effect : str
        One of :data:`EFFECTS`.
    score : float
        Share of the residual's variance its best shape explains beyond the
        other kept families (0 to 1).
    explained_rms : float
        The same in output units: RMS of the part of the residual it explains.
    block : str
        Spec name of the block that models it (``"lag"``, ``"boucwen"``, ...).
    parameters : dict of str to float
        First estimates of the block's parameters, by the block's own names.
    settings : dict
        Structural settings of the block (``samples`` of a delay, ``center`` of
        a polynomial).
    terms : dict of str to float
        The family's library terms that STLSQ kept, with their coefficients
        (output units per unit of the term).
    """

    effect: str
    score: float
    explained_rms: float
    block: str
    parameters: dict[str, float] = field(default_factory=dict)
    settings: dict = field(default_factory=dict)
    terms: dict[str, float] = field(default_factory=dict)

    @property
    def family(self) -> str:
        return FAMILY_OF[self.effect]

    def describe(self) -> str:
        """``'actuator_lag, time constant 0.12 s'``."""
        p, s = self.parameters, self.settings
        if self.effect == "actuator_lag":
            return f"{self.effect}, time constant {p['time_constant_s']:.3g} s"
        if self.effect == "time_delay":
            return f"{self.effect}, {s['samples']} samples ({s['delay_s']:.3g} s)"
        if self.effect == "backlash":
            return f"{self.effect}, width {p['width']:.3g}"
        if self.effect == "hysteresis":
            return f"{self.effect}, loop half-width {s['saturation']:.3g} (input units)"
        if self.effect == "static_nonlinearity":
            return f"{self.effect}, c2 {p['c2']:.3g}, c3 {p['c3']:.3g} about {s['center']:.3g}"
        return f"{self.effect}, {p['rate']:.3g} per s"

    def to_dict(self) -> dict:
        return {"effect": self.effect, "score": self.score, "explained_rms": self.explained_rms,
                "block": self.block, "parameters": dict(self.parameters),
                "settings": dict(self.settings), "terms": dict(self.terms)}


# -- the library ------------------------------------------------------------------------
def _derivative(v: np.ndarray, dt: float, order: int) -> np.ndarray:
    t = np.arange(v.size) * dt
    return np.asarray(ps.FiniteDifference(order=2, d=order)(v.reshape(-1, 1), t)).ravel()


def library(trace: ResidualTrace, span: float, center: float, half: float) -> tuple[np.ndarray, list[str], list[str]]:
    """Columns of the labelled library for one trace: ``(theta, names, families)``."""
    v, dt = trace.drive, trace.dt
    s, d = direction(v), since_reversal(v)
    x = (trace.static - center) / half
    cols = [_derivative(v, dt, 1), _derivative(v, dt, 2), s]
    names = ["dv/dt", "d2v/dt2", "sgn(dv)"]
    fams = ["rate", "rate", "reversal"]
    for frac in (0.02, 0.06, 0.2):
        cols.append(s * np.exp(-d / (frac * span)))
        names.append(f"sgn(dv)*exp(-d/{frac * span:.3g})")
        fams.append("reversal")
    cols += [x**2, x**3, trace.time]
    names += ["x^2", "x^3", "t"]
    fams += ["static", "static", "drift"]
    return np.column_stack(cols), names, fams


def _project_out(A: np.ndarray, basis: np.ndarray | None) -> np.ndarray:
    if basis is None or basis.shape[1] == 0:
        return A
    q, _ = np.linalg.qr(basis)
    return A - q @ (q.T @ A)


@dataclass
class _Stack:
    r: np.ndarray
    theta: np.ndarray
    nuisance: np.ndarray
    names: list[str]
    fams: list[str]
    traces: list[ResidualTrace]
    span: float
    center: float
    half: float
    gain: float


def _stack(traces: list[ResidualTrace]) -> _Stack:
    allv = np.concatenate([t.drive for t in traces])
    alls = np.concatenate([t.static for t in traces])
    span = float(np.ptp(allv)) or 1.0
    lo, hi = float(alls.min()), float(alls.max())
    center, half = (lo + hi) / 2, max((hi - lo) / 2, 1e-9)
    blocks = [library(t, span, center, half) for t in traces]
    theta = np.vstack([b[0] for b in blocks])
    nuisance = np.column_stack([np.ones(alls.size), alls - center])
    if all(t.sensitivities is not None for t in traces):
        sens = np.vstack([t.sensitivities for t in traces])
        scale = np.sqrt(np.mean(sens**2, axis=0))
        keep = scale > 1e-12
        if keep.any():
            nuisance = np.column_stack([nuisance, sens[:, keep] / scale[keep]])
    gain = float(np.median([t.gain for t in traces]))
    return _Stack(np.concatenate([t.residual for t in traces]), theta, nuisance,
                  blocks[0][1], blocks[0][2], list(traces), span, center, half, gain)


# -- diagnosis --------------------------------------------------------------------------
def diagnose(traces, noise_std: float | None = None, exclude=(), threshold: float = 0.25,
             min_score: float = 0.02, rounds: int = 2) -> list[Candidate]:
    """Name the effects the residual shows, best first.

    Parameters
    ----------
    traces : ResidualTrace or sequence of ResidualTrace
        The residual along each trajectory (several frequencies tell
        rate-dependent effects from rate-independent ones).
    noise_std : float, optional
        Measurement noise (output units); default :func:`noise_floor` of the residuals.
    exclude : iterable of str
        Effects not to name (e.g. those the model already has).
    threshold : float
        STLSQ keeps a term whose contribution has an RMS above
        ``threshold * noise_std``; a candidate's shape must explain as much.
    min_score : float
        Smallest share of the residual variance a candidate must explain
        beyond the other families.
    rounds : int
        Rounds of back-fitting the families' shapes against one another.

    Returns
    -------
    list of Candidate
        Sorted by score, highest first; empty when the residual shows no effect.

    Examples
    --------
    >>> import numpy as np
    >>> t = np.arange(0, 40, 0.04)
    >>> v = 3 - 3 * np.cos(2 * np.pi * 0.25 * t)
    >>> r = 0.05 * t + np.random.default_rng(0).normal(0, 0.1, t.size)  # a drifting output
    >>> [c.effect for c in diagnose(ResidualTrace(t, r, v, gain=10.0), noise_std=0.1)]
    ['drift']
    """
    traces = [traces] if isinstance(traces, ResidualTrace) else list(traces)
    if not traces or not all(isinstance(t, ResidualTrace) for t in traces):
        raise ValueError("diagnose needs one or more ResidualTrace objects.")
    unknown = sorted(set(exclude) - set(EFFECTS))
    if unknown:
        raise ValueError(f"Unknown effect(s) {unknown} in exclude. Must be among: {', '.join(EFFECTS)}.")
    if noise_std is None:
        noise_std = noise_floor([t.residual for t in traces])
    noise_std = max(float(noise_std), 1e-12)
    st = _stack(traces)
    shapes = _Shapes(st)
    theta, names, fams = _with_shapes(st, shapes, exclude)
    kept, coef = _sparse_terms(st, theta, fams, noise_std, threshold, exclude)
    families = [f for f in FAMILIES if any(fams[i] == f for i in kept)]
    if not families:
        return []
    members = {f: [e for e in FAMILIES[f] if e not in exclude] for f in families}
    chosen = {f: shapes.best(members[f], st.nuisance)[0] for f in families}
    for _ in range(rounds):
        for f in families:
            chosen[f] = shapes.best(members[f], _covariates(st, chosen, f))[0]
    r = st.r
    r_free = _project_out(r[:, None], st.nuisance).ravel()
    sst = float(r_free @ r_free)
    out = []
    for f in families:
        terms = {names[i]: float(coef[i]) for i in kept if fams[i] == f}
        cov = _covariates(st, chosen, f)
        for effect in members[f]:
            fit = shapes.fit(effect, cov)
            explained = float(np.sqrt(max(fit.drop, 0.0) / r.size))
            score = fit.drop / sst if sst > 0 else 0.0
            if score >= min_score and explained >= threshold * noise_std:
                cand = _candidate(effect, fit, st, shapes)
                if cand is not None:
                    out.append(Candidate(effect, float(score), explained, cand.block, cand.parameters,
                                         cand.settings, terms))
    return sorted(out, key=lambda c: -c.score)


def _with_shapes(st: _Stack, shapes: "_Shapes", exclude) -> tuple[np.ndarray, list[str], list[str]]:
    """The library plus, for each effect with a parametrised shape, its best shape alone.

    Generic terms such as ``sgn(dv) e^-d/w`` miss a second reversal effect on
    top of one the model has (backlash on Bouc-Wen); the exact shapes do not.
    """
    cols, names, fams = [], [], []
    for effect in ("actuator_lag", "time_delay", "backlash", "hysteresis"):
        if effect in exclude:
            continue
        fit = shapes.fit(effect, st.nuisance)
        if fit.drop <= 0:
            continue
        grid = shapes.shapes(effect)[1][fit.index]
        cols.append(fit.column)
        names.append(f"{BLOCK_OF[effect]}({', '.join(f'{k}={v:.3g}' for k, v in grid.items())})")
        fams.append(FAMILY_OF[effect])
    if not cols:
        return st.theta, list(st.names), list(st.fams)
    return np.column_stack([st.theta] + cols), st.names + names, st.fams + fams


def _sparse_terms(st: _Stack, theta: np.ndarray, fams: list[str], noise_std: float, threshold: float,
                  exclude) -> tuple[list[int], np.ndarray]:
    """STLSQ on the labelled library with the nuisance projected out: kept columns and coefficients."""
    r = _project_out(st.r[:, None], st.nuisance).ravel()
    theta = _project_out(theta, st.nuisance)
    rms = np.sqrt(np.mean(theta**2, axis=0))
    live = rms > 1e-12 * (1 + rms.max())
    allowed = np.array([any(e not in exclude for e in FAMILIES[f]) for f in fams])
    use = np.flatnonzero(live & allowed)
    coef = np.zeros(theta.shape[1])
    if use.size == 0 or not np.any(r):
        return [], coef
    # unit-RMS columns: a coefficient is the RMS (output units) of its term's contribution
    opt = ps.STLSQ(threshold=threshold * noise_std, alpha=1e-4 * r.size, unbias=True)
    with warnings.catch_warnings():  # "eliminated all coefficients" is an answer here, not a fault
        warnings.filterwarnings("ignore", message="Sparsity parameter is too big", category=UserWarning)
        opt.fit(theta[:, use] / rms[use], r)
    coef[use] = np.asarray(opt.coef_).ravel() / rms[use]
    return [int(i) for i in use if coef[i] != 0.0], coef


@dataclass
class _Fit:
    effect: str
    index: int
    drop: float  # SSE removed from the residual
    coef: np.ndarray
    column: np.ndarray  # the fitted contribution (output units), full length


def _covariates(st: _Stack, chosen: dict[str, _Fit], family: str) -> np.ndarray:
    cols = [fit.column for f, fit in chosen.items() if f != family]
    return np.column_stack([st.nuisance] + [c[:, None] for c in cols])


class _Shapes:
    """Exact shapes of each effect over its parameter grid, computed once per diagnosis.

    Lag, delay and backlash shapes are scaled by the model's gain and enter with
    a fixed coefficient of one, so their parameter is identified by the size of
    the residual as well as its shape (a free coefficient would let any small
    time constant mimic a delay). What the re-fit of the model's own blocks
    can absorb (a lag's share of a delay) is in the projected-out
    sensitivities. Bouc-Wen's scale is its ``A``: free. The static map and the drift are
    linear in their parameters: free.
    """

    FIXED = ("actuator_lag", "time_delay", "backlash")

    def __init__(self, st: _Stack):
        self.st = st
        self._cache: dict[str, tuple[np.ndarray, list[dict]]] = {}

    def shapes(self, effect: str) -> tuple[np.ndarray, list[dict]]:
        if effect not in self._cache:
            self._cache[effect] = _shapes(effect, self.st)
        return self._cache[effect]

    def fit(self, effect: str, cov: np.ndarray) -> _Fit:
        st = self.st
        q, _ = np.linalg.qr(cov)
        r = st.r - q @ (q.T @ st.r)
        base = float(r @ r)
        if effect in ("static_nonlinearity", "drift"):
            cols = [st.names.index("x^2"), st.names.index("x^3")] if effect != "drift" else [st.names.index("t")]
            raw = st.theta[:, cols]
            f = raw - q @ (q.T @ raw)
            c, *_ = np.linalg.lstsq(f, r, rcond=None)
            e = r - f @ c
            return _Fit(effect, 0, base - float(e @ e), c, raw @ c)
        raw, _ = self.shapes(effect)
        f = raw - q @ (q.T @ raw)
        if effect in self.FIXED:
            f = st.gain * f
            drop = 2 * (f.T @ r) - np.einsum("ij,ij->j", f, f)
            j = int(np.argmax(drop))
            return _Fit(effect, j, float(drop[j]), np.array([1.0]), st.gain * raw[:, j])
        ff = np.einsum("ij,ij->j", f, f)
        ok = ff > 1e-18
        fr = f.T @ r
        drop = np.where(ok, fr**2 / np.where(ok, ff, 1.0), 0.0)
        j = int(np.argmax(drop))
        c = fr[j] / ff[j] if ok[j] else 0.0
        return _Fit(effect, j, float(drop[j]), np.array([c]), c * raw[:, j])

    def best(self, members: list[str], cov: np.ndarray) -> tuple[_Fit, list[_Fit]]:
        fits = [self.fit(e, cov) for e in members]
        return max(fits, key=lambda fit: fit.drop), fits


def _shapes(effect: str, st: _Stack) -> tuple[np.ndarray, list[dict]]:
    """Stacked exact shapes of one effect over its parameter grid, and the grid."""
    dt = st.traces[0].dt
    if effect == "actuator_lag":
        grid = np.geomspace(0.25 * dt, 2.0, 48)
        return np.vstack([lag_shapes(t.drive, t.dt, grid) for t in st.traces]), \
            [{"time_constant_s": float(g)} for g in grid]
    if effect == "time_delay":
        grid = np.arange(1, int(round(0.6 / dt)) + 1) * dt  # the block delays by whole samples
        return np.vstack([delay_shapes(t.drive, t.dt, grid) for t in st.traces]), \
            [{"delay_s": float(g)} for g in grid]
    if effect == "backlash":
        grid = np.geomspace(0.003, 0.5, 48) * st.span
        return np.vstack([backlash_shapes(t.drive, grid) for t in st.traces]), \
            [{"width": float(g)} for g in grid]
    # hysteresis: saturation 1/(beta+gamma) from 0.3% to 40% of the travel, three loop shapes
    sat = np.geomspace(0.003, 0.4, 24) * st.span
    lam = np.repeat(1.0 / sat, 3)
    rho = np.tile([0.0, 0.25, 0.5], sat.size)
    beta, gamma = lam * (1 + rho) / 2, lam * (1 - rho) / 2
    return np.vstack([boucwen_shapes(t.hyst, beta, gamma) for t in st.traces]), \
        [{"beta": float(b), "gamma": float(g)} for b, g in zip(beta, gamma)]


def _candidate(effect: str, fit: _Fit, st: _Stack, shapes: _Shapes) -> Candidate | None:
    """First parameter estimates of the block for ``effect`` from its best shape."""
    g = st.gain
    if effect == "static_nonlinearity":
        c2, c3 = fit.coef[0] / (g * st.half**2), fit.coef[1] / (g * st.half**3)
        return Candidate(effect, 0.0, 0.0, "poly", {"c2": float(c2), "c3": float(c3)},
                         {"center": st.center})
    if effect == "drift":
        return Candidate(effect, 0.0, 0.0, "drift", {"rate": float(fit.coef[0])})
    params = dict(shapes.shapes(effect)[1][fit.index])
    if effect == "actuator_lag":
        return Candidate(effect, 0.0, 0.0, "lag", params)
    if effect == "time_delay":
        samples = max(1, int(round(params["delay_s"] / st.traces[0].dt)))
        return Candidate(effect, 0.0, 0.0, "delay", {}, {"samples": samples, "delay_s": params["delay_s"]})
    if effect == "backlash":
        return Candidate(effect, 0.0, 0.0, "backlash", params)
    k = float(fit.coef[0]) / g  # the data's z is k times the shape's (A = 1); for n = 1 that is A = k
    if abs(k) < 1e-9:
        return None
    sat = abs(k) / (params["beta"] + params["gamma"])
    return Candidate(effect, 0.0, 0.0, "boucwen",
                     {"A": k, "beta": params["beta"], "gamma": params["gamma"] * float(np.sign(k))},
                     {"saturation": float(sat)})

