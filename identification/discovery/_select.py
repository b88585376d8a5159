"""Physics chosen for extrapolation: blocks kept only if they help on whole runs never seen.

Fit quality on the training runs (or on held-out samples of those runs) rewards flexibility;
on the real catheter it ranks specs almost in reverse of how they extrapolate to another
baseline. :func:`select_physics` scores each candidate spec by cross-validation over whole
runs (leave one run out, or leave one condition out: ``group_by="frequency_hz"``; one run is held out
in its later branches, each after a fit on the run before it: :func:`~._folds.holdout`), and grows the model greedily from ``start``, keeping a block only when
it beats the spec held on the errors paired per fold: by more than ``margin`` pooled, on most
folds, and by more than one standard error of the paired differences. Additions equal on that evidence each grow on their own, and the branches' ends are decided
by the same rule, then by simplicity, never by a digit.

The folds' fits cost time in proportion to the samples: runs recorded at kHz with more than
``max_samples`` samples are compared at a lower rate (anti-aliased), never below
:data:`RATE_FACTOR` times the inputs' bandwidth, so every dynamic the input excites is kept.
The caller fits the chosen spec on the runs as recorded.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field

import numpy as np
from tqdm.auto import tqdm

from physics import BLOCKS, LiveTuple, Series, in_signal_order

from identification._errors import IdentificationError
from identification._checks import settings_or_default
from identification._identify import identify
from identification._ranking import Ranking
from identification._solver_settings import SolverSettings
from identification._sensitivity import shared_compiles

from ._folds import holdout
from ._pool import Workers, make_pool
from ._selection_settings import MAX_SAMPLES, SelectionSettings  # noqa: F401  (MAX_SAMPLES: the default's home)
from ._signatures import _Live

__all__ = ["Selection", "select_physics", "SELECT_BLOCKS", "SELECT_REFINEMENTS"]



def _selectable() -> tuple[str, ...]:
    return tuple(sorted((name for name, cls in BLOCKS.items() if cls.selectable and cls.effect is not None
                         and cls.rank is not None and not cls.refines),
                        key=lambda name: BLOCKS[name].selection_order))  # stable: ties in registration order


def _refined() -> dict[str, tuple[str, ...]]:
    out: dict[str, list[str]] = {}
    for name, cls in BLOCKS.items():
        for base in cls.refines:
            if base in BLOCKS:
                out.setdefault(base, []).append(name)
    return {base: tuple(out[base]) for base in BLOCKS if base in out}


#: Blocks the greedy search may add, in the order tried (live: the registered blocks with an effect
#: and a rank that declare ``selectable``, by their ``selection_order``; a block registered later is
#: tried too).
SELECT_BLOCKS = LiveTuple(_selectable)
#: Richer blocks tried in place of a chosen one once the greedy search stops (live: each block's
#: ``refines``): they cost more to fit, so they are only tried where the simpler block of the same
#: effect has already earned its place and its fits show the effect (``shows_effect``: a resonance
#: that rings, whose damping may change with amplitude as a ``hysteretic_oscillator``'s does).
SELECT_REFINEMENTS = _Live(_refined)
#: A spec with a block whose minor loops need not close (``Block.closes_minor_loops``: Bouc-Wen)
#: is compared at its held-out error times 1 + this: it must beat the specs without one by 10 %.
#: Held-out runs from the training conditions cannot show the drift such a law builds under cycles
#: at other offsets: on the catheter, set 1's runs chose backlash+boucwen+linear (held-out 1.19 deg
#: against 1.22 for resonance+backlash+gpi+poly+linear), which then ratcheted on set 2 (4.7 deg,
#: against 1.86 for the GPI spec).
UNCLOSED_MARGIN = 0.10
#: Identification options of the cross-validation fits: a bounded number of iterations (the
#: answer is the same on any machine), and a fit that hits the limit is still scored.
CV_IDENTIFY = {"solver": SolverSettings(max_iter=150), "allow_failure": True}
#: Most branches the greedy search follows from one spec when several additions are equal on the evidence
#: (each grows on its own; the ends are compared by the same rule, and the simplest of equals is kept).
MAX_BRANCHES = 3
#: A choice resting on fewer held-out folds than this is reported as too few to trust.
FEW_FOLDS = 4
#: A reduced rate stays at least this many times the inputs' bandwidth (the frequency under
#: :data:`BANDWIDTH_SHARE` of their variance).
RATE_FACTOR = 20.0
#: The bandwidth holds this share of the inputs' variance.
BANDWIDTH_SHARE = 0.999


@dataclass
class Selection(Ranking):
    """The chosen spec and the evidence: each candidate's cross-validated error over whole runs.

    A :class:`~identification.Ranking`: ``ranked()`` and ``fold_parameters`` say which specs to fit on
    all runs, in order, and where each fit starts.

    ``cv_rmse`` maps each spec tried to its pooled RMSE over the held-out runs (output units;
    ``inf`` when a fit failed, with the reason in ``failed``), ``fold_rmse`` to its RMSE on each
    fold, ``train_rmse`` to its mean in-sample RMSE over the folds' fits; ``folds`` lists the runs
    held out in each fold, ``path`` the specs accepted in turn.
    """

    spec: str
    cv_rmse: dict[str, float]
    fold_rmse: dict[str, list[float]]
    train_rmse: dict[str, float]
    folds: list[list[str]]
    how: str
    path: list[str] = field(default_factory=list)
    failed: dict[str, str] = field(default_factory=dict)
    seconds: float = 0.0
    #: The rate the folds were fitted at, when lower than the runs' own (``max_samples``); else None.
    rate_hz: float | None = None
    #: Each spec's parameters fitted on each fold (name -> value): starts for its fit on all runs
    #: (``identify(..., guesses=...)``). Not in :meth:`to_dict`.
    fold_parameters: dict[str, list[dict[str, float]]] = field(default_factory=dict, repr=False)
    #: The peers scored on the same folds (their errors are in ``cv_rmse`` under these names), and the best
    #: one, where its held-out error is lower than the chosen spec's (None: the physics holds).
    peers: list[str] = field(default_factory=list)
    peer: str | None = None
    #: Specs whose folds were stopped once they could not beat the spec held (spec -> folds scored):
    #: their held-out error is over those folds only.
    stopped: dict[str, int] = field(default_factory=dict)

    def to_dict(self) -> dict:
        out = asdict(self)
        out.pop("fold_parameters")
        # six significant digits, not decimals: an output in metres of micro-strain is ~1e-7
        out["cv_rmse"] = {k: (None if not np.isfinite(v) else float(f"{v:.6g}")) for k, v in self.cv_rmse.items()}
        return out

    def ranked(self) -> list[str]:
        """The chosen spec, then the other specs scored on every fold, best held-out error first: the
        order in which to try fitting them on all runs."""
        rest = sorted((s for s in self.cv_rmse if s != self.spec and s not in self.peers and s not in self.stopped
                       and np.isfinite(self.cv_rmse[s])), key=lambda s: self.cv_rmse[s])
        return [self.spec, *rest]

    def table(self) -> str:
        """The candidates as text, best held-out error first."""
        rate = f", fitted at {self.rate_hz:.4g} Hz" if self.rate_hz else ""
        lines = [f"physics selection ({self.how}, {len(self.folds)} folds{rate}): chose {self.spec}",
                 f"  {'spec':40s} {'held-out RMSE':>14s} {'train RMSE':>11s}"]
        for spec in sorted(self.cv_rmse, key=lambda s: (s in self.stopped, self.cv_rmse[s])):  # partial ones last
            lines.append(f"  {spec + (' (peer)' if spec in self.peers else ''):40s} {self.cv_rmse[spec]:14.4g} "
                         f"{self.train_rmse.get(spec, np.nan):11.4g}" + ("  (failed)" if spec in self.failed else "")
                         + (f"  (stopped after {self.stopped[spec]} folds)" if spec in self.stopped else ""))
        if self.peer:
            lines.append(f"  the peer {self.peer} beats {self.spec} held out")
        lines.append(f"  {self.evidence()}")
        return "\n".join(lines)

    def evidence(self) -> str:
        """How much the choice rests on, in words, and whether that is too few to trust."""
        return evidence(len(self.folds), self.how)


def evidence(folds: int, how: str) -> str:
    """``The choice rests on N held-out folds (how)``, and a warning below :data:`FEW_FOLDS`."""
    text = f"The choice rests on {folds} held-out folds ({how})."
    if folds < FEW_FOLDS:
        text += (f" That is fewer than {FEW_FOLDS}, too few to trust a choice between close candidates: "
                 "record more runs (other amplitudes, rates, offsets).")
    return text


def _refinements(spec: str, refinements: dict, fitted: list[dict]) -> list[str]:
    """Specs with one block of ``spec`` replaced by a refinement, alone and with each other
    block of an effect the refinement holds itself (``holds_effects``: the hysteretic oscillator's
    backlash and hysteresis) removed. Only blocks whose fits on some fold (``fitted``, the
    folds' parameters) show their effect are refined."""
    names = spec.split("+")
    out = []
    for i, name in enumerate(names):
        if name not in refinements:
            continue
        prefix = f"{name}."
        own = [{k[len(prefix):]: v for k, v in values.items() if k.startswith(prefix)} for values in fitted]
        if not any(BLOCKS[name].shows_effect(values) for values in own):
            continue
        for new in refinements[name]:
            swapped = names[:i] + [new] + names[i + 1:]
            out.append(_ordered(swapped))
            out += [_ordered([n for n in swapped if n != drop]) for drop in swapped
                    if drop != new and BLOCKS[drop].effect in BLOCKS[new].holds_effects]
    return list(dict.fromkeys(out))


def _ordered(names: Sequence[str]) -> str:
    """Block names as a spec in signal order (each block's declared rank; ties keep registration order)."""
    return "+".join(in_signal_order(names))


def _insert(spec: str, block: str) -> str:
    """``block`` added to ``spec`` in signal order."""
    return _ordered(spec.split("+") + [block])


#: A held-out prediction whose error exceeds this many times the outputs' span has diverged: the
#: spec is reported as failed on that fold, not scored with an astronomical RMSE.
RUNAWAY = 1e3


def spread_of(y) -> float:
    """The scale :func:`diverges` measures errors against: ``ptp(y)``, else ``max |y|``, else 1."""
    y = np.asarray(y, dtype=float)
    return float(np.ptp(y)) or float(np.max(np.abs(y), initial=0.0)) or 1.0


def diverges(error, spread: float) -> bool:
    """True if a prediction has run away: an error not finite, or beyond :data:`RUNAWAY` times
    ``spread`` (:func:`spread_of` the measured values)."""
    error = np.asarray(error, dtype=float)
    return bool(not np.all(np.isfinite(error)) or np.max(np.abs(error), initial=0.0) > RUNAWAY * spread)


def _fold(spec: str, dt: float, options: dict, warmup: int, fit_runs, held_runs, spread: float, shared=None):
    """One fold: ``spec`` fitted on ``fit_runs`` predicts ``held_runs`` (each after its first ``warmup``
    samples, which set its state). Returns ``(errors, train RMSE, parameters)``; a module-level function
    of plain data, so a worker process can run it (``shared``: the folder the pool's workers share
    compiled steps through)."""
    with shared_compiles(shared):
        fit = identify(Series.from_spec(spec, dt=dt), fit_runs, **options)
    model = fit.model()
    slow = drift_time(model, max(r.n for r in fit_runs) * dt)
    if slow is not None:
        raise IdentificationError(f"{slow[0]} fitted at {slow[1]:.3g} s, comparable to the {max(r.n for r in fit_runs) * dt:.3g} s "
                                  "record it was fitted on: drift that follows the run's own course, not a dynamic "
                                  "that the next run shows")
    e = np.concatenate([_held_error(model, r, warmup) for r in held_runs])
    if diverges(e, spread):
        raise IdentificationError(f"the fitted model's prediction of held-out run(s) {[r.source for r in held_runs]} "
                                  f"diverges (error {np.max(np.abs(e)):.3g}, the outputs span {spread:.3g})")
    return e, float(fit.train_rmse), {**fit.parameters, **fit.fixed}


#: A block's time (a parameter in seconds, or the period of one in Hz) longer than this share of the
#: longest run a fold was fitted on is drift: the fit follows that record's own course (a resonance
#: whose period is a third of a single calibration loop predicts pieces of that loop, then fails on the
#: next branch). A spec is not chosen on a fold where it fits one: the fold counts as failed.
DRIFT_SHARE = 1 / 3


def drift_time(model, record_s: float) -> tuple[str, float] | None:
    """``(parameter, time in s)`` of the slowest time of ``model``'s blocks (:class:`Series`: parameters
    with the unit ``s``, periods of those in ``Hz``) when it exceeds :data:`DRIFT_SHARE` of ``record_s``;
    else None. A block that models drift itself (a creep's relaxation times are settings) is not read."""
    declared = [p for b in model.blocks for p in b.parameters]  # in the order of param_names
    slowest = None
    for name, p, v in zip(model.param_names, declared, model.params):
        time_s = v if p.unit == "s" else 1.0 / v if p.unit == "Hz" and v > 0 else None
        if time_s is not None and (slowest is None or time_s > slowest[1]):
            slowest = (name, float(time_s))
    return slowest if slowest is not None and slowest[1] > DRIFT_SHARE * record_s else None


def _held_error(model, run, warmup: int) -> np.ndarray:
    """The held-out run's error, simulated free after its first ``warmup`` samples, which set the state
    (:meth:`Series.estimate_state`; a peer's ``predict(run, warmup=window)``), as every model is scored."""
    k = min(warmup, run.n - 1)
    if isinstance(model, Series):
        y = model.simulate(run.u[k:], warmup=(run.u[:k], run.y[:k])) if k else model.simulate(run.u)
    else:
        y = model.predict(run.segment(k), warmup=run.segment(0, k)) if k else model.predict(run)
    return y - run.y[k:]


class _Tally:
    """One spec's folds as they are read, in order: summed squared errors, samples, per-fold RMSEs,
    training RMSEs and parameters; ``check`` its early-stop test, ``arrived`` the finished fits not yet
    read (fold index -> future)."""

    def __init__(self, partial, check):
        self.sq, self.n, per, train, fitted = partial
        self.per, self.train, self.fitted = list(per), list(train), list(fitted)
        self.check, self.arrived, self.failed, self.stopped, self.done = check, {}, None, False, False


class _Scorer:
    """Cross-validated error of specs on fixed folds; remembers what it has scored.

    ``score_all({spec: rival}, hopeless)`` fits the specs' folds on a pool (:func:`._pool.make_pool`:
    here, local worker processes or a Dask cluster), fold by fold across the specs, so that all workers
    are busy whatever the number of specs and folds. Each spec's folds are read in order as they arrive,
    and its fits stop once ``hopeless(spec, rival)(per_fold, sq)`` says that the folds read so far already
    decide it cannot beat its rival (:meth:`_Rule.hopeless`, an exact bound): its pooled error is then
    that of the folds it was read on, and ``stopped`` says after how many. A fit that finishes after its spec stopped is not
    read, and each fold's fit is the same in any process, so the choice and every number are the same
    on any pool as serial.
    """

    def __init__(self, runs, folds, dt, options, warmup: int = 0, pool=None, bar=None, fits=None):
        from ._pool import make_pool

        self.runs, self.folds, self.dt, self.options, self.warmup = runs, folds, dt, options, warmup
        #: Per fold, the runs fitted on (default: every run not held out).
        self.fits = fits if fits is not None else [[i for i in range(len(runs)) if i not in f] for f in folds]
        self.pool, self.bar = pool if pool is not None else make_pool(), bar
        self.spread = spread_of(np.concatenate([r.y for r in runs]))
        self.cv, self.per_fold, self.train, self.failed, self.fitted, self.stopped = {}, {}, {}, {}, {}, {}
        #: A stopped spec's rival, and what its folds so far gave (to go on from against another).
        self.stopped_by, self._partial = {}, {}
        #: Samples every fold scores in all (the pooled error's denominator).
        self.n_scored = sum(r.n - min(warmup, r.n - 1) for f in folds for r in (runs[i] for i in f))

    def __call__(self, spec: str) -> float:
        return self.score(spec)

    def score(self, spec: str, hopeless=None, rival: str | None = None) -> float:
        """``spec``'s held-out error; with ``hopeless`` (its test against ``rival``) stopped once it
        cannot beat ``rival``."""
        self.score_all({spec: rival}, None if hopeless is None else lambda _spec, _rival: hopeless)
        return self.cv[spec]

    def score_all(self, against: dict, hopeless=None) -> None:
        """Score each spec of ``against`` (spec -> its rival or None), stopped once ``hopeless(spec,
        rival)`` (a test of its folds so far, or None) says it cannot beat its rival. A spec scored
        already is kept, unless it was stopped against another rival or is asked in full: it goes on
        from the folds it has."""
        tallies = {}
        for spec, rival in against.items():
            if spec in self.cv and (spec not in self.stopped or self.stopped_by.get(spec) == rival):
                continue
            self.stopped.pop(spec, None)
            self.stopped_by.pop(spec, None)
            check = None if rival is None or hopeless is None else hopeless(spec, rival)
            tally = tallies[spec] = _Tally(self._partial.pop(spec, (0.0, 0, [], [], [])), check)
            if check is not None and tally.per and check(tally.per, tally.sq):
                tally.stopped = tally.done = True
        queue = [(spec, k) for k in range(len(self.folds)) for spec, t in tallies.items() if k >= len(t.per)
                 and not t.done]
        running: dict = {}
        try:
            while queue or running:
                while queue and len(running) < self.pool.workers:
                    spec, k = queue.pop(0)
                    if not tallies[spec].done:
                        running[self.pool.submit(_fold, *self._job(spec, k))] = (spec, k)
                        if self.bar is not None:
                            self.bar.total += 1
                            self.bar.refresh()
                if not running:
                    break
                future = self.pool.first(running)
                spec, k = running.pop(future)
                if self.bar is not None:
                    self.bar.update()
                tally = tallies[spec]
                if not tally.done:
                    tally.arrived[k] = future
                    self._read(tally)
                    if tally.done:  # its other fits in flight are not needed (nor counted as to come)
                        late = [f for f, (s, _) in running.items() if s == spec]
                        self.pool.cancel(late)
                        for f in late:
                            running.pop(f)
                        if self.bar is not None and late:
                            self.bar.total -= len(late)
                            self.bar.refresh()
        except BaseException:  # a Ctrl-C: nothing goes on running for this selection
            self.pool.abort(list(running))
            raise
        for spec, tally in tallies.items():
            self._finish(spec, tally, against[spec])

    def _job(self, spec: str, k: int) -> tuple:
        return (spec, self.dt, self.options, self.warmup, [self.runs[i] for i in self.fits[k]],
                [self.runs[i] for i in self.folds[k]], self.spread, self.pool.shared)

    def _read(self, tally: _Tally) -> None:
        """Read the spec's arrived folds in order, up to the first missing one, a failure or a stop."""
        while not tally.done and len(tally.per) in tally.arrived:
            future = tally.arrived.pop(len(tally.per))
            try:
                e, train_rmse, values = future.result()
            except (IdentificationError, RuntimeError, ValueError) as exc:
                tally.failed, tally.done = str(exc).splitlines()[0][:300], True
                return
            tally.sq, tally.n = tally.sq + float(e @ e), tally.n + e.size
            tally.per.append(float(np.sqrt(np.mean(e * e))))
            tally.train.append(train_rmse)
            tally.fitted.append(values)
            if len(tally.per) == len(self.folds):
                tally.done = True
            elif tally.check is not None and tally.check(tally.per, tally.sq):
                tally.stopped = tally.done = True

    def _finish(self, spec: str, tally: _Tally, rival: str | None) -> None:
        self.per_fold[spec] = tally.per
        if tally.failed is not None:
            self.failed[spec], self.cv[spec] = tally.failed, float("inf")
            return
        self.cv[spec] = float(np.sqrt(tally.sq / tally.n))
        self.train[spec], self.fitted[spec] = float(np.mean(tally.train)), tally.fitted
        if tally.stopped:
            self.stopped[spec], self.stopped_by[spec] = len(tally.per), rival
            self._partial[spec] = (tally.sq, tally.n, list(tally.per), list(tally.train), list(tally.fitted))

    def peer(self, name: str, make) -> float:
        """The held-out error of a peer (``make()`` an estimator with ``fit(runs)`` and
        ``predict(run, warmup=window)``) on the same folds and under the same warm-up window."""
        if name in self.cv:
            return self.cv[name]
        errors = []
        try:
            for fit, held in zip(self.fits, self.folds):
                model = make().fit([self.runs[i] for i in fit])
                errors.append(np.concatenate([_held_error(model, self.runs[i], self.warmup) for i in held]))
                if diverges(errors[-1], self.spread):
                    raise IdentificationError(f"the peer's prediction of held-out run(s) {sorted(held)} diverges")
        except (IdentificationError, RuntimeError, ValueError) as exc:
            self.failed[name] = str(exc).splitlines()[0][:300]
            self.cv[name], self.per_fold[name] = float("inf"), []
            return self.cv[name]
        e = np.concatenate(errors)
        self.cv[name] = float(np.sqrt(np.mean(e * e)))
        self.per_fold[name] = [float(np.sqrt(np.mean(f * f))) for f in errors]
        return self.cv[name]


def select_physics(trajectories, candidates: Sequence[str] | None = None, *, start: str = "linear",
                   blocks: Sequence[str] | None = None, refinements: dict[str, Sequence[str]] | None = None,
                   peers: dict | None = None, warmup: int = 0, settings: SelectionSettings | None = None,
                   identify_options: dict | None = None, workers: Workers | None = None,
                   progress: bool = False, verbose: bool = False) -> Selection:
    """The physics spec that extrapolates best to runs left out of the fit.

    Parameters
    ----------
    trajectories : sequence of Trajectory
        Training runs at one rate (``dt`` from their time stamps or ``meta["rate_hz"]``).
    candidates : sequence of str, optional
        Specs to compare, simplest first; a richer spec replaces the one held only if it beats it
        (the rule of ``blocks`` below). Default: the greedy search
        below. In both, a spec with a block whose minor loops need not close (Bouc-Wen, the
        hysteretic oscillator) is compared at its held-out error times ``1 +`` :data:`UNCLOSED_MARGIN`.
    start, blocks : str, sequence of str
        The greedy search begins at ``start`` and tries adding each of ``blocks`` (one block per
        effect), keeping an addition while it beats the spec held: a held-out error lower by more than
        ``margin`` pooled over the folds, lower on most folds, and lower by more than one standard error
        of the paired per-fold differences. Additions
        that beat it and that the best of them does not beat in turn are equal on this evidence: each
        (up to :data:`MAX_BRANCHES`, simplest first) grows on its own, the branches' ends are compared
        by the same rule, and the simplest end of those equal to the best is taken (fewest fitted
        parameters, then registry order), never the one ahead by a digit. Default :data:`SELECT_BLOCKS`.
    refinements : dict, optional
        Once the greedy search stops, each chosen block named here is tried replaced by each of
        its refinements, alone and with each other hysteresis-like block of the spec removed (the
        refinement may hold that effect itself); one is kept if it beats the spec held by the same
        rule, the simplest of those equal on the evidence.
        Default :data:`SELECT_REFINEMENTS`; ``{}`` turns it off.
    settings : SelectionSettings, optional
        How the evidence is gathered and weighed (:class:`SelectionSettings`): the ``margin`` a block
        must bring (0.03: 3 %), the folds (runs sharing ``meta[group_by]`` held out together, at most
        ``max_folds`` of them; default one run per fold) and ``max_samples``, the most samples the folds'
        fits see (more: the runs are resampled, anti-aliased, never below :data:`RATE_FACTOR` times
        the inputs' bandwidth, :data:`BANDWIDTH_SHARE` of their variance, and never for a spec with a
        pure delay). A single run is held out in its last branches between input reversals (or later
        stretches), each predicted by a fit on the run before it (:func:`~._folds.next_folds`). Default ``SelectionSettings()``.
    identify_options : dict, optional
        For the fits of the folds; default :data:`CV_IDENTIFY` (bounded iterations).
    warmup : int
        Each held-out run is simulated free after its first ``warmup`` samples, which set the model's
        state (the protocol ``hyst compare`` and ``hyst fit`` score every model with), so a wrong start
        is not taken for a wrong structure; 0: from rest at the first input.
    workers : Workers, optional
        Where the folds' fits run (:class:`Workers`): ``n_jobs`` local worker processes (joblib's loky
        executor; -1: one per core), or the workers of a running Dask cluster (its ``scheduler``
        address or a ``Client``; a Ctrl-C cancels the fits in flight there). The folds of all the specs
        tried at one step run side by side. Each fold's fit is the same in any process, so the choice
        and the numbers are the same as serial (the default, ``Workers()``).
    progress : bool
        A progress bar (tqdm, on stderr where it is a terminal) of the fold fits as they finish, and
        the specs scored.
    peers : dict of str to callable, optional
        Simple models scored on the same folds under the same warm-up window, ``name -> make`` with
        ``make()`` an unfitted estimator (``fit(runs)``, ``predict(run, warmup=window)``), e.g. a
        linear ARX. ``Selection.peer`` names the one with the lowest held-out error where it is lower than the
        chosen spec's: the default is never worse than a simple model on the same evidence.

    Returns
    -------
    Selection
    """
    t0 = time.perf_counter()
    runs = list(trajectories)
    if not runs:
        raise IdentificationError("select_physics needs training runs; got none.")
    settings = _settings(settings)
    margin, max_samples = settings.margin, settings.max_samples
    dt = _dt(runs)
    named = [start, *(candidates or ()), *(blocks or ())]
    delay = any(BLOCKS[b].pure_delay for n in named for b in str(n).replace(" ", "").split("+") if b in BLOCKS)
    reduced, dt, rate_hz = _budget(runs, dt, max_samples, delay)
    if verbose and rate_hz:
        print(f"select: {sum(r.n for r in runs)} samples, over max_samples={max_samples}: the folds are fitted at "
              f"{rate_hz:.4g} Hz", file=sys.stderr, flush=True)
    evidence_ = holdout(reduced, warmup, settings.group_by, settings.max_folds)  # the budget counts each sample once
    runs, folds, how = evidence_.runs, evidence_.held, evidence_.how
    options = {**CV_IDENTIFY, **(identify_options or {})}
    pool = make_pool(workers)
    bar = tqdm(total=0, desc="select", unit="fit", disable=None if progress else True, leave=False,
               file=sys.stderr)  # None: off where stderr is no terminal (a log file)
    score = _Scorer(runs, folds, dt, options, int(warmup), pool, bar, evidence_.fit)
    rule = _Rule(score, margin)

    def say(against: dict) -> None:  # score each spec (against its rival); progress on stderr
        score.score_all(against, rule.hopeless)
        for spec, rival in against.items():
            stopped = (f", stopped after {score.stopped[spec]} of {len(folds)} folds: it cannot beat {rival}"
                       if spec in score.stopped else "")
            if verbose:
                bar.write(f"select: {spec}: held-out RMSE {score.cv[spec]:.4g}{stopped} "
                          f"({time.perf_counter() - t0:.0f} s)", file=sys.stderr)
        bar.set_postfix_str(f"{len(score.cv)} specs", refresh=True)

    try:
        best, path = _search(say, score, rule, dt, candidates, start, blocks, refinements)
        if not np.isfinite(score(best)):
            raise IdentificationError("No candidate spec could be fitted on the folds:\n  "
                                      + "\n  ".join(f"{k}: {v}" for k, v in score.failed.items()))
        peer = None
        for name, make in (peers or {}).items():
            score.peer(name, make)
            if verbose:
                bar.write(f"select: peer {name}: held-out RMSE {score.cv[name]:.4g}", file=sys.stderr)
            if score.cv[name] < score.cv[peer or best]:  # the best on the same evidence, never worse than a peer
                peer = name
    finally:
        bar.close()
        pool.close()
    return Selection(best, dict(score.cv), dict(score.per_fold), dict(score.train),
                     [[str(getattr(runs[i], "source", "") or f"run{i}") for i in f] for f in folds], how, path,
                     dict(score.failed), round(time.perf_counter() - t0, 2), rate_hz, dict(score.fitted),
                     peers=list(peers or ()), peer=peer, stopped=dict(score.stopped))


def _settings(settings) -> SelectionSettings:
    return settings_or_default(settings, SelectionSettings, "settings", "SelectionSettings(margin=0.05)")


def _search(say, score: _Scorer, rule: _Rule, dt: float, candidates, start: str, blocks, refinements):
    """``(best, path)``: the candidates compared simplest first, or the greedy search with its
    branches and refinements (see :func:`select_physics`); ``say({spec: rival})`` scores specs."""
    if candidates is not None:
        specs = [Series.from_spec(c, dt=dt).spec for c in candidates]  # typos fail here, before any fit
        if not specs:
            raise IdentificationError("candidates is empty; give at least one spec, or None for the greedy search.")
        best, path = None, []
        for spec in sorted(dict.fromkeys(specs), key=_simplicity):
            say({spec: best})
            if best is None or rule.beats(spec, best):
                best = spec
                path.append(spec)
    else:
        blocks = tuple(SELECT_BLOCKS if blocks is None else blocks)  # read from the registry now
        refinements = dict(SELECT_REFINEMENTS if refinements is None else refinements)
        for b in (*blocks, *refinements, *(n for new in refinements.values() for n in new)):
            if b not in BLOCKS:
                raise IdentificationError(f"Unknown block {b!r} in blocks or refinements. Must be among: "
                                          f"{', '.join(BLOCKS)}.")
        root = Series.from_spec(start, dt=dt).spec
        say({root: None})
        parent: dict[str, str | None] = {root: None}
        ends, todo = [], [root]
        while todo:  # each branch grows while an addition beats it; ties between additions branch
            grown = {spec: _additions(spec, blocks) for spec in todo}  # the branches' trials, scored together
            against = {}
            for spec, trials in grown.items():
                against.update({t: spec for t in trials if t not in against})
            say(against)
            todo = []
            for spec, trials in grown.items():
                steps = rule.equals([t for t in trials if rule.beats(t, spec)])[:MAX_BRANCHES]
                if not steps:
                    ends.append(spec)
                for step in steps:
                    if step not in parent:
                        parent[step] = spec
                        todo.append(step)
        best = rule.choose(list(dict.fromkeys(ends)))
        path = [best]
        while parent[path[0]] is not None:
            path.insert(0, parent[path[0]])
        refined = _refinements(best, refinements, score.fitted.get(best, []))
        say(dict.fromkeys(refined, best))
        step = rule.choose([s for s in refined if rule.beats(s, best)])
        if step is not None:
            best = step
            path.append(best)
            best = _pruned(say, rule, best, path)
    return best, path


def _pruned(say, rule: "_Rule", spec: str, path: list) -> str:
    """After a refinement: ``spec`` with each block that no longer earns its place dropped, one at a time
    while the spec with it does not beat the spec without it by the rule (the simpler kept: a lag added
    while the resonance could not hold the hysteresis is not needed once a hysteretic oscillator does);
    ``path`` gets each spec taken."""
    while True:
        names = spec.split("+")
        fewer = [_ordered([n for n in names if n != drop]) for drop in names
                 if BLOCKS[drop].effect is not None and len(names) > 2]  # the output map (no effect) stays
        if not fewer:
            return spec
        say(dict.fromkeys(fewer))
        kept = rule.choose([f for f in fewer if not rule.beats(spec, f)])
        if kept is None:
            return spec
        spec = kept
        path.append(spec)


def _additions(spec: str, blocks) -> list[str]:
    """``spec`` with each of ``blocks`` added whose effect it does not hold yet."""
    have = {BLOCKS[n].effect for n in spec.split("+")}
    return [_insert(spec, b) for b in blocks if b not in spec.split("+") and BLOCKS[b].effect not in have]


def _simplicity(spec: str) -> tuple:
    """Simpler first: fewer fitted parameters, then blocks earlier in the registry (a fixed order, so
    the choice between equals never rests on digits of their errors)."""
    model = Series.from_spec(spec)
    order = list(BLOCKS)
    return int(model.fit_mask.sum()), len(model.blocks), sorted(order.index(b.name) for b in model.blocks)


class _Rule:
    """When one candidate is better than another: on the errors paired per fold, not on a digit.

    ``a`` beats ``b`` when its pooled held-out error (raised for a law whose minor loops drift) is below
    ``b``'s by more than ``margin``, it is lower on most folds (more than half), *and* the mean of the
    paired per-fold differences is below zero by more than one standard error. Three conditions that
    must all hold: where candidates are close, one of them fails by far, so no digit decides. Among several
    candidates that beat the incumbent, the best one and every one it does not beat in turn are equal
    on this evidence, and the simplest of them is taken (:func:`_simplicity`).
    """

    def __init__(self, score: _Scorer, margin: float):
        self.score, self.margin = score, margin

    def _factor(self, spec: str) -> float:
        unclosed = any(not BLOCKS[n].closes_minor_loops for n in spec.split("+") if n in BLOCKS)
        return 1 + UNCLOSED_MARGIN if unclosed else 1.0

    def cost(self, spec: str) -> float:
        value = self.score.cv[spec] if spec in self.score.cv else self.score(spec)
        return value * self._factor(spec)

    def beats(self, a: str, b: str) -> bool:
        if a in self.score.stopped:  # stopped once its folds showed it could not beat ``b`` (the spec held)
            if self.score.stopped_by.get(a) == b:
                return False
            self.score.score(a, self.hopeless(a, b), b)  # stopped against another: go on against this one
            if a in self.score.stopped:
                return False
        ca, cb = self.cost(a), self.cost(b)
        if not np.isfinite(cb):
            return bool(np.isfinite(ca))
        if not ca < cb * (1 - self.margin):
            return False
        d = np.array(self.score.per_fold[a]) * self._factor(a) - np.array(self.score.per_fold[b]) * self._factor(b)
        if not 2 * np.sum(d < 0) > d.size:
            return False
        # and lower by more than one standard error of the paired differences: a mean a fold's noise
        # could give is no evidence (on the catheter a step 3.02 % better pooled and on 4 of 5 folds lay
        # 0.4 standard errors from no difference, and a fourth digit decided the margin)
        return d.size < 2 or bool(np.mean(d) + np.std(d, ddof=1) / np.sqrt(d.size) < 0)

    def hopeless(self, a: str, b: str):
        """``check(per_fold, sq)``: True once ``a``'s folds scored so far (their RMSEs and summed squared
        errors) prove it cannot beat ``b``: it has lost on so many folds that it can no longer win on
        most, or its squared errors already exceed what the margin allows over all folds. Exact: a spec
        stopped by it would not have beaten ``b`` on all folds either."""
        cb = self.cost(b)
        if not np.isfinite(cb):
            return None
        fa, fb, rival = self._factor(a), self._factor(b), self.score.per_fold[b]
        limit = self.score.n_scored * (cb * (1 - self.margin) / fa) ** 2

        def check(per: list[float], sq: float) -> bool:
            losses = sum(x * fa >= y * fb for x, y in zip(per, rival))
            return 2 * (len(rival) - losses) <= len(rival) or sq >= limit

        return check

    def equals(self, better: Sequence[str]) -> list[str]:
        """The best of ``better`` and every candidate it does not beat in turn, simplest first: equal on
        the evidence (empty when ``better`` is)."""
        if not better:
            return []
        top = min(better, key=lambda s: (self.cost(s), _simplicity(s)))
        return sorted((s for s in better if not self.beats(top, s)), key=_simplicity)

    def choose(self, better: Sequence[str]) -> str | None:
        """The simplest of the candidates equal to the best of ``better`` (None when it is empty)."""
        equal = self.equals(better)
        return equal[0] if equal else None


def _bandwidth(runs, dt: float, share: float = BANDWIDTH_SHARE) -> float:
    """The highest frequency (Hz) below which ``share`` of a run's input variance lies, over the runs
    (each detrended and Hann-windowed, so that the jump between a run's ends adds no power)."""
    out = 0.0
    for r in runs:
        u = np.asarray(r.u, dtype=float)
        u = (u - np.polyval(np.polyfit(np.arange(u.size), u, 1), np.arange(u.size))) * np.hanning(u.size)
        power = np.abs(np.fft.rfft(u)) ** 2
        total = power[1:].sum()
        if total <= 0:
            continue
        k = int(np.searchsorted(np.cumsum(power[1:]) / total, share)) + 1
        out = max(out, float(np.fft.rfftfreq(u.size, dt)[min(k, power.size - 1)]))
    return out


def _budget(runs, dt: float, max_samples: int | None, delay: bool):
    """The runs the folds are fitted on, their step, and the reduced rate (None when unchanged)."""
    n = sum(r.n for r in runs)
    if max_samples is None or n <= max_samples or delay or not all(hasattr(r, "resample") for r in runs):
        return runs, dt, None
    rate = max(max_samples / n / dt, RATE_FACTOR * _bandwidth(runs, dt))
    if rate * dt > 0.8:  # less than 20 % fewer samples: not worth the resampling
        return runs, dt, None
    runs = [r.resample(rate) for r in runs]
    return runs, _dt(runs), rate


def _dt(runs) -> float:
    steps = []
    for r in runs:
        if getattr(r, "time", None) is not None and len(r.time) > 1:
            steps.append(float(np.median(np.diff(r.time))))
        elif getattr(r, "meta", {}).get("rate_hz"):
            steps.append(1.0 / float(r.meta["rate_hz"]))
    if not steps:
        raise IdentificationError("The runs carry no time stamps or meta['rate_hz']; pass physics.data.Trajectory.")
    if max(steps) - min(steps) > 1e-6 * max(steps):
        raise IdentificationError(f"All runs must share one sample rate; got steps {sorted(set(steps))} s.")
    return steps[0]
