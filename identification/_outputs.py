"""Identification of a model with several outputs that one chain of blocks drives (the tip's angle and
its position from one tendon): :func:`identify_outputs`.

Two stages. First the chain alone, through :func:`identify` (its starts, grids and multi-start): on
the angle where the model's last block is an :class:`~physics.Arc` that outputs it, else on the
outputs' first principal component (each output standardized: the one signal they share). Then every
parameter at once, chain and maps, by Levenberg-Marquardt on all outputs, each output's error divided
by its own standard deviation, so that millimetres and degrees count alike.
"""

from __future__ import annotations

import copy
import itertools
import time
from dataclasses import dataclass, replace

import casadi as ca
import numpy as np

from physics import Arc, LinearMap, OutputMaps, Series
from physics.data import Trajectory

from ._errors import IdentificationError
from ._identify import identify
from ._result import FitResult

__all__ = ["identify_outputs", "OutputsFit", "output_columns", "predict_outputs", "primary_view", "fit_maps"]

#: Levenberg-Marquardt stops when a step lowers the cost by less than this share of it, or when the last
#: ``STALL`` steps together lower it by less than one residual's mean square (``cost / len(r)``): a change
#: no sample could tell (the catheter's joint fit crept by 1e-4 of its cost over 700 evaluations).
RELATIVE_DECREASE = 1e-10
STALL = 10
#: Starts of an arc's own fit (before the joint one): the heading every quarter turn, the straight
#: section's angle half the angles' span below or above them, each handedness.
_ARC_HEADINGS = (0.0, 90.0, 180.0, 270.0)


def output_columns(traj: Trajectory, outputs, refuse_copies: bool = True,
                   error: type[Exception] = IdentificationError) -> np.ndarray:
    """``(n, k)``: the named outputs of ``traj``, each its ``y`` (by ``output_name``) or an ``extra`` column.

    Raises ``error`` (:class:`IdentificationError`; the estimators pass :class:`physics.data.DataError`, what bad
    data raises there) naming the run and the columns it has where one is missing or (with ``refuse_copies``, the
    runs a model is fitted or scored on) is a copy of the input."""
    cols = []
    for name in outputs:
        if name == traj.output_name:
            v = np.asarray(traj.y, dtype=float)
        elif name in traj.extra:
            v = np.asarray(traj.extra[name], dtype=float)
        else:
            have = ", ".join([traj.output_name, *traj.extra]) or "none"
            raise error(f"Run '{traj.source or '?'}' has no output column '{name}'; its columns besides the input "
                        f"are: {have}. Name one of them.")
        if refuse_copies and np.array_equal(v, traj.u):
            raise error(f"Output '{name}' of run '{traj.source or '?'}' is a copy of the input '{traj.input_name}'. "
                        "Name a measured output instead.")
        cols.append(v)
    return np.column_stack(cols)


@dataclass(frozen=True)
class OutputsFit:
    """A model with several outputs fitted by :func:`identify_outputs`.

    Attributes
    ----------
    series : physics.Series
        The fitted model (``n_y`` outputs, in the order of ``outputs``).
    outputs : tuple of str
        The output columns, in the model's order.
    standard_errors : dict of str to float
        The standard errors of the fitted parameters: ``sqrt(diag((J^T W J)^-1))`` with ``W`` each output's
        inverse residual variance (NaN at a bound, ``inf`` where the data do not determine it).
    train_rmse : dict of str to float
        Each output's RMSE on the training runs (its own unit), on the samples after each run's warm-up.
    chain : FitResult
        The first stage: the chain fitted to one output.
    iterations : int
        Levenberg-Marquardt iterations of the joint fit.
    status : str
        Why the joint fit stopped.
    wall_time_s : float
        Both stages (reported, never a limit).
    warmup : int
        The samples at each run's start whose measurements set its state (:meth:`predict`), as the fit
        scored each run.
    """

    series: Series
    outputs: tuple[str, ...]
    standard_errors: dict[str, float]
    train_rmse: dict[str, float]
    chain: FitResult
    iterations: int
    status: str
    wall_time_s: float
    warmup: int = 0

    @property
    def parameters(self) -> dict[str, float]:
        """Every parameter of the fitted model (fitted and held), by name."""
        return self.series.param_dict()

    def predict(self, traj: Trajectory, warmup: int | None = None) -> np.ndarray:
        """``(n - warmup, k)``: the outputs after ``traj``'s first ``warmup`` samples (default: the fit's), from
        the state those samples' measurements set (:func:`predict_outputs`); from rest at the first input
        with ``warmup=0``."""
        warmup = self.warmup if warmup is None else int(warmup)
        measured = output_columns(traj, self.outputs) if warmup else None
        return predict_outputs(self.series, np.asarray(traj.u, dtype=float), measured, warmup)

    def rmse(self, trajectories) -> dict[str, float]:
        """Each output's RMSE pooled over ``trajectories``, on the samples after each run's warm-up."""
        runs = _as_list(trajectories)
        return _rmse(self.series, self.outputs, runs, [output_columns(t, self.outputs) for t in runs], self.warmup)


def _rmse(series: Series, outputs, runs, ys, warmup: int) -> dict[str, float]:
    """Each output's RMSE pooled over ``runs`` (their outputs ``ys``), on the samples after each warm-up."""
    err = np.vstack([predict_outputs(series, t.u, y, warmup) - y[warmup:] for t, y in zip(runs, ys)])
    return dict(zip(outputs, np.sqrt(np.mean(err**2, axis=0)).tolist()))


def primary_view(series: Series) -> tuple[Series, int]:
    """The model of one output whose state is ``series``'s, and which output it is: the angle an arc reads,
    or the first output's own map. A warm-up window's state is fitted on that output (its scales from the
    input range the model was fitted on, as a model of one output's)."""
    last = series.blocks[-1]
    if isinstance(last, Arc) and "angle" in last.outputs:
        return Series(*series.blocks[:-1], dt=series.dt, input_range=series.input_range), last.outputs.index("angle")
    if isinstance(last, OutputMaps):
        first = LinearMap()
        first.set_param_values(last.param_values()[:2])
        return Series(*series.blocks[:-1], first, dt=series.dt, input_range=series.input_range), 0
    raise IdentificationError(f"'{series.spec}' has no output that its state is fitted on: end it in 'maps', or in "
                              "an 'arc' that outputs the angle.")


def predict_outputs(series: Series, u: np.ndarray, measured: np.ndarray | None = None, warmup: int = 0) -> np.ndarray:
    """``(n - warmup, k)``: ``series``'s outputs after the first ``warmup`` samples of ``u``, from the state
    those samples set: :meth:`~physics.Series.estimate_state` of :func:`primary_view` on its output's
    ``measured`` column (``(n, k)``); from rest at ``u[0]`` with ``warmup=0``."""
    if not warmup:
        return series.simulate(u)
    view, j = primary_view(series)
    x = view.estimate_state(u[:warmup], measured[:warmup, j]).x
    return series.simulate(u[warmup:], x0=x)


def _as_list(trajectories) -> list[Trajectory]:
    runs = [trajectories] if isinstance(trajectories, Trajectory) else list(trajectories)
    if not runs or not all(isinstance(t, Trajectory) for t in runs):
        raise IdentificationError("identify_outputs takes a Trajectory or a list of them (physics.data.Trajectory), "
                                  "their outputs named by `outputs`.")
    return runs


def _model(model, k: int, dt: float) -> Series:
    """The model with ``k`` outputs: a spec (at the runs' step) or a Series with one output whose last block
    becomes one of ``k`` outputs (a ``linear``: a map per output; an ``arc``: its angle and position, or
    its position), or a Series with ``k`` outputs as given."""
    if isinstance(model, str):
        model = Series.from_spec(model, dt=dt)
    if not isinstance(model, Series):
        raise IdentificationError(f"model must be a physics.Series or a spec string ('lag+gpi+linear'); got "
                                  f"{type(model).__name__}.")
    series, last = copy.deepcopy(model), model.blocks[-1]
    if series.n_y == 1 and isinstance(last, LinearMap):  # each output its own cubic (the catheter: 5-40 % lower)
        series = Series(*series.blocks[:-1], OutputMaps(outputs=k, cubic=True), dt=series.dt)
    elif series.n_y != k and isinstance(last, Arc) and 2 <= k <= 3:
        series = Series(*series.blocks[:-1], last.with_settings(outputs=("angle", "x", "y")[3 - k:]), dt=series.dt)
    if series.n_y != k:
        raise IdentificationError(f"The model '{series.spec}' has {series.n_y} output(s) but {k} output columns are "
                                  "named. Name one column per output, in the model's order.")
    if abs(series.dt - dt) > 1e-9 * dt:
        raise IdentificationError(f"The runs are sampled every {dt:.6g} s but the model every {series.dt:.6g} s; "
                                  "resample the runs or build the model at their rate.")
    return series


def identify_outputs(model, trajectories, outputs, *, warmup: int = 0, max_iter: int = 100, fixed=(),
                     chain_options: dict | None = None) -> OutputsFit:
    """Fit a model whose outputs (the tip's angle and position, say) one chain of blocks drives.

    Parameters
    ----------
    model : physics.Series or str
        A Series whose last block outputs ``len(outputs)`` signals (:class:`~physics.OutputMaps`,
        :class:`~physics.Arc`), or a spec such as ``"lag+gpi+linear"``: its last ``linear`` becomes a
        cubic map per output (``"...+linear+arc"``: the arc's angle and position, or its position).
        :func:`~identification.discovery.select_outputs_chain` chooses one on runs left out of the fit.
    trajectories : Trajectory or list of Trajectory
        Runs at the model's rate. Each output is the run's ``y`` (named by its ``output_name``) or a
        column of its ``extra``.
    outputs : sequence of str
        The output columns, in the model's order.
    warmup : int
        Samples at each run's start that set its state instead of being fitted: the window's fit of
        :meth:`~physics.Series.estimate_state` on the output the chain is fitted on (the angle, or the first
        output), as a model card scores each run (0: from rest at the first input). The joint stage holds
        the first stage's window states.
    max_iter : int
        Iterations of the joint Levenberg-Marquardt fit (the limit that decides the answer; it stops before
        where ten iterations lower the error by less than one sample's mean square).
    chain_options : dict, optional
        Options of the first stage's :func:`identify` (``starts``, ``solver``, ...).

    Returns
    -------
    OutputsFit

    Raises
    ------
    IdentificationError
        An output column missing, constant or a copy of the input (named, with the run), fewer than two
        outputs, a model whose outputs do not match them, or an arc without its angle.
    """
    t0 = time.perf_counter()
    outputs = tuple(str(o) for o in ([outputs] if isinstance(outputs, str) else outputs))
    if len(outputs) < 2 or len(set(outputs)) != len(outputs):
        raise IdentificationError(f"identify_outputs needs two or more distinct output columns; got {list(outputs)}. "
                                  "For one output use identify.")
    runs = _as_list(trajectories)
    ys = [output_columns(t, outputs) for t in runs]
    pooled = np.vstack(ys)
    for name, column in zip(outputs, pooled.T):
        if np.ptp(column) == 0:
            raise IdentificationError(f"Output '{name}' is constant ({column[0]:.6g}) in every run: nothing can be "
                                      "identified from it. Leave it out, or give runs where it moves.")
    if warmup < 0 or any(t.n <= warmup + 1 for t in runs):
        raise IdentificationError(f"warmup must be >= 0 and leave samples to fit in every run; got {warmup} with runs "
                                  f"of {min(t.n for t in runs)} samples or more.")
    series = _model(model, len(outputs), runs[0].dt)
    scales = np.std(np.vstack([y[warmup:] for y in ys]), axis=0)
    chain_fit, series = _first_stage(series, runs, ys, scales, {"warmup": warmup, **(chain_options or {})})
    unknown = sorted(set(fixed) - set(series.param_names))
    if unknown:
        raise IdentificationError(f"fixed names no parameter of '{series.spec}': {unknown}. Its parameters are: "
                                  f"{', '.join(series.param_names)}.")
    series, iterations, status, std = _joint(series, runs, ys, scales, warmup, max_iter, set(fixed))
    inputs = np.concatenate([t.u for t in runs])
    series.input_range = (float(np.min(inputs)), float(np.max(inputs)))  # a controller's default input bounds
    return OutputsFit(series=series, outputs=outputs, standard_errors=std,
                      train_rmse=_rmse(series, outputs, runs, ys, warmup), chain=chain_fit, iterations=iterations,
                      status=status, wall_time_s=time.perf_counter() - t0, warmup=int(warmup))


def _first_stage(series: Series, runs, ys, scales, options: dict):
    """The chain fitted to one signal, then each output's map to it: the joint fit's start."""
    last, chain_blocks = series.blocks[-1], series.blocks[:-1]
    if isinstance(last, Arc):
        if "angle" not in last.outputs:
            raise IdentificationError("An arc's position is fitted with the tip's angle measured beside it: give "
                                      "the angle column too (Arc(outputs=('angle', 'x', 'y'))).")
        target = [y[:, last.outputs.index("angle")] for y in ys]
        chain = Series(*chain_blocks, dt=series.dt)
    else:
        target = _principal(ys, scales)
        chain = Series(*chain_blocks, LinearMap(), dt=series.dt)
    fit = identify(chain, [replace(t, y=c, extra={}) for t, c in zip(runs, target)], **options)
    fitted = fit.model()
    if isinstance(last, Arc):  # the geometry from the measured angle: the arc's own evidence
        arc = _fit_arc(last, target, ys, scales)
        return fit, Series(*fitted.blocks, arc, dt=series.dt)
    return fit, fit_maps(fitted, runs, ys, last)


def fit_maps(fitted: Series, runs, ys, maps: OutputMaps) -> Series:
    """``fitted`` (a chain ending in one output's map) read by ``maps`` instead, each output's map fitted by
    least squares to its measurements ``ys`` (per run, ``(n, k)``) on the chain's signal from rest, about the
    signal's middle: the joint fit's start, and a fold's model from a chain fitted without some runs."""
    inner = Series(*fitted.blocks[:-1], dt=fitted.dt) if len(fitted.blocks) > 1 else None
    signal = np.concatenate([inner.simulate(t.u) if inner is not None else t.u for t in runs])
    maps = maps.with_settings(center=0.5 * (float(np.min(signal)) + float(np.max(signal))))
    design = np.column_stack(np.broadcast_arrays(*maps.features(signal)))
    coef = np.linalg.lstsq(design, np.vstack(ys), rcond=None)[0]  # (terms, k): each output's weights
    maps.set_param_values(coef.T.ravel())
    return Series(*fitted.blocks[:-1], maps, dt=fitted.dt)


def _principal(ys, scales) -> list[np.ndarray]:
    """Each run's outputs projected on their first principal component (standardized outputs), in the
    first output's units: the one signal they share."""
    stacked = np.vstack(ys)
    mean = stacked.mean(axis=0)
    z = (stacked - mean) / scales
    _, _, vt = np.linalg.svd(z, full_matrices=False)
    v = vt[0] * np.sign(vt[0, 0] or 1.0)
    return [((y - mean) / scales) @ v * scales[0] + mean[0] for y in ys]


def _fit_arc(arc: Arc, angles, ys, scales) -> Arc:
    """The arc's length, base and heading (and handedness) fitted to the positions at the chain's angles:
    Levenberg-Marquardt from each heading quarter and handedness, the best kept."""
    pos = [i for i, o in enumerate(arc.outputs) if o != "angle"]
    a = np.concatenate(angles)
    target = np.vstack(ys)[:, pos]
    span = float(np.ptp(target, axis=0).max())
    centre = np.resize(np.mean(target, axis=0), 2)
    best = None
    for mirrored in (False, True):
        trial = arc.with_settings(mirrored=mirrored, outputs=tuple(arc.outputs[i] for i in pos))
        p_sym = ca.SX.sym("p", trial.n_p)
        a_sym = ca.SX.sym("a")
        xy = ca.vertcat(*trial.position(a_sym, p_sym))
        fn = ca.Function("xy", [a_sym, p_sym], [xy, ca.jacobian(xy, p_sym)]).map(a.size)
        bounds = _arc_bounds(trial, a)
        s = scales[pos]

        def residual(p, fn=fn, s=s, n_p=trial.n_p):
            out, jac = fn(a[None, :], ca.repmat(ca.DM(p), 1, a.size))
            out = np.asarray(out, dtype=float).reshape(len(pos), a.size).T
            jac = np.asarray(jac, dtype=float).reshape(len(pos), a.size, n_p)
            return ((out - target) / s).T.ravel(), (jac / s[:, None, None]).reshape(len(pos) * a.size, n_p)

        for heading, straight in itertools.product(_ARC_HEADINGS, (np.min(a) - np.ptp(a) / 2, np.max(a) + np.ptp(a) / 2)):
            p0 = np.array([span, *centre, float(straight), heading])
            p, cost, _, _ = _levenberg_marquardt(residual, p0, *bounds, 200)
            if best is None or cost < best[0]:
                best = (cost, mirrored, p)
    _, mirrored, p = best
    out = arc.with_settings(mirrored=mirrored, angle_range=[float(np.min(a)), float(np.max(a))])
    out.set_param_values(p)
    return out


def _arc_bounds(arc: Arc, angles) -> tuple[np.ndarray, np.ndarray]:
    """The arc's parameter bounds for tip angles ``angles``: its declared ones, with the bend ``angle -
    base_angle`` less than a full turn at every angle and the heading within a turn either way. A longer arc
    wound more than once round fits any smooth curve (331 mm wound 1.5 times fitted a 72 mm catheter's two
    runs, and its chain's offset went to -302 deg)."""
    lo = np.array([q.lower for q in arc.parameters])
    hi = np.array([q.upper for q in arc.parameters])
    turn = 360.0 if arc.angle_unit == "deg" else 2 * np.pi
    names = [q.name for q in arc.parameters]
    i, h = names.index("base_angle"), names.index("heading")
    lo[i], hi[i] = max(lo[i], float(np.max(angles)) - turn), min(hi[i], float(np.min(angles)) + turn)
    lo[h], hi[h] = -turn, turn
    return lo, hi


def _levenberg_marquardt(residual, p0, lo, hi, max_iter: int):
    """Bounded Levenberg-Marquardt (Marquardt's scaling; steps clipped to the bounds) on ``residual(p) ->
    (r, J)``. Returns ``(p, cost, iterations, status)``."""
    p = np.clip(np.asarray(p0, dtype=float), lo, hi)
    r, J = residual(p)
    cost, lam = float(r @ r), 1e-3
    costs = [cost]
    for it in range(1, max_iter + 1):
        A, g = J.T @ J, J.T @ r
        d = np.maximum(np.diag(A), 1e-12 * max(1.0, float(np.max(np.diag(A)))))
        for _ in range(30):
            try:
                step = -np.linalg.solve(A + lam * np.diag(d), g)
            except np.linalg.LinAlgError:
                lam *= 10.0
                continue
            trial = np.clip(p + step, lo, hi)
            r_new, J_new = residual(trial)
            new = float(r_new @ r_new)
            if np.isfinite(new) and new < cost:
                break
            lam *= 4.0
        else:
            return p, cost, it, "No_Descent"
        decrease = cost - new
        p, r, J, cost, lam = trial, r_new, J_new, new, max(lam / 3.0, 1e-12)
        costs.append(cost)
        if decrease <= RELATIVE_DECREASE * cost:
            return p, cost, it, "Converged"
        if len(costs) > STALL and costs[-1 - STALL] - cost < cost / r.size:
            return p, cost, it, "Converged"
    return p, cost, max_iter, "Maximum_Iterations"


def _joint(series: Series, runs, ys, scales, warmup: int, max_iter: int, fixed: set):
    """Every fitted parameter of the chain and the maps at once, each output's error over its scale; each run
    from the state its warm-up window gives the start's parameters (held), or from rest."""
    free = series.fit_mask & np.array([n not in fixed for n in series.param_names])
    lo, hi = series.lower_bounds, series.upper_bounds
    last = series.blocks[-1]
    if isinstance(last, Arc):
        lo[-last.n_p:], hi[-last.n_p:] = _arc_bounds(last, np.vstack(ys)[:, last.outputs.index("angle")])
    P = ca.MX.sym("p", series.n_p)
    parts = []
    base = series.params
    view, j = primary_view(series) if warmup else (None, 0)
    for t, y in zip(runs, ys):
        if warmup:
            x0 = ca.DM(view.estimate_state(t.u[:warmup], y[:warmup, j]).x)
        else:
            try:
                x0 = series.steady_state_expr(ca.DM(float(t.u[0])), P)[0]
            except (RuntimeError, TypeError, NotImplementedError):  # a block whose rest needs numbers
                x0 = ca.DM(series.steady_state(float(t.u[0]), base))
        n = t.n - warmup
        _, out = series.rollout(n)(x0, ca.DM(t.u[None, warmup:]), P)
        parts.append(ca.vec((out - ca.DM(y[warmup:].T)) / ca.repmat(ca.DM(scales), 1, n)))
    r = ca.vertcat(*parts)
    idx = np.flatnonzero(free)
    fn = ca.Function("residual", [P], [r, ca.jacobian(r, P)[:, idx.tolist()]])

    def residual(w):
        p = base.copy()
        p[idx] = w
        out, jac = fn(p)
        return np.asarray(out, dtype=float).ravel(), np.asarray(ca.densify(jac), dtype=float)

    w, _, iterations, status = _levenberg_marquardt(residual, base[idx], lo[idx], hi[idx], max_iter)
    fitted = copy.deepcopy(series)
    p = base.copy()
    p[idx] = w
    fitted.params = p
    r_end, J = residual(w)
    k = len(scales)
    res = r_end.reshape(-1, k)  # rows: samples, columns: outputs (vec is column-major: outputs first)
    dof = max(res.shape[0] - idx.size / k, 1.0)
    var = np.sum(res**2, axis=0) / dof  # each output's residual variance, in scaled units
    weights = np.tile(1.0 / np.sqrt(var), res.shape[0])
    std = _standard_errors(J * weights[:, None], w, lo[idx], hi[idx])
    names = [series.param_names[i] for i in idx]
    return fitted, iterations, status, dict(zip(names, std.tolist()))


def _standard_errors(Jw: np.ndarray, w: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    at_bound = (w <= lo) | (w >= hi)
    out = np.full(w.size, np.nan)
    inner = ~at_bound
    A = Jw[:, inner].T @ Jw[:, inner]
    try:
        cov = np.linalg.inv(A)
        out[inner] = np.sqrt(np.maximum(np.diag(cov), 0.0))
    except np.linalg.LinAlgError:
        out[inner] = np.inf
    return out
