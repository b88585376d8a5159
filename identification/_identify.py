"""Fit a physics model's parameters to measured trajectories with IPOPT (CasADi)."""

from __future__ import annotations

import copy
import functools
import time
from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from physics import AbstractBlock, Series
from physics.data import DataError
from physics.data.io import raise_if_pressed, recording

from . import _lsq
from ._at_once import AtOnce
from ._checks import (Record, check_fixed, check_model, check_trajectories, check_x0, data_scales,
                      settings_or_default)
from ._covariance import standard_errors
from ._errors import IdentificationError
from ._initial import affine_indices, initial_guess, line_fit, perturbed
from ._nested import embed
from ._noise import noise_floor
from ._problem import LeastSquaresProblem, Solve, WarmStart
from ._ranking import Ranking
from ._result import FitResult, pooled_rmse
from ._solver_settings import SolverSettings

#: Smallest typical magnitude used to scale a parameter, as a share of its magnitude for the
#: data's signal scales (``Series.signal_scales``).
SCALE_FLOOR = 1e-2


def _interruptible(fn):
    """Ctrl-C during ``fn`` stops it after the solve in progress (KeyboardInterrupt), results untouched."""
    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        with recording():
            return fn(*args, **kwargs)
    return wrapper


#: An output whose level lies more than this many times its spread's decade from zero has its
#: offset bounded around, and solved for from, that level (``_offset_centre``).
FAR_LEVEL = 100.0


def _offset_centre(model: Series, records, s_u: float, s_y: float) -> np.ndarray:
    """Per parameter, the level its window and its steps are measured from: 0, except a location
    where the signal it sits on lies far from 0 (more than ``FAR_LEVEL`` times its spread's decade):
    an affine block's offset is measured from the data's level (the straight line's offset through
    them), and a location on the input axis (``Parameter.location``, e.g. ``gpi.center``) of a block
    before the output map from the middle of the input's range.

    Bounds and steps follow the decade of the signals' spread, so an output of 30 mm that moves
    by micrometres would bound its offset to a fraction of a millimetre, and solving for it as a
    multiple of 30 would ask for eleven digits: it is solved for as its distance from that level.
    Likewise an input in motor steps (1360-2801) puts an envelope's centre near 2000 steps, where
    IPOPT would move it by thousandths of itself: it is solved for as its distance from ~2080.
    """
    centre = np.zeros(model.n_p)
    level = line_fit(records)[1]
    if abs(level) > FAR_LEVEL * s_y:
        for _, _, io in affine_indices(model):
            centre[io] = level
    u = np.concatenate([r.u for r in records])
    u_level = 0.5 * float(u.min() + u.max())
    if abs(u_level) > FAR_LEVEL * s_u:
        k = 0
        for b in model.blocks:
            if b.affine_output is not None:
                break  # the output map leaves the input's units
            for i, par in enumerate(b.parameters):
                if par.location:
                    centre[k + i] = u_level
            k += b.n_p
    return centre


def _typical(p_init: np.ndarray, centre: np.ndarray, factors: np.ndarray, model: Series) -> np.ndarray:
    """Each parameter's typical magnitude (IPOPT solves for ``(p - centre) / typical``): its distance
    from ``centre`` at the start, at least ``SCALE_FLOOR`` of its magnitude for the data's scales; a
    location measured from the input's level, at least that magnitude (it starts at 0 from there)."""
    floor = SCALE_FLOOR * factors
    located = np.array([par.location for b in model.blocks for par in b.parameters], dtype=bool) & (centre != 0)
    floor[located] = factors[located]
    return np.maximum(np.abs(p_init - centre), floor)


@_interruptible
def identify(model: Series | str, trajectories, *, fixed=None, free=None, x0="steady", warmup: int = 0,
             starts: int | None = None, seed: int = 0, nested=(), guesses=(), allow_failure: bool = False,
             solver: SolverSettings | None = None) -> FitResult:
    """Fit the parameters of ``model`` to one or many trajectories.

    Output-error least squares by single shooting: each trajectory is
    simulated from its initial state by the model's own CasADi rollout, and
    IPOPT minimises the mean squared output error over the free parameters
    within the blocks' bounds and constraints (Gauss-Newton Hessian from
    forward sensitivities). ``preisach+linear`` is solved exactly as a bounded
    linear least-squares problem instead (the output is linear in the weights).

    Parameters
    ----------
    model : physics.Series or str
        The model (its current parameter values are used for held parameters)
        or a spec such as ``"lag+boucwen+linear"`` (25 Hz).
    trajectories : trajectory or sequence of trajectories
        Objects with 1-D ``u`` and ``y`` arrays sampled at the model's rate
        (``hybrid.data.Trajectory``); a ``time`` array or ``meta["rate_hz"]``,
        when present, is checked against the model's rate.
    fixed : dict of str to float, or list of str, optional
        Parameters to hold: name -> value, or names held at the model's
        current values. Parameters whose block holds them by default
        (``model.fit_mask`` False, e.g. ``boucwen.n``) are held too.
    free : list of str, optional
        Parameters to fit although their block holds them by default.
    x0 : {"steady", "estimate"} or array
        Initial states: the steady state at each trajectory's first input, or
        estimated with the parameters, or given ((n_x,) or (n_traj, n_x)).
    warmup : int
        With ``K > 0``, each trajectory's first ``K`` samples set its state and the error of the
        samples after them is minimised: the state is the window fit of
        :meth:`Series.estimate_state` as a function of the parameters, the rule ``score_model``,
        the model card and ``predict(..., warmup=...)`` score and run every model with, so the fit
        minimises the error that is scored and ``train_rmse`` is that error. Needs ``x0="steady"``.
    starts : int, optional
        Number of starts: the physics-based guess, then random points near it
        (seeded by ``seed``, within the bounds). The best converged one is kept.
        None (the default): multi-start where the spec is prone to local minima,
        ``max(block.starts)`` starts (3 with a lag, backlash or Bouc-Wen block, else 1);
        the extra starts are skipped when the first already fits down to the data's own noise
        (train RMSE within 10 % of :func:`noise_floor` of the outputs), so a fit that cannot
        improve costs one start; otherwise each runs a tenth of ``max_iter`` and continues
        with the full budget only if it is then below the first start (another basin).
        Deterministic: the same data and ``seed`` give the same fit.
    allow_failure : bool
        Return a result flagged ``success=False`` instead of raising when no
        start converged.
    solver : SolverSettings, optional
        How IPOPT solves it: the method (single shooting), ``max_iter`` per start (default 3000:
        the limit that decides the answer, the same on any machine), an optional ``max_wall_time``
        safeguard, extra ``ipopt_options``, ``jit`` and ``verbose``
        (:class:`~identification.SolverSettings`; default ``SolverSettings()``).
    nested : sequence of FitResult or physics.Series, optional
        Fitted simpler models nested in ``model`` (its blocks in the same order, the others
        able to pass their input through: :func:`identification._nested.is_nested`). Each is
        a point of ``model``'s parameter space (the extra blocks at their identity) that
        simulates as it does: when the fit ends above the best of them, IPOPT starts again
        from that point, and if it still ends above, the result is that point, with status
        ``Nested_Start_Kept`` (a richer model never fits worse than a simpler one it contains).
    guesses : sequence of dict, optional
        Parameter values of this spec (name -> value) found elsewhere, e.g. its fits on subsets of
        these runs (``Selection.fold_parameters``: a fit on fewer runs can land in a better basin
        than every start on all of them). Each is scored on these runs; where the fit ends above
        the best of them, IPOPT starts again from it, as from a ``nested`` point.

    Returns
    -------
    FitResult

    Raises
    ------
    IdentificationError
        Bad data, unknown parameter names, too few samples, or (unless
        ``allow_failure``) no start converged.

    Notes
    -----
    FINDINGS measured multiple shooting to be slower here unless the graph is
    expanded (7-13 s to build) and to fall into restoration from poor guesses;
    single shooting with good initial guesses converged in 10-20 iterations.
    """
    t0 = time.perf_counter()
    solver = _check_solver(solver)
    model = check_model(model)
    records = check_trajectories(trajectories, model.dt)
    rest, windows = _windows(records, warmup, x0)  # checked before any work
    from_rest = None
    if windows:  # the fit from rest first: smooth in the parameters, it starts the window-scored fit near its optimum
        from_rest = identify(model, trajectories, fixed=fixed, free=free, starts=starts, seed=seed, nested=nested,
                             guesses=guesses, allow_failure=True, solver=solver)
    s_u, s_y = data_scales(records)
    u_all = np.concatenate([r.u for r in records])
    model = model.for_scales(s_u, s_y, (float(u_all.min()), float(u_all.max())))
    model = _input_ranges(model)  # measured afresh after this fit
    factors, state_factors = model.signal_scales(s_u, s_y)
    centre = _offset_centre(model, records, s_u, s_y)
    lo, hi = centre + model.lower_bounds * factors, centre + model.upper_bounds * factors  # in the data's units
    mask, held = check_fixed(model, fixed, free, (lo, hi))
    x0 = check_x0(x0, model, len(records))
    records = rest
    auto = starts is None
    starts = max([b.starts for b in model.blocks] + [1]) if auto else starts
    _check_starts(starts)
    max_wall_time, verbose, jit = solver.max_wall_time, solver.verbose, solver.jit
    names = model.param_names
    p_base = model.params.copy()
    for name, value in held.items():
        p_base[names.index(name)] = value
    n_decision = int(mask.sum()) + (len(records) * model.n_x if isinstance(x0, str)
                                    and x0 == "estimate" else 0)
    n_samples = sum(r.n for r in records)
    if n_samples <= n_decision:
        raise IdentificationError(
            f"Too few samples: {n_samples} for {n_decision} unknowns; give longer or more "
            "trajectories, or fix some parameters.")
    if _lsq.applies(model, mask, x0) and not windows:
        return _lsq_honest(model, _fit_linear(model, records, held, mask, t0), records, allow_failure)

    p_init = initial_guess(model, records, mask, p_base, (lo, hi)) if mask.any() else p_base
    if windows:
        if np.isfinite(from_rest.train_rmse):
            p_init = np.clip(np.where(mask, [from_rest.parameters[n] for n in names], p_init), lo, hi)
        x0 = _warm_start(model, windows, u_all, p_init)
    scale = _typical(p_init, centre, factors, model)
    problem = LeastSquaresProblem(model, records, mask, p_init, scale, x0, jit, bounds=(lo, hi),
                                  state_scale=state_factors, shift=centre)
    from_nested = _nested_points(problem, model, nested) + _guess_points(problem, model, guesses)  # checked first
    rng = np.random.default_rng(seed)
    candidates = [p_init] + [centre + perturbed(p_init - centre, mask, lo - centre, hi - centre, rng, factors)
                             for _ in range(starts - 1)]
    options = solver.options()
    threads = 1 if max_wall_time is not None or verbose else solver.threads  # a wall-time limit runs them in turn
    if auto and starts > 1 and threads > 1:
        solves = _multi_start_at_once(problem, candidates, records, threads, options)
    elif auto and starts > 1:  # the extra starts only where the first leaves room above the noise
        solves = _run_starts(problem, candidates[:1], t0, max_wall_time, verbose, options)
        if not _at_noise(solves[0], records):
            solves += _probe(problem, candidates[1:], solves[0], t0, max_wall_time, verbose, options)
    elif threads > 1 and len(candidates) > 1:
        with AtOnce(problem, threads) as pool:
            solves = _read([pool.submit(c, options) for c in candidates])
    else:
        solves = _run_starts(problem, candidates, t0, max_wall_time, verbose, options)
    best = _best(solves)
    best, solves = _from_nested(problem, from_nested, best, solves, (t0, max_wall_time, verbose, options))
    nested, nested_cost, nested_name = _nested(model, records, mask, p_init, (lo, hi))
    if nested is not None and _worse(best, nested_cost):  # start again from the simpler model's optimum
        solves += _run_starts(problem, [nested], t0, max_wall_time, verbose, options)
        best = _best(solves)
    if not best.success and not allow_failure:
        raise IdentificationError(
            f"IPOPT did not converge for '{model.spec}': status {best.status} after "
            f"{best.iterations} iterations (best of {len(solves)} start(s)). Try more starts, "
            "fix poorly determined parameters, raise the budget (solver=SolverSettings(max_iter=...)), or pass "
            "allow_failure=True "
            "to inspect the result.")
    best, why = _honest(model, best, nested_cost, nested_name)
    if why and not allow_failure:
        raise IdentificationError(why)
    result = _result(model, problem, best, solves, held, p_init, t0)
    return _scored(result, records, windows) if windows else result


def _windows(records, warmup, x0) -> tuple[list, list]:
    """``(records after their windows, windows)``; ``(records, [])`` without a warm-up."""
    if isinstance(warmup, bool) or not isinstance(warmup, (int, np.integer)) or warmup < 0:
        raise IdentificationError(f"warmup must be a whole number of samples >= 0. Got {warmup!r} instead.")
    k = int(warmup)
    if not k:
        return records, []
    if not (isinstance(x0, str) and x0 == "steady"):
        raise IdentificationError("Give x0 or a warm-up window, not both: the window sets each run's state.")
    short = [r for r in records if r.n <= k + 1]
    if short:
        raise IdentificationError(f"A warm-up of {k} samples leaves too little of trajectory {short[0].name!r} "
                                  f"({short[0].n} samples) to fit; give a shorter warm-up.")
    return ([Record(r.u[k:], r.y[k:], r.name) for r in records],
            [(np.asarray(r.u[:k], dtype=float), np.asarray(r.y[:k], dtype=float)) for r in records])


def _warm_start(model: Series, windows, u_all, p) -> WarmStart:
    """The window fits' scales as :meth:`Series.estimate_state` of the fitted model takes them: on the
    training inputs' range, at the first guess."""
    from physics._warmup import scales

    ranged = Series(*model.blocks, dt=model.dt, input_range=(float(u_all.min()), float(u_all.max())))
    return WarmStart([(u_w, y_w, *scales(ranged, u_w, y_w, p)) for u_w, y_w in windows])


def _scored(result: FitResult, records, windows) -> FitResult:
    """``result`` with its training errors as they are scored: the fitted model run from each window's
    estimated state (the optimiser's state fit took its scales at the first guess, the scorer at the fit)."""
    model = result.model()
    errors = [model.simulate(r.u, warmup=w) - r.y for r, w in zip(records, windows)]
    pooled, per = pooled_rmse(errors)
    return replace(result, train_rmse=pooled, train_rmse_per_trajectory=per)


def _nested_points(problem, model: Series, nested) -> list[tuple]:
    """``(cost, w, success, spec)`` of each nested fit embedded in ``model`` (see :func:`identify`)."""
    points = []
    for simple in nested:
        simple_model = simple.model() if isinstance(simple, FitResult) else simple
        if not isinstance(simple_model, Series):
            raise IdentificationError(f"nested takes fitted simpler models (FitResult or physics.Series); "
                                      f"got {type(simple).__name__}.")
        points.append(_point(problem, embed(model, simple_model), bool(getattr(simple, "success", True)),
                             simple_model.spec))
    return points


def _point(problem, values: np.ndarray, success: bool, spec: str) -> tuple:
    """``(cost, w, success, spec)`` of a parameter vector: held parameters keep their values, the
    others are clipped to their bounds."""
    w = problem.scaled(np.clip(np.where(problem.free, values, problem.p_base), problem.lower, problem.upper))
    return problem.cost(w), w, success, spec


def _guess_points(problem, model: Series, guesses) -> list[tuple]:
    """``(cost, w, success, spec)`` of each parameter guess (see :func:`identify`)."""
    points, names = [], model.param_names
    for guess in guesses:
        unknown = sorted(set(guess) - set(names)) if isinstance(guess, dict) else None
        if unknown is None or unknown:
            raise IdentificationError(f"guesses take dicts of '{model.spec}' parameter values (name -> value); got "
                                      + (f"unknown names {unknown}." if unknown else f"{type(guess).__name__}."))
        values = np.array([float(guess.get(n, b)) for n, b in zip(names, problem.p_base)])
        points.append(_point(problem, values, True, model.spec))
    return points


def _from_nested(problem, points, best, solves, run):
    """The best solve, never above the best of the nested fits' points."""
    if not points:
        return best, solves
    cost, w, ok, _ = min(points, key=lambda t: t[0] if np.isfinite(t[0]) else np.inf)
    if not (np.isfinite(cost) and _worse(best, cost)):
        return best, solves
    t0, max_wall_time, verbose, options = run
    solves = solves + _run_starts(problem, [problem.params(w)], t0, max_wall_time, verbose, options)
    best = _best(solves)
    if _worse(best, cost):  # IPOPT left the simpler model's optimum for a worse point: keep that optimum
        best = Solve(w, cost, "Nested_Start_Kept", ok, 0, 0.0)
        solves = solves + [best]
    return best, solves


def _nested(model: Series, records, mask, p_init, bounds):
    """The start at the nested simpler model (every block passing its input through, the affine
    output map fitted by least squares) and that model's cost; ``None`` when a block has no
    pass-through values or they are held elsewhere. Costs are mean squared errors over Var(y)."""
    u = np.concatenate([r.u for r in records])
    y = np.concatenate([r.y for r in records])
    var = float(np.var(y)) or 1.0
    affine = [b for b in model.blocks if b.affine_output is not None]
    if len(affine) != 1 or any(b.identity is None for b in model.blocks if b is not affine[0]):
        return None, 1.0, "the data's mean"
    a, c = line_fit(records)
    p, k = np.array(p_init, dtype=float), 0
    for b in model.blocks:
        own = {par.name: k + i for i, par in enumerate(b.parameters)}
        values = dict(zip(b.affine_output, (a, c))) if b is affine[0] else dict(b.identity)
        for name, value in values.items():
            j = own[name]
            if not mask[j] and not np.isclose(p[j], value):
                return None, 1.0, "the data's mean"  # held away from it: not nested
            p[j] = value
        k += b.n_p
    lo, hi = bounds
    return np.clip(p, lo, hi), float(np.mean((y - a * u - c) ** 2)) / var, f"'{affine[0].name}' alone"


#: A first start whose train RMSE is within this factor of the data's noise floor needs no more.
AT_NOISE = 1.1


def _at_noise(solve, records) -> bool:
    """Did ``solve`` converge to a train RMSE within ``AT_NOISE`` of the outputs' noise floor?"""
    if not (solve.success and np.isfinite(solve.cost)):
        return False
    var = float(np.var(np.concatenate([r.y for r in records]))) or 1.0
    floor = noise_floor([r.y for r in records])
    return bool(np.sqrt(solve.cost * var) <= AT_NOISE * floor)


def _worse(solve, cost: float) -> bool:
    """True when ``solve`` ends above ``cost`` (relative MSE) by more than rounding."""
    return not solve.cost <= cost * (1 + 1e-3) + 1e-12


def _honest(model: Series, best, nested_cost: float, nested_name: str):
    """``best``, marked failed (with the reason) when it fits worse than the nested simpler model
    or than the data's mean: a model that contains them never should."""
    limit, what = min(1.0, nested_cost), nested_name if nested_cost < 1.0 else "the data's mean"
    if not _worse(best, limit):
        return best, ""
    hint = (f"the spec has no output map (its output is in the input's units): add '+linear' ('{model.spec}+linear')"
            if not any(b.affine_output for b in model.blocks)
            else "try more starts (starts=5) or fix poorly determined parameters")
    why = (f"The fit of '{model.spec}' is worse than {what} (relative MSE {best.cost:.3g} > {limit:.3g}), "
           f"which it contains; {hint}. Pass allow_failure=True to inspect it.")
    return replace(best, success=False, status="Worse_Than_Nested_Model"), why


def _lsq_honest(model: Series, fit: FitResult, records, allow_failure: bool) -> FitResult:
    """The exact weights fit, failed when worse than the data's mean (relays that never switch:
    a threshold range away from the data's)."""
    var = float(np.var(np.concatenate([r.y for r in records]))) or 1.0
    if fit.train_rmse**2 <= var * (1 + 1e-3) + 1e-300:
        return fit
    why = (f"The fit of '{model.spec}' is worse than the data's mean (relative MSE "
           f"{fit.train_rmse**2 / var:.3g} > 1): its relays hardly switch on this input; leave the "
           "Preisach range to the data (lower=None, upper=None) or set it to the input's range.")
    if not allow_failure:
        raise IdentificationError(why)
    return replace(fit, success=False, status="Worse_Than_Nested_Model")


def fitted_series(physics, trajectories, dt: float, identify_options: dict | None = None,
                  failed: dict[str, str] | None = None, guesses: dict[str, Sequence[dict]] | None = None):
    """The physics model a hybrid uses, and its fit: a spec string is identified on
    ``trajectories``; a sequence of specs is tried in order and the first that fits is used
    (the others' failures are in the error if none does, and in ``failed``, spec -> reason,
    when given); a :class:`FitResult` gives its fitted model; a ``Series`` is used as given
    (a copy); a :class:`Ranking` (a ``Selection`` of ``select_physics``) tries its ranked specs. Each
    spec's fit starts also from its ``guesses`` (spec -> parameter sets; a Ranking's default: its
    ``fold_parameters``, the fits on the folds). Returns ``(series, fit_result_or_None)``."""
    if isinstance(physics, Ranking):
        guesses = physics.fold_parameters if guesses is None else guesses
        physics = physics.ranked()
    guesses = {} if guesses is None else guesses
    if isinstance(physics, (list, tuple)) and physics and all(isinstance(p, str) for p in physics):
        failed = {} if failed is None else failed
        for spec in physics:
            names = set(Series.from_spec(spec).param_names)  # the options' own guesses that are this spec's
            options = {**(identify_options or {})}
            options["guesses"] = [g for g in options.get("guesses", ()) if set(g) <= names]
            try:
                return fitted_series(spec, trajectories, dt, options, guesses=guesses)
            except IdentificationError as exc:
                failed[spec] = str(exc)
        raise IdentificationError("No physics spec could be fitted:\n  "
                                  + "\n  ".join(f"'{k}': {v}" for k, v in failed.items()))
    if isinstance(physics, str):
        options = {**(identify_options or {})}
        options["guesses"] = [*options.get("guesses", ()), *guesses.get(physics, ())]
        fit = identify(Series.from_spec(physics, dt=dt), list(trajectories), **options)
        return fit.model(), fit
    if isinstance(physics, FitResult):
        return physics.model(), physics
    if isinstance(physics, Series):
        return copy.deepcopy(physics), None
    raise DataError(f"physics must be a spec string such as 'backlash+boucwen+linear' (or a list of them, tried "
                    f"in order), a Ranking (identification.discovery.Selection), a physics.Series or an "
                    f"identification.FitResult; got {type(physics).__name__}.")


def _check_starts(starts) -> None:
    if not isinstance(starts, (int, np.integer)) or starts < 1:
        raise IdentificationError(f"starts must be a whole number >= 1. Got {starts!r} instead.")


def _check_solver(solver) -> SolverSettings:
    return settings_or_default(solver, SolverSettings, "solver", "SolverSettings(max_iter=300)")


def _run_starts(problem, candidates, t0, max_wall_time, verbose, options) -> list[Solve]:
    """One IPOPT solve per candidate; with ``max_wall_time`` (a safeguard) the starts it leaves no
    time for are skipped. A Ctrl-C recorded meanwhile raises KeyboardInterrupt before the next one."""
    solves, solver, budget = [], None, None
    for cand in candidates:
        raise_if_pressed()
        if max_wall_time is None:  # iterations decide: every start runs
            solver = solver or problem.solver(None, verbose, options)
        else:
            remaining = max_wall_time - (time.perf_counter() - t0)
            if remaining <= 0.05:
                break
            if solver is None or remaining < 0.9 * budget:  # IPOPT's limit is per solve
                solver, budget = problem.solver(remaining, verbose, options), remaining
        solves.append(problem.solve(solver, problem.scaled(cand)))
    raise_if_pressed()
    if not solves:
        raise IdentificationError(
            f"max_wall_time ({max_wall_time} s) was spent before IPOPT could start; raise it.")
    return solves


#: Share of ``max_iter`` an extra start of the default multi-start runs before it is either
#: dropped or, when already below the first start's cost, continued with the full budget.
PROBE_SHARE = 0.1


def _probe(problem, candidates, first: Solve, t0, max_wall_time, verbose, options) -> list[Solve]:
    """The extra starts of the default multi-start: each runs ``PROBE_SHARE`` of the iteration
    budget; one that ends below ``first`` (another basin) continues from there with the full
    budget. A slow fit (thousands of iterations in a flat valley) then costs little more than
    one start, and the result stays the same on any machine."""
    short = _short(options)
    out = []
    for cand in candidates:
        probe = _run_starts(problem, [cand], t0, max_wall_time, verbose, short)
        out += probe
        if probe and _continues(probe[0], first):
            out += _run_starts(problem, [problem.params(probe[0].w)], t0, max_wall_time, verbose, options)
    return out


def _multi_start_at_once(problem, candidates, records, threads: int, options) -> list[Solve]:
    """The default multi-start (the first start, then :func:`_probe`'s) with its starts solved at once:
    the probes run beside the first and are dropped (cancelled) where it ends at the noise; those that
    end below it then continue together. The same solves, in the same order, as one after another."""
    short = _short(options)
    with AtOnce(problem, threads) as pool:
        first = pool.submit(candidates[0], options)
        probes = [pool.submit(c, short) for c in candidates[1:]]
        first = _read([first])[0]
        if _at_noise(first, records):
            return [first]
        probes = _read(probes)
        more = [pool.submit(problem.params(p.w), options) if _continues(p, first) else None for p in probes]
        out = [first]
        for probe, after in zip(probes, more):
            out += [probe] + ([] if after is None else _read([after]))
    return out


def _read(futures) -> list[Solve]:
    """The solves of ``futures`` in order; a Ctrl-C recorded meanwhile raises KeyboardInterrupt."""
    out = [f.result() for f in futures]
    raise_if_pressed()
    return out


def _short(options: dict) -> dict:
    """A probe's options: ``PROBE_SHARE`` of the iteration budget."""
    return {**options, "max_iter": max(1, int(options["max_iter"] * PROBE_SHARE))}


def _continues(probe: Solve, first: Solve) -> bool:
    """A probe that ended below the first start without converging (another basin) goes on."""
    return bool(np.isfinite(probe.cost) and probe.cost < first.cost and not probe.success)


def _best(solves: list[Solve]) -> Solve:
    ok = [s for s in solves if s.success]
    pool = ok or [s for s in solves if np.isfinite(s.cost)] or solves
    return min(pool, key=lambda s: s.cost if np.isfinite(s.cost) else np.inf)


def _split_residuals(r: np.ndarray, records) -> list[np.ndarray]:
    return np.split(r, np.cumsum([rec.n for rec in records])[:-1])


def _result(model, problem: LeastSquaresProblem, best: Solve, solves, held, p_init, t0):
    names = model.param_names
    p = problem.params(best.w)
    r, J = (np.asarray(v, dtype=float) for v in problem.residuals(best.w))
    r = r.ravel()
    A_eq = None
    if problem.g.numel():
        eq = problem.lbg == problem.ubg
        A_eq = np.asarray(problem.g_jac(best.w), dtype=float)[eq] if eq.any() else None
    lo, hi = problem.bounds()
    tol = 1e-7 * np.maximum(1.0, np.abs(best.w))
    active = (best.w - lo <= tol) | (hi - best.w <= tol)
    se_w, singular = standard_errors(J, r, A_eq, active)
    free_idx = np.flatnonzero(problem.free)
    se = {names[k]: float(se_w[j] * problem.scale[k]) for j, k in enumerate(free_idx)}
    at_bounds = tuple(names[k] for j, k in enumerate(free_idx) if active[j])
    pooled, per = pooled_rmse(_split_residuals(r, problem.records))
    x0s = problem.initial_states(best.w)
    return _make_result(model, p, p_init, tuple(tuple(map(float, x)) for x in x0s), problem.records, t0,
                        standard_errors=se, fixed=held, train_rmse=pooled, train_rmse_per_trajectory=per,
                        status=best.status, success=best.success, iterations=best.iterations, n_samples=len(r),
                        n_trajectories=len(problem.records), method="single", noise_std=_noise(r, best.w.size),
                        covariance_singular=singular, at_bounds=at_bounds,
                        starts=tuple({"status": s.status, "cost": s.cost, "iterations": s.iterations,
                                      "wall_time_s": s.wall_time_s, "best": s is best} for s in solves))


def _noise(r: np.ndarray, k: int) -> float:
    return float(np.sqrt(r @ r / max(r.size - k, 1)))


def _input_ranges(model: Series, records=None, x0s=None) -> Series:
    """``model`` with the range of its input on ``records`` (``Series.input_range``) and each block
    told the range its own input had there from the fit's initial states ``x0s``
    (``AbstractBlock.for_input_range``: a fitted ``poly`` continues along its tangent beyond it);
    without records, or where a block's input is not finite, the ranges are cleared (a model
    fitted again measures them afresh)."""
    blocks = list(model.blocks)
    u = None if records is None else np.concatenate([np.asarray(r.u, dtype=float) for r in records])
    for i, b in enumerate(blocks):
        if type(b).for_input_range is AbstractBlock.for_input_range:
            continue
        seen = np.array([np.nan])
        if records is not None:
            prefix = Series(*blocks[:i], dt=model.dt) if i else None
            seen = np.concatenate([prefix.simulate(r.u, x0=np.asarray(x0, dtype=float)[:prefix.n_x]) if prefix
                                   else np.asarray(r.u, dtype=float) for r, x0 in zip(records, x0s)])
        blocks[i] = (b.for_input_range(float(seen.min()), float(seen.max())) if np.all(np.isfinite(seen))
                     else b.for_input_range(None, None))
    return Series(*blocks, dt=model.dt, input_range=None if u is None else (float(u.min()), float(u.max())))


def _make_result(model, p, p_init, x0s, records, t0, *, fixed, success, iterations, **fields) -> FitResult:
    """The :class:`FitResult` of parameters ``p`` of ``model``, started at ``p_init`` from the states ``x0s``
    on ``records`` (``t0``: when the fit began). ``fields`` are FitResult's own, by name (``standard_errors``,
    ``train_rmse``, ``status``, ...); the spec, units, parameters and the fitted model with the ranges its
    blocks' inputs had on the records are filled in here."""
    names = model.param_names
    units = dict(zip(names, (par.unit for b in model.blocks for par in b.parameters)))
    fitted = copy.deepcopy(model)
    fitted.params = p
    fitted = _input_ranges(fitted, records, x0s)
    return FitResult(
        spec=model.spec, dt=model.dt, parameters=dict(zip(names, map(float, p))), units=units,
        fixed=dict(fixed), success=bool(success), iterations=int(iterations), wall_time_s=time.perf_counter() - t0,
        initial_parameters=dict(zip(names, map(float, p_init))), initial_states=x0s, fitted_model=fitted, **fields)


def _fit_linear(model, records, held, mask, t0) -> FitResult:
    p, r, J, info = _lsq.fit(model, records)
    names = model.param_names
    lo, hi = model.lower_bounds, model.upper_bounds
    active = (p - lo <= 1e-9) | (hi - p <= 1e-9)
    active[-2:] = False
    A_eq = np.r_[np.ones(len(p) - 2), 0.0, 0.0][None, :]
    se_v, singular = standard_errors(J, r, A_eq, active)
    se = dict(zip(names, map(float, se_v)))
    pooled, per = pooled_rmse(_split_residuals(r, records))
    x0s = tuple(tuple(map(float, model.steady_state(rec.u[0], p))) for rec in records)
    start = {"status": info["status"], "cost": float(r @ r) / len(r),
             "iterations": info["iterations"], "wall_time_s": info["wall_time_s"], "best": True}
    return _make_result(model, p, p, x0s, records, t0, standard_errors=se, fixed=held, train_rmse=pooled,
                        train_rmse_per_trajectory=per, status=info["status"], success=info["success"],
                        iterations=info["iterations"], n_samples=len(r), n_trajectories=len(records), method="lsq",
                        noise_std=_noise(r, len(p) - 1), covariance_singular=singular,
                        at_bounds=tuple(n for n, a in zip(names, active) if a), starts=(start,))
