"""The discrepancy workflow: find where model and data disagree, name the missing effect, add it.

Each step fits the current model (CasADi + IPOPT, :func:`identify`) to the
training data, diagnoses the residual with :func:`diagnose` (pysindy over a
library of terms labelled by effect), inserts the block of the best candidate
in signal order, initialised from the diagnosis, re-fits, and keeps the block
only if the held-out error drops by a clear margin (or, for an effect with several blocks such
as hysteresis, if one of its other blocks does). It stops when the
held-out error is at the noise floor, or when no candidate helps.
"""

from __future__ import annotations

import copy
import inspect
import time
from dataclasses import dataclass, replace

import numpy as np

from physics import BLOCKS, EFFECTS, Series, clip_to_bounds, effect_blocks
from physics.data import Trajectory

from identification._checks import settings_or_default
from identification._identify import identify
from identification._solver_settings import SolverSettings
from ._report import DiscoveryReport, Step
from ._noise import noise_floor, whiteness
from ._thresholds import DiscoveryThresholds
from ._signatures import BLOCK_OF, FAMILIES, FAMILY_OF, Candidate, ResidualTrace, _Live, diagnose

#: Signal order of block names (each block's declared ``rank``).
RANK = _Live(lambda: {name: cls.rank for name, cls in BLOCKS.items() if cls.rank is not None})

#: Effect that each block already models (each block's declared ``effect``).
EFFECT_OF_BLOCK = _Live(lambda: {name: cls.effect for name, cls in BLOCKS.items() if cls.effect})

#: The other member of a two-effect family (lag/delay, backlash/hysteresis).
SIBLING = _Live(lambda: {e: next(m for m in members if m != e) for members in FAMILIES.values()
                         if len(members) == 2 for e in members})


def _rank(block) -> int:
    if block.rank is None:
        raise ValueError(f"Block '{block.name}' ({type(block).__name__}) declares no rank, so discovery "
                         "cannot place it in signal order; set `rank = ...` on its class.")
    return block.rank


@dataclass(frozen=True)
class _Split:
    """Training runs, and the runs the held-out error is measured on (from sample ``start`` on)."""

    train: list[Trajectory]
    test: list[Trajectory]
    test_start: list[int]
    how: str


# -- data ------------------------------------------------------------------------------
def _runs(trajectories) -> list[Trajectory]:
    items = [trajectories] if hasattr(trajectories, "u") else list(trajectories)
    if not items:
        raise ValueError("discover needs at least one trajectory; got none.")
    out = []
    for i, t in enumerate(items):
        u, y = np.asarray(t.u, dtype=float), np.asarray(t.y, dtype=float)
        if u.ndim != 1 or u.shape != y.shape or u.size < 20:
            name = f"Trajectory {i}" + (f" ({t.source})" if getattr(t, "source", "") else "")
            raise ValueError(f"{name} needs 1-D u and y of equal length >= 20 samples (give a longer run); "
                             f"got shapes {u.shape} and {y.shape}.")
        if getattr(t, "time", None) is None:
            raise ValueError(f"Trajectory {i} has no time stamps; discovery needs them for the sample rate. "
                             "Pass physics.data.Trajectory(time, u, y).")
        tt = np.asarray(t.time, dtype=float)
        out.append(Trajectory(tt - tt[0], u, y, source=str(getattr(t, "source", "") or f"run{i}")))
    dts = [float(np.median(np.diff(r.time))) for r in out]
    if max(dts) - min(dts) > 1e-6 * max(dts):
        raise ValueError(f"All trajectories must share one sample rate; got steps {sorted(set(dts))} s. "
                         "Resample them first (hybrid.data.resample).")
    return out


#: Discovery works at about this rate (Hz) at most: faster data is decimated by a whole factor for
#: the search, and the final model is brought back to the data's own rate.
WORKING_RATE_HZ = 200.0


def decimation(dt: float, working_rate_hz: float | None) -> int:
    """Whole factor that brings a step of ``dt`` s to about ``working_rate_hz`` (1: none)."""
    if working_rate_hz is None:
        return 1
    return max(1, int(round(1.0 / (dt * working_rate_hz))))


def _decimated(runs: list[Trajectory], k: int) -> list[Trajectory]:
    # every k-th sample: the effects searched for are slow next to the working rate, and white
    # noise picked every k-th sample stays white with the same spread (a block mean would not)
    if k == 1:
        return runs
    return [Trajectory(r.time[::k], r.u[::k], r.y[::k], source=r.source) for r in runs]


def at_rate(model: Series, dt: float) -> Series:
    """``model`` at another sample step: parameters are in physical units (seconds) and carry
    over; a pure delay's whole number of samples is scaled to keep its length in seconds."""
    blocks = []
    for b in copy.deepcopy(model.blocks):
        if b.pure_delay and b.searched_setting is not None:
            samples = getattr(b, b.searched_setting)
            b = b.with_settings(**{b.searched_setting: max(1 if samples else 0,
                                                           int(round(samples * model.dt / dt)))})
        blocks.append(b)
    return Series(*blocks, dt=dt, input_range=model.input_range)


def _refine_delays(model: Series, split: "_Split", k: int) -> Series:
    """A pure delay converted from a rate ``k`` times slower, set to the whole number of samples
    within ``k // 2`` of it that simulates the training runs best (no re-fit: the other
    parameters are in physical units, and a fit with one state per sample of delay at a kHz
    rate costs minutes)."""
    for i, b in enumerate(model.blocks):
        if not (b.pure_delay and b.searched_setting is not None):
            continue
        key, now = b.searched_setting, getattr(b, b.searched_setting)
        before = Series(*copy.deepcopy(model.blocks[:i]), dt=model.dt) if i else None
        after = Series(*copy.deepcopy(model.blocks[i + 1:]), dt=model.dt)
        ins = [before.simulate(r.u) if before is not None else r.u for r in split.train]
        trials = []
        for d in range(max(1, now - k // 2), now + k // 2 + 1):
            # the delay at rest outputs its first input: a shift, simulated without its d states
            e = [r.y - after.simulate(np.concatenate([np.full(d, v[0]), v[:-d]]))
                 for r, v in zip(split.train, ins)]
            trials.append((float(np.mean(np.concatenate(e) ** 2)), abs(d - now), d))
        blocks = list(copy.deepcopy(model.blocks))
        blocks[i] = b.with_settings(**{key: min(trials)[2]})
        model = Series(*blocks, dt=model.dt, input_range=model.input_range)
    return model


def split_runs(runs: list[Trajectory], holdout: float = 0.3) -> _Split:
    """Hold out every third trajectory (from the second) when there are three or more,
    else the last ``holdout`` of each trajectory's time."""
    if len(runs) >= 3:
        test_idx = set(range(1, len(runs), 3))
        train = [r for i, r in enumerate(runs) if i not in test_idx]
        test = [r for i, r in enumerate(runs) if i in test_idx]
        return _Split(train, test, [0] * len(test), "trajectories")
    train, starts = [], []
    for r in runs:
        cut = int(round(r.u.size * (1 - holdout)))
        train.append(Trajectory(r.time[:cut], r.u[:cut], r.y[:cut], source=r.source))
        starts.append(cut)
    return _Split(train, list(runs), starts, "time")


# -- models ------------------------------------------------------------------------------
def present_effects(model: Series) -> set[str]:
    """Effects the model already has a block for."""
    return {b.effect for b in model.blocks if b.effect}


def _prefix_output(model: Series, max_rank: int, u: np.ndarray) -> np.ndarray:
    blocks = [b for b in model.blocks if _rank(b) <= max_rank]
    if not blocks:
        return u
    if blocks != list(model.blocks[: len(blocks)]):
        raise ValueError(f"Blocks of '{model.spec}' are not in signal order; "
                         "write lag/delay, backlash, hysteresis, poly, linear, drift.")
    return Series(*blocks, dt=model.dt).simulate(u)


def residual_traces(model: Series, runs) -> list[ResidualTrace]:
    """The residual of ``model`` along each run, with its internal signals (see :class:`ResidualTrace`)."""
    runs = _runs(runs) if not (runs and isinstance(runs[0], Trajectory)) else runs
    sims = [model.simulate(r.u) for r in runs]
    statics = [_prefix_output(model, 3, r.u) for r in runs]
    s_all, y_all = np.concatenate(statics), np.concatenate(sims)
    gain = float(np.polyfit(s_all, y_all, 1)[0]) if np.ptp(s_all) > 0 else 1.0
    return [ResidualTrace(r.time, r.y - ysim, _prefix_output(model, 1, r.u),
                          _prefix_output(model, 2, r.u), st, gain if gain != 0 else 1.0,
                          sensitivities(model, r.u, ysim))
            for r, ysim, st in zip(runs, sims, statics)]


def sensitivities(model: Series, u: np.ndarray, y: np.ndarray | None = None) -> np.ndarray:
    """``d y / d p`` of the fitted parameters along ``u`` by finite differences, shape (n, k).

    A block's ``searched_setting`` (a delay's whole number of samples) gets a
    column too (the output with one more minus one less): it is searched when re-fitting.
    """
    y = model.simulate(u) if y is None else y
    p0 = model.params
    lo, hi = model.lower_bounds, model.upper_bounds
    cols = []
    for k in np.flatnonzero(model.fit_mask):
        h = 1e-5 * max(abs(p0[k]), 1e-2)
        sign = 1.0 if p0[k] + h <= hi[k] else -1.0
        p = p0.copy()
        p[k] += sign * h
        cols.append((model.simulate(u, p=p) - y) / (sign * h))
    for i, block in enumerate(model.blocks):  # a delay's length moves like a continuous parameter
        key = block.searched_setting
        if key is not None:
            shifted = []
            value = getattr(block, key)
            for k in (value + 1, max(value - 1, 0)):
                blocks = list(model.blocks)
                blocks[i] = block.with_settings(**{key: k})
                shifted.append(Series(*blocks, dt=model.dt).simulate(u))
            cols.append(shifted[0] - shifted[1])
    return np.column_stack(cols) if cols else np.zeros((u.size, 0))


def new_block(cand: Candidate, dt: float, max_step: float = 0.0):
    """The block for a candidate, initialised from its first estimates (see ``Signature.build``)."""
    cls = BLOCKS[cand.block]
    build = cls.signature.build if cls.signature is not None else None
    if build is not None:
        return build(dict(cand.parameters), dict(cand.settings), max_step)
    takes = set(inspect.signature(cls.__init__).parameters)
    return cls(**clip_to_bounds(cls, cand.parameters),
               **{k: v for k, v in cand.settings.items() if k in takes})


def insert(model: Series, block) -> Series:
    """A copy of ``model`` with ``block`` inserted in signal order."""
    blocks = list(copy.deepcopy(model.blocks))
    at = sum(1 for b in blocks if _rank(b) <= _rank(block))
    return Series(*blocks[:at], block, *blocks[at:], dt=model.dt)


def settings_of(model: Series) -> dict:
    """Structural settings that a spec string does not carry (``"delay.samples"``, ...)."""
    return {f"{pre}.{k}": v for pre, b in zip(model._prefixes, model.blocks) for k, v in b.get_settings().items()}


# -- fitting and scoring -------------------------------------------------------------------
#: IPOPT's settings of discovery's fits by default: 300 iterations per fit, the limit.
DISCOVERY_SOLVER = SolverSettings(max_iter=300)


def _fit_once(model: Series, split: _Split, limits: dict) -> tuple[Series, float]:
    """``limits``: ``solver`` (:class:`SolverSettings`: its ``max_iter`` is the deciding limit);
    optionally ``failed``, a list that each failed fit is appended to (spec, status)."""
    if model.n_p == 0 or not model.fit_mask.any():
        return model, _train(model, split)
    # one start: discovery's starts are informed (the previous model's optimum and the
    # diagnosis' estimates) and it compares several candidates; multi-start would triple its cost
    res = identify(model, split.train, starts=1, allow_failure=True, solver=limits["solver"])
    if not res.success and limits.get("failed") is not None:
        limits["failed"].append({"spec": model.spec, "settings": settings_of(model), "status": res.status,
                                 "iterations": res.iterations})
    return res.model(), float(res.train_rmse) if res.success else np.inf


#: Longest delay the local search reaches (s), and at least this many samples.
MAX_DELAY_S, MAX_DELAY_SAMPLES = 0.6, 25


def _fit(model: Series, split: _Split, limits: dict) -> Series:
    """Identify the parameters; a block's searched setting (a delay's whole number of samples) by a
    local search on the training error, one sample at a time up to ``MAX_DELAY_S`` (at least
    ``MAX_DELAY_SAMPLES`` samples)."""
    max_delay = max(MAX_DELAY_SAMPLES, int(np.ceil(MAX_DELAY_S / model.dt)))
    fitted, cost = _fit_once(model, split, limits)
    for i, block in enumerate(model.blocks):
        key = block.searched_setting
        if key is None:
            continue
        for step in (-1, 1):
            while 1 <= getattr(fitted.blocks[i], key) + step <= max_delay:
                blocks = list(copy.deepcopy(fitted.blocks))
                blocks[i] = fitted.blocks[i].with_settings(**{key: getattr(fitted.blocks[i], key) + step})
                # a neighbouring length is a local refinement: a short budget
                trial, c = _fit_once(Series(*blocks, dt=model.dt), split,
                                     {**limits, "solver": limits["solver"].with_budget(
                                         max(1, limits["solver"].max_iter // 4))})
                if not c < cost * (1 - 1e-4):
                    break
                fitted, cost = trial, c
    return fitted


def _heldout(model: Series, split: _Split) -> float:
    errs = [r.y[k:] - model.simulate(r.u)[k:] for r, k in zip(split.test, split.test_start)]
    e = np.concatenate(errs)
    return float(np.sqrt(np.mean(e**2)))


def _white(model: Series, split: _Split) -> bool:
    e = [r.y[k:] - model.simulate(r.u)[k:] for r, k in zip(split.test, split.test_start)]
    n = sum(x.size for x in e)
    return max(whiteness(x) * np.sqrt(x.size / n) for x in e) <= 4 / np.sqrt(n)


def _train(model: Series, split: _Split) -> float:
    e = np.concatenate([r.y - model.simulate(r.u) for r in split.train])
    return float(np.sqrt(np.mean(e**2)))


# -- the loop -------------------------------------------------------------------------------------
def discover(trajectories, start: str | Series = "linear", *, max_steps: int = 6, max_tries: int = 3,
             holdout: float = 0.3, revise: bool = True, working_rate_hz: float | None = WORKING_RATE_HZ,
             thresholds: DiscoveryThresholds | None = None, solver: SolverSettings | None = None,
             verbose: bool = False, diagnose_options: dict | None = None) -> DiscoveryReport:
    """Grow a physics model one named effect at a time until it explains the data.

    Parameters
    ----------
    trajectories : sequence of trajectories
        Objects with ``time``, ``u`` and ``y`` (``hybrid.data.Trajectory``), one
        sample rate. Several runs at different frequencies let the diagnosis
        tell rate-dependent effects (lag, delay) from rate-independent ones.
    start : str or physics.Series
        The starting model, default ``"linear"``.
    max_steps : int
        Most effects added.
    max_tries : int
        Most candidate blocks fitted per step. Candidates of one family whose
        scores are within ``thresholds.ambiguity`` of each other are all fitted and the
        best held-out one is kept. A candidate that fails the held-out test is
        also fitted as the other blocks of its effect that fit from their
        defaults (GPI for Bouc-Wen, see :func:`alternatives`), outside this count.
    holdout : float
        With fewer than three trajectories, the share of each one's time held out.
    revise : bool
        At the end, re-fit the final model without each named effect and drop
        the effect if it no longer passes the held-out test (an effect added
        while another was missing may have been standing in for it; the model
        without it is also tried with a Bouc-Wen swapped for GPI, whose envelope
        and plays may take up a static map or a backlash); then try each named
        lag/delay and backlash/hysteresis against its sibling with every other
        effect in the model and swap only if the sibling passes the held-out test.
    working_rate_hz : float or None
        Data sampled faster than this is searched at about this rate (every k-th sample, k
        whole), so a kHz recording costs no more than a slow one and a delay's search in
        samples reaches the same time; the final model is then re-fitted at the data's own
        rate: its parameters carry over (they are in physical units), a delay is set to the
        best whole number of samples there, and the start and final RMSEs are measured there
        (the steps' at the working rate). None: always the data's rate.
    thresholds : DiscoveryThresholds, optional
        The tests' thresholds: ``margin`` and ``z`` (when a block is kept), ``floor_tolerance``
        (when the search stops) and ``ambiguity`` (which look-alike candidates are all fitted);
        default ``DiscoveryThresholds()``.
    solver : SolverSettings, optional
        IPOPT's settings for every fit (:class:`~identification.SolverSettings`); default
        ``SolverSettings(max_iter=300)``: the iterations are the limit, so the same data give the same
        report on any machine (a neighbouring delay length is refined with a quarter of them).
    verbose : bool
        Print each step.
    diagnose_options : dict, optional
        Keyword arguments of :func:`diagnose`.

    Returns
    -------
    DiscoveryReport

    Examples
    --------
    >>> from hybrid.virtual import VirtualCatheter, DecayingSinusoid
    >>> cath = VirtualCatheter(effects="lag", input="command", seed=1)
    >>> runs = [cath.run(DecayingSinusoid(f, "mid", cycles=3)) for f in (0.1, 0.3, 0.6)]
    >>> report = discover(runs, start="linear")
    >>> report.named_effects, report.final_model
    (['actuator_lag'], 'lag+linear')
    """
    t_start = time.perf_counter()
    thresholds = settings_or_default(thresholds, DiscoveryThresholds, "thresholds", "DiscoveryThresholds(margin=0.3)")
    solver = DISCOVERY_SOLVER if solver is None else settings_or_default(solver, SolverSettings, "solver",
                                                                         "SolverSettings(max_iter=300)")
    full_runs = _runs(trajectories)
    dt_data = float(np.median(np.diff(full_runs[0].time)))
    model = Series.from_spec(start, dt=dt_data) if isinstance(start, str) else copy.deepcopy(start)
    if abs(model.dt - dt_data) > 1e-9 * dt_data:
        raise ValueError(f"The start model's dt ({model.dt} s) differs from the data's ({dt_data} s).")
    k = decimation(dt_data, working_rate_hz)
    runs, dt = _decimated(full_runs, k), dt_data * k
    model = at_rate(model, dt) if k > 1 else model
    split = split_runs(runs, holdout)
    floor = noise_floor([r.y for r in full_runs])  # the same white noise at either rate
    max_step = max(float(np.max(np.abs(np.diff(r.u)))) for r in runs)
    say = print if verbose else (lambda *a, **k: None)
    failed: list[dict] = []
    limits = {"solver": solver, "failed": failed}
    accept = _Acceptance(split, floor, thresholds.margin, thresholds.z)  # the held-out test of every step, prune and swap

    model = _fit(model, split, limits)
    start_model = copy.deepcopy(model)
    rmse0 = _heldout(model, split)
    say(f"start '{model.spec}': held-out RMSE {rmse0:.3g} (noise floor {floor:.3g})")
    steps: list[Step] = []
    rmse = rmse0
    for _ in range(max_steps):
        if rmse <= (1 + thresholds.floor_tolerance) * floor and _white(model, split):
            break
        traces = residual_traces(model, split.train)
        cands = diagnose(traces, noise_std=floor, exclude=present_effects(model),
                         **(diagnose_options or {}))
        step = _try_candidates(model, cands, split, rmse, accept, max_tries, thresholds.ambiguity,
                               max_step, limits)
        if step is None:
            say("no candidate lowers the held-out error: stop")
            break
        model, record = step
        steps.append(record)
        say(f"missing effect: {record.description}; RMSE {record.rmse_before:.3g} -> "
            f"{record.rmse_after:.3g}")
        rmse = record.rmse_after
    if revise and steps:
        model, steps = _prune(model, steps, split, accept, limits, say, max_step)
        model, steps = _revise(model, steps, split, accept, max_step, limits, say)
        rmse = _heldout(model, split)
    if k > 1:  # back to the data's rate: parameters carry over, a delay's length is refined
        split = split_runs(full_runs, holdout)
        start_model = _refine_delays(at_rate(start_model, dt_data), split, k)
        model = _refine_delays(at_rate(model, dt_data), split, k)
        rmse0, rmse = _heldout(start_model, split), _heldout(model, split)
        say(f"at the data's rate ({1 / dt_data:.4g} Hz): held-out RMSE {rmse0:.3g} -> {rmse:.3g}")
    final_resid = np.concatenate([r.y[k:] - model.simulate(r.u)[k:]
                                  for r, k in zip(split.test, split.test_start)])
    return DiscoveryReport(
        start=start if isinstance(start, str) else start.spec,
        named_effects=[s.effect for s in steps if not s.removed], steps=steps, rmse_start=rmse0, rmse_final=rmse,
        noise_floor=floor, final_model=model.spec, final_parameters=model.param_dict(),
        final_settings=settings_of(model), whiteness=whiteness(final_resid),
        split=split.how, n_trajectories=len(full_runs), wall_time_s=time.perf_counter() - t_start,
        failed_fits=failed, model=model, start_model=start_model)


@dataclass(frozen=True)
class _Acceptance:
    """Does a re-fitted model beat the current one on held-out data by a clear margin?"""

    split: _Split
    floor: float
    margin: float
    z: float

    def __call__(self, before: Series, after: Series) -> bool:
        e_b, e_a, dy = [], [], []
        for r, k in zip(self.split.test, self.split.test_start):
            yb, ya = before.simulate(r.u)[k:], after.simulate(r.u)[k:]
            e_b.append(r.y[k:] - yb)
            e_a.append(r.y[k:] - ya)
            dy.append(ya - yb)
        e_b, e_a, dy = (np.concatenate(v) for v in (e_b, e_a, dy))
        rb, ra = np.sqrt(np.mean(e_b**2)), np.sqrt(np.mean(e_a**2))
        gap_closed = rb - ra > self.margin * max(rb - self.floor, 0.0) and ra < rb
        noise_se = 2 * self.floor * np.sqrt(np.mean(dy**2)) / np.sqrt(dy.size)
        return bool(gap_closed and rb**2 - ra**2 > self.z * noise_se)


#: Two candidates are look-alikes when each explains less than this share of what it explains
#: alone beyond the other families (their shapes overlap on these data).
LOOKALIKE = 0.1


def _alike(a: Candidate, b: Candidate, ambiguity: float) -> bool:
    """Candidates of two families whose shapes alone explain about as much (within ``ambiguity``)
    and little beyond each other: the diagnosis cannot tell them apart, held-out fits can."""
    overlap = all(c.score < LOOKALIKE * c.alone for c in (a, b))
    return overlap and min(a.alone, b.alone) >= ambiguity * max(a.alone, b.alone) > 0


def _other_blocks(effect: str, block: str) -> list[str]:
    """Names of the other blocks of ``effect`` than ``block`` that a gradient fit can start from
    their own defaults (smooth in the input, no signature of their own: GPI next to Bouc-Wen)."""
    return [cls.name for cls in effect_blocks(effect)
            if cls.name != block and cls.smooth_in_input and cls.signature is None]


def alternatives(cand: Candidate) -> list[Candidate]:
    """``cand`` as each of :func:`_other_blocks` of its effect, without first estimates. A loop
    that is asymmetric or whose centre line bends is then taken up by the effect's richer block
    rather than left to another effect (a static map)."""
    return [replace(cand, block=name, parameters={}, settings={}) for name in _other_blocks(cand.effect, cand.block)]


def _trial(model, cand, split, max_step, limits) -> tuple:
    """``model`` with ``cand``'s block inserted and fitted: (held-out RMSE, cand, model, the block)."""
    block = new_block(cand, model.dt, max_step)
    fitted = _fit(insert(model, block), split, limits)
    new = [b for b in fitted.blocks if type(b) is type(block) and b.name == block.name]
    return _heldout(fitted, split), cand, fitted, new[-1] if new else block


def _try_candidates(model, cands, split, rmse, accept, max_tries, ambiguity, max_step,
                    limits):
    """Fit candidate blocks in score order; the first family that passes the held-out test wins.
    Look-alikes of other families (see :func:`_alike`) are fitted with it, and the best held-out
    of them is the one judged. Each that fails the held-out test is also fitted with its
    :func:`alternatives` (not counted in ``max_tries``), and the first of them that passes
    stands for it."""
    tried = 0
    families_done: set[str] = set()
    for cand in cands:
        if cand.family in families_done or tried >= max_tries:
            continue
        group = [c for c in cands if c.family == cand.family and c.score >= ambiguity * cand.score]
        alike = {}
        for c in cands:
            if c.family not in families_done | {cand.family} | set(alike) and _alike(c, cand, ambiguity):
                alike[c.family] = c
        group += list(alike.values())
        families_done |= {cand.family, *alike}
        group = group[: max(1, max_tries - tried)]
        tried += len(group)
        trials, fits = [], []
        for c in group:
            trial = _trial(model, c, split, max_step, limits)
            fits.append(trial)
            # the signature's block (with its first estimates) unless it fails the held-out test
            # and an alternative passes it (a richer block taken whenever it fits a bit better
            # takes up a second effect: GPI's plays a backlash, its envelope a bend)
            if not accept(model, trial[2]):
                for alt in alternatives(c):
                    fits.append(_trial(model, alt, split, max_step, limits))
                    if accept(model, fits[-1][2]):
                        trial = fits[-1]
                        break
            trials.append(trial)
        after, c, fitted, block = min(trials, key=lambda t: t[0])
        if accept(model, fitted):
            fitted_params = block.summary(model.dt)
            desc = _describe(c, block, model.dt)
            return fitted, Step(effect=c.effect, block=c.block, rmse_before=rmse, rmse_after=after,
                                train_rmse_before=_train(model, split),
                                train_rmse_after=_train(fitted, split),
                                parameters=fitted_params, first_estimate=dict(c.parameters),
                                description=desc, spec_after=fitted.spec,
                                candidates=[x.to_dict() for x in cands],
                                tried=[{"effect": t[1].effect, "block": t[1].block, "rmse_after": t[0]}
                                       for t in fits])
    return None


def _without(model: Series, effect: str) -> Series:
    at = max(k for k, b in enumerate(model.blocks) if b.effect == effect)
    return Series(*copy.deepcopy(model.blocks[:at] + model.blocks[at + 1:]), dt=model.dt)


#: Signature families whose shapes a richer block of another effect may take up: memoryless
#: and reversal shapes (GPI's envelope is a static map, its plays are reversals), not a lag's,
#: a delay's, a drift's or a creep's time scales.
ABSORBABLE = ("static", "reversal")


def _richer(model: Series, removed: str, max_step: float) -> list[Series]:
    """``model`` with one of its blocks swapped for an :func:`alternatives` block of its effect
    (GPI for Bouc-Wen), started from that block's defaults: one per swap; none when the
    ``removed`` effect's family is not :data:`ABSORBABLE`."""
    if FAMILY_OF.get(removed) not in ABSORBABLE:
        return []
    out = []
    for at, b in enumerate(model.blocks):
        for name in _other_blocks(b.effect, b.name) if b.effect else ():
            blocks = list(copy.deepcopy(model.blocks))
            blocks[at] = new_block(Candidate(b.effect, 0.0, 0.0, name), model.dt, max_step)
            out.append(Series(*blocks, dt=model.dt))
    return out


def _prune(model, steps, split, accept, limits, say, max_step=0.0):
    """Drop named effects that the final model does not need (backward elimination, one block at a
    time): a block goes only when the model without it, re-fitted, is not clearly beaten by the
    model with it *and* its held-out error, recomputed, stays within ``margin`` of the current one.
    The model without it is also tried with another effect's block swapped for that effect's
    richer block (:func:`_richer`), and the best held-out of these is the one judged: a bend
    that a static map took up beside Bouc-Wen is one loop for GPI's envelope, one effect not two."""
    steps = list(steps)
    for i in reversed(range(len(steps))):
        effect = steps[i].effect
        if effect not in present_effects(model):
            continue
        now = _heldout(model, split)

        def goes(reduced):
            return not accept(reduced, model) and _heldout(reduced, split) <= now * (1 + accept.margin)

        without_it = _without(model, effect)
        reduced = _fit(without_it, split, limits)
        drop = goes(reduced)
        richer = [] if drop else [_fit(m, split, limits) for m in _richer(without_it, effect, max_step)]
        if richer:
            reduced = min(richer, key=lambda m: _heldout(m, split))
            drop = goes(reduced)
        if drop:
            say(f"removed: {effect} (held-out RMSE {now:.3g} -> {_heldout(reduced, split):.3g} "
                f"without it, as '{reduced.spec}')")
            steps[i] = replace(steps[i], removed=True)
            blocks = {b.effect: b.name for b in reduced.blocks if b.effect}
            steps = [replace(s, block=blocks[s.effect]) if not s.removed and s.effect in blocks else s
                     for s in steps]
            model = reduced
    return model, steps


def _revise(model, steps, split, accept, max_step, limits, say):
    """Swap a named effect for its sibling where that fits the held-out data clearly better (the
    test a new block passes, ``accept``): the diagnosis named it first, a sibling that is only a
    little better held out (a delay for a lag behind a hysteresis' phase) does not overturn it."""
    steps = list(steps)
    for i, step in enumerate(steps):
        sib = SIBLING.get(step.effect)
        present = present_effects(model)
        if step.removed or sib is None or sib in present or step.effect not in present:
            continue
        reduced = _fit(_without(model, step.effect), split, limits)
        others = set(EFFECTS) - {sib}
        cands = diagnose(residual_traces(reduced, split.train), noise_std=accept.floor, exclude=others,
                         threshold=0.0, min_score=0.0)
        if not cands:
            continue
        block = new_block(cands[0], model.dt, max_step)
        alt = _fit(insert(reduced, block), split, limits)
        now, then = _heldout(model, split), _heldout(alt, split)
        if accept(model, alt):
            new = [b for b in alt.blocks if b.name == block.name][-1]
            params = new.summary(model.dt)
            desc = _describe(cands[0], new, model.dt)
            say(f"revised: {step.effect} -> {desc}; RMSE {now:.3g} -> {then:.3g}")
            steps[i] = replace(step, effect=sib, block=cands[0].block, parameters=params,
                               first_estimate=dict(cands[0].parameters), description=desc,
                               revised_from=step.effect)
            model = alt
    return model, steps


def _describe(c: Candidate, block, dt: float) -> str:
    words = block.describe(dt)
    return f"{c.effect}, {words}" if words else c.effect


__all__ = ["discover", "residual_traces", "split_runs", "insert", "new_block", "EFFECTS", "BLOCK_OF"]
