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
``creep``               (its exact shape only)          ``creep``
======================  ==============================  ==================================

``v`` is the signal where the missing block would enter (the command after the
model's own lag and delay), ``d`` the distance ``v`` has travelled since its
last reversal, ``x`` the centred and scaled input of the static map and ``t``
the time since the trajectory's start. Which blocks, families and terms exist is
read from the blocks' own :class:`physics.Signature` (nothing here lists blocks
by name). The model's own refit directions (an
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

import inspect
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from physics import EFFECTS, Estimate, Signature, direction, effect_blocks, since_reversal

from ._noise import noise_floor
from ._shapes import along, free_drops
from ._timescale import not_in_time


def _signed() -> dict[str, type]:
    """Effect -> the first registered block (in signal order) that models it and has a signature."""
    out = {}
    for effect in EFFECTS:
        found = [cls for cls in effect_blocks(effect) if cls.signature is not None]
        if found:
            out[effect] = found[0]
    return out


def signature_of(effect: str) -> Signature:
    """The signature of the block discovery adds for ``effect``."""
    signed = _signed()
    if effect not in signed:
        raise ValueError(f"No registered block with a signature models {effect!r}; "
                         f"discovery can name: {', '.join(signed)}.")
    return signed[effect].signature


def _families() -> dict[str, tuple[str, ...]]:
    out: dict[str, list[str]] = {}
    for effect, cls in _signed().items():
        out.setdefault(cls.signature.family, []).append(effect)
    return {f: tuple(m) for f, m in out.items()}


class _Live(Mapping):
    """A read-only mapping computed from the block registry on each use."""

    def __init__(self, build: Callable[[], dict]):
        self._build = build

    def __getitem__(self, key):
        return self._build()[key]

    def __iter__(self):
        return iter(self._build())

    def __len__(self) -> int:
        return len(self._build())

    def __repr__(self) -> str:
        return repr(self._build())


#: Block spec name that discovery adds for each effect it can name.
BLOCK_OF = _Live(lambda: {e: cls.name for e, cls in _signed().items()})

#: Families of effects that share library terms, in signal order.
FAMILIES = _Live(_families)

FAMILY_OF = _Live(lambda: {e: fam for fam, members in _families().items() for e in members})


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
    alone : float
        Share of the residual's variance its best shape explains by itself
        (the other families not projected out). Two families of different
        kinds whose shapes look alike on the data (creep and hysteresis on
        slow sinusoids) each explain little beyond the other: ``alone`` tells
        that they tie, and discovery then fits both.
    """

    effect: str
    score: float
    explained_rms: float
    block: str
    parameters: dict[str, float] = field(default_factory=dict)
    settings: dict = field(default_factory=dict)
    terms: dict[str, float] = field(default_factory=dict)
    alone: float = 0.0

    @property
    def family(self) -> str:
        return signature_of(self.effect).family

    def describe(self) -> str:
        """``'actuator_lag, time constant 0.12 s'``."""
        return f"{self.effect}, {signature_of(self.effect).describe(self.parameters, self.settings)}"

    def to_dict(self) -> dict:
        return {"effect": self.effect, "score": self.score, "explained_rms": self.explained_rms,
                "block": self.block, "parameters": dict(self.parameters),
                "settings": dict(self.settings), "terms": dict(self.terms), "alone": self.alone}


# -- the library ------------------------------------------------------------------------
def _pysindy():
    """pysindy, imported on first use (the ``[discovery]`` extra)."""
    try:
        import pysindy
    except ModuleNotFoundError as exc:
        raise ModuleNotFoundError("Discovery's sparse regression needs pysindy: "
                                  "pip install 'hysteresis-hybrid[discovery]'.", name="pysindy") from exc
    return pysindy


def _derivative(v: np.ndarray, dt: float, order: int) -> np.ndarray:
    t = np.arange(v.size) * dt
    return np.asarray(_pysindy().FiniteDifference(order=2, d=order)(v.reshape(-1, 1), t)).ravel()


@dataclass(frozen=True)
class _Path:
    """What the generic library terms are built from, along one trace."""

    v: np.ndarray  # drive
    dt: float
    s: np.ndarray  # direction of motion of v
    d: np.ndarray  # distance travelled since the last reversal
    x: np.ndarray  # static map's input, centred and scaled to [-1, 1]
    t: np.ndarray
    span: float


#: Generic library terms a signature may name: term -> ``path -> [(column name, column)]``.
TERMS: dict[str, Callable[[_Path], list[tuple[str, np.ndarray]]]] = {
    "dv/dt": lambda c: [("dv/dt", _derivative(c.v, c.dt, 1))],
    "d2v/dt2": lambda c: [("d2v/dt2", _derivative(c.v, c.dt, 2))],
    "sgn(dv)": lambda c: [("sgn(dv)", c.s)],
    "sgn(dv)*exp(-d/w)": lambda c: [(f"sgn(dv)*exp(-d/{frac * c.span:.3g})", c.s * np.exp(-c.d / (frac * c.span)))
                                    for frac in (0.02, 0.06, 0.2)],
    "x^2": lambda c: [("x^2", c.x**2)],
    "x^3": lambda c: [("x^3", c.x**3)],
    "t": lambda c: [("t", c.t)],
}


def library(trace: ResidualTrace, span: float, center: float, half: float) -> tuple[np.ndarray, list[str], list[str]]:
    """Columns of the labelled library for one trace: ``(theta, names, families)``.

    Each family's columns are the terms its members' signatures name, in signal order.
    """
    v = trace.drive
    path = _Path(v, trace.dt, direction(v), since_reversal(v), (trace.static - center) / half, trace.time, span)
    cols, names, fams = [], [], []
    for family, members in _families().items():
        for term in dict.fromkeys(t for e in members for t in signature_of(e).terms):
            if term not in TERMS:
                raise ValueError(f"Unknown library term {term!r} in the signature of {family!r} effects. "
                                 f"Must be one of: {', '.join(TERMS)}.")
            for name, col in TERMS[term](path):
                cols.append(col)
                names.append(name)
                fams.append(family)
    theta = np.column_stack(cols) if cols else np.zeros((v.size, 0))
    return theta, names, fams


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
             min_score: float = 0.02, rounds: int = 2, tie: float = 0.85) -> list[Candidate]:
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
    tie : float
        A candidate below ``min_score`` is still named when its shape alone
        explains at least ``tie`` times what the best shape alone does (look-alike
        shapes of two families: each explains little beyond the other).

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
    all_families = _families()
    families = [f for f in all_families if any(fams[i] == f for i in kept)]
    if not families:
        return []
    members = {f: [e for e in all_families[f] if e not in exclude] for f in families}
    chosen = {f: shapes.best(members[f], st.nuisance)[0] for f in families}
    for _ in range(rounds):
        for f in families:
            chosen[f] = shapes.best(members[f], _covariates(st, chosen, f))[0]
    r = st.r
    r_free = _project_out(r[:, None], st.nuisance).ravel()
    sst = float(r_free @ r_free)
    alone = {e: shapes.fit(e, st.nuisance) for f in families for e in members[f]}
    best_alone = max([fit.drop for fit in alone.values()] + [0.0])
    out = []
    for f in families:
        terms = {names[i]: float(coef[i]) for i in kept if fams[i] == f}
        cov = _covariates(st, chosen, f)
        for effect in members[f]:
            fit = shapes.fit(effect, cov)
            explained = float(np.sqrt(max(fit.drop, 0.0) / r.size))
            score = fit.drop / sst if sst > 0 else 0.0
            passes = score >= min_score and explained >= threshold * noise_std
            by_itself = alone[effect].drop
            tied = (by_itself >= tie * best_alone and by_itself >= min_score * sst
                    and np.sqrt(max(by_itself, 0.0) / r.size) >= threshold * noise_std)
            if (passes or tied) and not not_in_time(signature_of(effect), st.traces, st.gain, noise_std, min_score):
                # a tie is judged by its shape alone: its estimates come from that fit
                cand = _candidate(effect, fit if passes else alone[effect], st, shapes)
                if cand is not None:
                    out.append(Candidate(effect, float(max(score, 0.0)), explained, cand.block, cand.parameters,
                                         cand.settings, terms, float(by_itself / sst) if sst > 0 else 0.0))
    return sorted(out, key=lambda c: -c.score)


def _with_shapes(st: _Stack, shapes: "_Shapes", exclude) -> tuple[np.ndarray, list[str], list[str]]:
    """The library plus, for each effect with a parametrised shape, its best shape alone.

    Generic terms such as ``sgn(dv) e^-d/w`` miss a second reversal effect on
    top of one the model has (backlash on Bouc-Wen); the exact shapes do not.
    """
    cols, names, fams = [], [], []
    for effect, cls in _signed().items():
        if effect in exclude or cls.signature.scale == "linear":
            continue
        fit = shapes.fit(effect, st.nuisance)
        if fit.drop <= 0:
            continue
        grid = shapes.shapes(effect)[1][fit.index]
        cols.append(fit.column)
        names.append(f"{cls.name}({', '.join(f'{k}={v:.3g}' for k, v in grid.items())})")
        fams.append(cls.signature.family)
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
    families = _families()
    allowed = np.array([any(e not in exclude for e in families[f]) for f in fams], dtype=bool)
    use = np.flatnonzero(live & allowed)
    coef = np.zeros(theta.shape[1])
    if use.size == 0 or not np.any(r):
        return [], coef
    # unit-RMS columns: a coefficient is the RMS (output units) of its term's contribution
    opt = _pysindy().STLSQ(threshold=threshold * noise_std, alpha=1e-4 * r.size, unbias=True)
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

    Shapes whose signature's scale is ``"fixed"`` (lag, delay, backlash) are
    scaled by the model's gain and enter with a fixed coefficient of one, so
    their parameter is identified by the size of the residual as well as its
    shape (a free coefficient would let any small time constant mimic a
    delay). What the re-fit of the model's own blocks can absorb (a lag's
    share of a delay) is in the projected-out sensitivities. Bouc-Wen's scale
    is its ``A``: ``"free"``. The static map and the drift are ``"linear"`` in
    their parameters: their family's library terms with free coefficients.
    """

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
        sig = signature_of(effect)
        if sig.scale == "linear":
            cols = [i for i, f in enumerate(st.fams) if f == sig.family]
            raw = st.theta[:, cols]
            f = raw - q @ (q.T @ raw)
            c, *_ = np.linalg.lstsq(f, r, rcond=None)
            e = r - f @ c
            return _Fit(effect, 0, base - float(e @ e), c, raw @ c)
        raw, _ = self.shapes(effect)
        f = raw - q @ (q.T @ raw)
        if sig.scale == "fixed":
            f = st.gain * f
            drop = 2 * (f.T @ r) - np.einsum("ij,ij->j", f, f)
            j = int(np.argmax(drop))
            return _Fit(effect, j, float(drop[j]), np.array([1.0]), st.gain * raw[:, j])
        drop, coef = free_drops(f, r, st.gain, sig.positive)
        j = int(np.argmax(drop))
        return _Fit(effect, j, float(drop[j]), np.array([coef[j]]), coef[j] * raw[:, j])

    def best(self, members: list[str], cov: np.ndarray) -> tuple[_Fit, list[_Fit]]:
        fits = [self.fit(e, cov) for e in members]
        return max(fits, key=lambda fit: fit.drop), fits


def _duration_if_asked(grid, st: _Stack) -> tuple:
    """``(longest run's duration,)`` for a grid that takes it (``(dt, span, duration)``), else ``()``."""
    try:
        takes = len(inspect.signature(grid).parameters) >= 3
    except (TypeError, ValueError):
        takes = False
    return (max(float(t.time[-1] - t.time[0]) for t in st.traces),) if takes else ()


def _shapes(effect: str, st: _Stack) -> tuple[np.ndarray, list[dict]]:
    """Stacked exact shapes of one effect over its parameter grid, and the grid."""
    sig = signature_of(effect)
    grid = sig.grid(st.traces[0].dt, st.span, *_duration_if_asked(sig.grid, st))
    return np.vstack([sig.shapes(along(t, sig.signal), t.dt, grid) for t in st.traces]), grid


def _candidate(effect: str, fit: _Fit, st: _Stack, shapes: _Shapes) -> Candidate | None:
    """First parameter estimates of the block for ``effect`` from its best shape."""
    sig = signature_of(effect)
    grid = None if sig.scale == "linear" else shapes.shapes(effect)[1][fit.index]
    est = sig.estimate(Estimate(fit.coef, grid, st.gain, st.center, st.half, st.traces[0].dt))
    if est is None:
        return None
    params, settings = est
    return Candidate(effect, 0.0, 0.0, BLOCK_OF[effect], params, settings)
