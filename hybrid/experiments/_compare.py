"""Physics, learned and hybrid models side by side, forward and inverse, in and out of distribution.

``compare`` trains every model on one data set and scores it on test categories
named in the ``test`` column as ``<category>:<trajectory>`` (``id:f0.15_mid``)
plus a pooled row per category (``id:all``):

``id``           the paper's tests (virtual: 0.15 and 0.45 Hz; catheter_2023: set 2; its protocols
                 ``:reverse`` set 1 and ``:interp`` the 0.2 and 0.4 Hz runs of both sets)
``ood_freq``     (virtual) decaying sinusoids at 0.6-1.0 Hz
``ood_amp``      (virtual) amplitude 20 % beyond training (q_max 3.6 mm)
``ood_baseline`` (virtual) trained on the zero and mid baselines, tested on 'end'
``ood_steps``    (virtual) random-step commands
``ood_random``   (niti_frequency_trials) the random excitation, trained on decaying sinusoids only
``data_1``, ``data_3``, ``data_all``  the id tests, trained on 1, 3 and all training runs
"""

from __future__ import annotations

import platform
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from identification.discovery import AUTO, DEFAULT_SPECS, PhysicsPolicy, Workers
from physics import Series
from physics.data import Dataset, check_warmup_length, join
from physics.data.io import write_json
from ._compare_plots import plot_all
from ._compare_table import Row, rows as table_rows, write_tables
from ._datasets import CompareData
from ._hybrid_or_alone import ALONE_KEPT, hybrid_or_alone, pooled_rmse
from ._presets import BUDGETS, PAPER_NETWORKS, Budget, check_preset
from ._scoring import score_model

__all__ = ["PEERS", "CompareResult", "compare", "compare_policy"]

#: Measured samples at the start of each test run every model sets its state from (the protocol of the
#: system-identification peers: each run simulated free from its first samples, scored after them).
WARMUP = 10
#: Tag of the training sets of the intervals' folds (``compare(..., interval=...)``).
FOLD = "fold"
#: Most folds the intervals' calibration fits every forward model on.
INTERVAL_FOLDS = 5
#: The network of the forward hybrid that the model-based inverse inverts.
INVERSE_NETWORK = "fnn-hib"
#: Physics specs tried in order for the hybrids where the selection of ``physics="auto"`` fails: the
#: first that fits is used, the failures of the ones before it are listed in run.json (a comparison
#: never dies because one physics fit did). The physics policy's (``identification.DEFAULT_SPECS``).
PHYSICS = DEFAULT_SPECS
#: The peers ``compare`` scores beside our models by default (:data:`hybrid.peers.PEERS`); those whose
#: optional package is missing are skipped with a note in run.json.
PEERS = ("arx", "narx", "subnet")


@dataclass
class CompareResult:
    out: Path
    rows: list[Row]
    fit_seconds: dict[str, float]
    seconds: float


class _Physics:
    """The physics model alone as a predictor: ``Series.simulate`` forward, ``Series.inverse`` inverse
    (bounded, and lags passed through or not, as an inverse hybrid's: ``inverse_form``)."""

    def __init__(self, series, direction, train):
        self.series, self.direction = series, direction
        if direction == "inverse":
            from hybrid.models._hybrid import inverse_form

            self.bounds, self.quasi_static = inverse_form(series, train)

    def predict(self, traj, warmup=None):
        if self.direction == "forward":  # the window in the forward model's roles either way
            return self.series.simulate(traj.u, warmup=warmup)
        return self.series.inverse(traj.y, bounds=self.bounds, quasi_static=self.quasi_static, warmup=warmup)


class _ViaExport:
    """A fitted forward model scored through its CasADi export (``export_model``: the same model,
    equal to its own ``predict`` to rounding, as the export tests check). For the neural ODE, whose
    torch rollout steps from Python once per sample: a 153,000-sample test run in 0.3 s, not 5 min.
    A run whose input moves faster than the export is valid for (``meta["max_input_step"]``) is
    predicted by the model itself, which integrates those intervals in finer steps."""

    def __init__(self, model, warmup: int = 0):
        from hybrid.export import export_model

        self.model, self.direction = model, model.direction
        self.exported = export_model(model, warmup=warmup or None)

    def predict(self, traj, warmup=None):
        whole = traj if warmup is None else join(warmup, traj)
        fastest = float(np.abs(np.diff(whole.u)).max()) if whole.u.size > 1 else 0.0
        if fastest > self.exported.meta.get("max_input_step", np.inf):  # past where the export's fixed
            return self.model.predict(traj, warmup=warmup)  # steps equal the model's: its own, finer steps
        return self.exported.simulate(traj.u, warmup=None if warmup is None else (warmup.u, warmup.y))


# ---------------------------------------------------------------------- job
@dataclass
class _Job:
    """What every training of one comparison shares; ``timings`` collects the fit times."""

    cfg: Budget
    networks: tuple[str, ...]
    seed: int
    progress: bool | None
    #: The hybrids' physics: ``auto`` or specs tried in order, what to try where the selection fails, and
    #: the selection's options (where its fold fits run among them: ``select_options["workers"]``)
    policy: PhysicsPolicy = field(default_factory=lambda: compare_policy())
    warmup: int = 0
    peers: tuple[str, ...] = ()
    timings: dict[str, float] = field(default_factory=dict)
    physics_failed: dict[str, str] = field(default_factory=dict)
    skipped: dict[str, str] = field(default_factory=dict)  # models a physics cannot carry, and why
    physics_used: dict[str, str] = field(default_factory=dict)
    # per hybrid row (training set/direction/name): the hybrid or its network alone, and the held-out evidence
    hybrid_choice: dict[str, dict] = field(default_factory=dict)
    physics_selection: dict[str, Any] = field(default_factory=dict)
    physics_inverse: dict[str, Any] = field(default_factory=dict)  # bounds and quasi_static of each inverse
    fitted: dict[str, Any] = field(default_factory=dict)  # the physics fitted per training set (both directions)
    # per training set: the specs in the order tried, and the selection's fold fits of each (starts)
    candidates: dict[str, tuple[list[str], dict]] = field(default_factory=dict)
    device: str = "cpu"  # where the networks train (TrainingSettings.device)

    def settings(self, network: str):
        """The TrainingSettings ``network`` trains with (the budget's, with this job's seed and progress)."""
        return self.cfg.networks.for_network(network, **self.common, device=self.device)

    @property
    def common(self) -> dict[str, Any]:
        return dict(seed=self.seed, progress=self.progress)


def _models(train: Dataset, direction: str, job: _Job, ode: bool, inverse: bool, tag: str) -> dict[str, tuple[str, Any]]:
    """Fit every model of one direction on ``train``: name -> (kind, fitted model)."""
    from hybrid.models._hybrid import HybridModel, input_bounds
    from hybrid.control._inverse import ModelInverse
    from hybrid.learning._learned import LearnedModel
    from hybrid.networks import make_network

    def timed(key, fn):
        t0 = time.perf_counter()
        out = fn()
        job.timings[f"{tag}/{direction}/{key}"] = round(time.perf_counter() - t0, 2)
        return out

    fit = timed("physics", lambda: _physics_fit(job, list(train), f"{tag}/{direction}"))
    physics = _Physics(fit.model(), direction, list(train))
    if direction == "inverse":
        job.physics_inverse[f"{tag}/{direction}"] = {"bounds": list(physics.bounds), "quasi_static": physics.quasi_static}
    models: dict[str, tuple[str, Any]] = {"physics": ("physics", physics)}
    for m in job.networks:
        s = job.settings(m)
        models[m] = ("learned", timed(m, lambda: LearnedModel(make_network(m), direction, training=s).fit(train)))
    for m in job.networks:
        s = job.settings(m)
        new = lambda: HybridModel(fit, m, direction, training=s)  # noqa: E731 (called at once, in this iteration)
        # the network alone in the hybrid's place where it does better on runs held out of both fits
        choice = timed(f"{m}+physics/held-out", lambda: hybrid_or_alone(
            new, lambda: LearnedModel(make_network(m), direction, training=s),
            pooled_rmse(direction, job.warmup), list(train), job.warmup, make_network(m).history))
        job.hybrid_choice[f"{tag}/{direction}/{m}+physics"] = choice.to_dict()
        models[f"{m}+physics"] = ("hybrid", models[m][1] if choice.kept == ALONE_KEPT else
                                  timed(f"{m}+physics", lambda: new().fit(train)))
    if tag == "all" or tag.startswith(FOLD):
        _peers(models, job, train, direction, timed)
    if direction == "forward" and ode:
        _neural_ode(models, fit, job, list(train), f"{tag}/{direction}")
    if direction == "inverse" and inverse:
        forward = HybridModel(fit, INVERSE_NETWORK, "forward", training=job.settings(INVERSE_NETWORK))
        models[f"model-inverse:{INVERSE_NETWORK}+physics"] = ("hybrid", timed("model-inverse", lambda: ModelInverse(
            forward, u_bounds=input_bounds(train), **job.cfg.inverse).fit(train)))
    return models


def _peers(models: dict, job: _Job, train: Dataset, direction: str, timed) -> None:
    """The peers (``job.peers``) fitted on the same runs, in their own rows (kind ``peer``); one whose
    optional package is missing is skipped with its note."""
    for name in job.peers:
        peer, note = new_peer(name, job.cfg, job.seed, direction=direction)
        if peer is None:
            job.skipped[f"all/{direction}/{name}"] = note
            continue
        models[f"peer:{name}"] = ("peer", timed(f"peer:{name}", lambda: peer.fit(train)))


def new_peer(name: str, cfg: Budget, seed: int, **settings):
    """``(peer, None)``: the unfitted peer ``name`` with the preset's settings (``cfg.peers``), ``seed`` where it
    takes one, and ``settings`` (``direction``, ``outputs``); or ``(None, note)`` where its optional package is
    missing (the note printed)."""
    from hybrid.peers import PEERS as CLASSES, available_peers

    note = available_peers()[name]
    if note is not None:
        print(f"compare: peer {name} skipped: {note}", flush=True)
        return None, note
    settings = {**cfg.peers.get(name, {}), **settings}
    if "seed" in CLASSES[name]().get_params():
        settings["seed"] = seed
    return CLASSES[name](**settings), None


def _no_ode_form(series) -> str | None:
    """Why the neural-ODE hybrid cannot run on ``series`` (a block without a continuous form, or no
    state at all), or None."""
    from hybrid.models._neural_ode import ode_state_names
    from physics import PhysicsError

    try:
        ode_state_names(series)
    except PhysicsError as exc:
        return str(exc)
    return None


#: The neural-ODE hybrid's physics policy: a spec whose ODE form carries it (every block continuous, a
#: state to correct), at most three of them tried in turn (each fitted, then checked stable under RK4);
#: its specs are the hybrids' physics, then the later ones of their ranking or list (:func:`_neural_ode`).
ODE_POLICY = PhysicsPolicy(physics=(), requires=_no_ode_form, max_tries=3)


def _neural_ode(models: dict, fit, job: _Job, train: list, where: str) -> None:
    """The neural-ODE hybrid, on the hybrids' physics where its ODE form carries one (every block
    continuous, a state to correct, stable under RK4 at up to 8 steps per sample), else on the next spec of
    the ranking (``auto``) or of the list that does and fits (:data:`ODE_POLICY`, applied by
    :func:`identification.physics_fits`). When none does, the comparison goes on without it and run.json's
    ``skipped`` says why."""
    from dataclasses import replace

    from hybrid.models._neural_ode import NeuralODEHybrid
    from identification import PhysicsReport, physics_fits
    from physics import PhysicsError

    t0 = time.perf_counter()  # timed whole: the fallback fits and the refused attempts too
    specs, guesses = job.candidates.get(where.split("/")[0], ([], {}))
    later = specs[specs.index(fit.spec) + 1:] if fit.spec in specs else []
    report = PhysicsReport("", "none")
    reasons = []
    try:
        for _, ode_fit in physics_fits(replace(ODE_POLICY, physics=[fit, *later]), train, guesses, report):
            if not reasons and fit.spec in report.skipped:  # the hybrids' own physics has no ODE form: why
                reasons.append(report.skipped[fit.spec])
            try:
                model = NeuralODEHybrid(ode_fit, **job.cfg.ode, **job.common, threads=1).fit(train)
            except (PhysicsError, FloatingPointError) as exc:  # unstable at this rate, or its training blew up
                reasons.append(str(exc))
                print(f"compare: no neural-ode hybrid on '{ode_fit.spec}' ({where}): {exc}", flush=True)
                continue
            models["neural-ode"] = ("hybrid", _ViaExport(model, job.warmup))
            if ode_fit is not fit:
                job.physics_used[f"{where}/neural-ode"] = ode_fit.spec
                print(f"compare: the neural-ode hybrid runs on '{ode_fit.spec}', the next spec that carries one "
                      f"({where})", flush=True)
            break
        else:
            if not reasons and fit.spec in report.skipped:
                reasons.append(report.skipped[fit.spec])
            job.skipped[f"{where}/neural-ode"] = " ".join(reasons) or f"no spec with a continuous form fitted ({where})"
            print(f"compare: no neural-ode hybrid ({where}): {job.skipped[f'{where}/neural-ode']}", flush=True)
    finally:
        for spec, why in report.failed.items():  # the later specs that did not fit
            job.physics_failed[f"{where}/neural-ode/{spec}"] = why
            print(f"compare: physics '{spec}' did not fit ({where}/neural-ode)", flush=True)
    job.timings[f"{where}/neural-ode"] = round(time.perf_counter() - t0, 2)


def _physics_fit(job: _Job, train: list, where: str):
    """The physics of ``job.policy`` (:func:`identification.fit_physics`: the first spec that fits
    ``train``; ``auto``: the selection's ranking, or :data:`PHYSICS` where the selection fails); the
    failures before it are recorded. Both directions train on one training set (``where``'s first part):
    fitted once, deterministically."""
    from dataclasses import replace

    from identification import IdentificationError, PhysicsFitError, fit_physics

    tag = where.split("/")[0]
    if tag in job.fitted:
        job.physics_used[where] = job.fitted[tag].spec
        return job.fitted[tag]
    auto = job.policy.auto
    # the physics hyst fit reaches on the same runs: chosen and fitted under the scoring protocol
    policy = job.policy.scored_after(job.warmup)
    policy = replace(policy, select_options={"verbose": job.progress is not False, **policy.select_options})
    try:
        fit, report = fit_physics(policy, train)[1:]
    except PhysicsFitError as exc:
        fit, report = None, exc.report
    if auto:
        _record_selection(job, report, where)
    job.candidates[tag] = (list(report.candidates), report.selection.fold_parameters if report.selection else {})
    for spec, why in report.failed.items():
        job.physics_failed[f"{where}/{spec}"] = why
        print(f"compare: physics '{spec}' did not fit ({where})", flush=True)
    if fit is None:
        raise IdentificationError(f"None of the physics specs {list(report.candidates)} could be fitted ({where}):\n  "
                                  + "\n  ".join(f"{k}: {v}" for k, v in job.physics_failed.items()))
    job.physics_used[where] = fit.spec
    job.fitted[tag] = fit
    return fit


def _record_selection(job: _Job, report, where: str) -> None:
    """``physics="auto"``: the selection's choice and evidence for run.json (or why it failed and the
    specs tried instead)."""
    if report.selection is None:
        job.physics_selection[where] = {"error": report.selection_error,
                                        "fallback": list(job.policy.if_selection_fails or ())}
        return
    job.physics_selection[where] = report.selection.to_dict()
    job.timings[f"{where}/physics-selection"] = round(report.selection.seconds, 2)
    print(f"compare: physics chosen on held-out runs ({where}): {report.selection.spec}", flush=True)


def _score(models: dict[str, tuple[str, Any]], direction: str, tests: dict[str, Dataset], warmup: int) -> list[Row]:
    """Every model on every test category (the category's name -> its test runs), each run's first
    ``warmup`` samples given as its warm-up window and the rest scored."""
    return [row for name, (kind, model) in models.items() for category, runs in tests.items()
            for row in table_rows(score_model(model, runs, name, direction=direction, diverged="inf",
                                              warmup=warmup), kind, category)]


def _fold_held_out(train: list, fold: list[int], k: int, n_folds: int, job: _Job) -> tuple[dict[str, list], dict]:
    """Interval fold ``k``: every forward model fitted on ``train`` without the runs ``fold``, and its
    predictions of those runs (name -> :class:`~hybrid.intervals.HeldOut` list); with what the fits
    recorded in ``job`` (timings, failures), for the caller's job."""
    from hybrid.intervals import HeldOut, predict_with
    from physics.data import warmup_split

    fitted_on = [t for i, t in enumerate(train) if i not in fold]
    print(f"compare: intervals, fold {k + 1}/{n_folds} (runs {fold} held out)", flush=True)
    held: dict[str, list] = {}
    for name, (_, model) in _models(Dataset(fitted_on), "forward", job, True, False, f"{FOLD}{k}").items():
        for i in fold:
            window, rest = warmup_split(train[i], job.warmup)
            y = predict_with(model, rest, window)
            if np.all(np.isfinite(y)):
                held.setdefault(name, []).append(HeldOut(rest, y, fitted_on))
    return held, {key: getattr(job, key) for key in ("timings", "physics_failed", "skipped", "physics_used",
                                                          "hybrid_choice")}


def _intervals(models: dict, data: CompareData, job: _Job, level: float) -> list[dict]:
    """Every forward model's conformal intervals: each model kind fitted again on the folds of the
    training runs (at most :data:`INTERVAL_FOLDS`, leave one run out; the physics spec the models use
    on all runs, not selected again), calibrated on the runs each fold left out, then scored on each
    test category: coverage, mean width (``hi - lo``) and the share of samples outside the data.

    The folds run where the physics selection's fold fits do (the policy's ``select_options["workers"]``:
    local workers or a Dask cluster), each a function of plain data: the same numbers in any process,
    read in fold order."""
    from hybrid.intervals import ConformalIntervals, coverage, predict_with
    from identification.discovery import make_pool, run_folds
    from physics.data import DataError, warmup_split

    train = list(data.train)
    folds, _ = run_folds(train, max_folds=INTERVAL_FOLDS)
    # a fold's models use the spec chosen on all runs, fitted in the fold's process: nothing inside a fold
    # runs on the pool again (and a Dask Client, which does not pickle, stays here)
    fold_policy = replace(job.policy, physics=[job.fitted["all"].spec], select_options={})
    fold_job = _Job(job.cfg, job.networks, job.seed, job.progress, fold_policy, job.warmup, job.peers,
                    device=job.device)
    held: dict[str, list] = {name: [] for name in models}
    pool = make_pool(job.policy.select_options.get("workers"))
    futures = [pool.submit(_fold_held_out, train, fold, k, len(folds), fold_job) for k, fold in enumerate(folds)]
    try:
        for future in futures:  # in fold order, whatever order they finish in
            fold_held, records = future.result()
            for name, runs in fold_held.items():
                if name in held:
                    held[name].extend(runs)
            for key, record in records.items():
                getattr(job, key).update(record)
    except BaseException:
        pool.abort(futures)
        raise
    finally:
        pool.close()
    out = []
    for name, (kind, model) in models.items():
        try:
            intervals = ConformalIntervals(level).fit(train, held[name])
            intervals.quantile()
        except DataError as exc:  # said, not only recorded: --interval asked for them
            job.skipped[f"intervals/{name}"] = str(exc)
            print(f"compare: no {level * 100:.4g}% intervals for {name}: {exc}", flush=True)
            continue
        for category, runs in data.tests.items():
            ys, bands = [], []
            for t in runs:
                window, rest = warmup_split(t, job.warmup)
                y = predict_with(model, rest, window)
                if not np.all(np.isfinite(y)):
                    break
                ys.append(rest.y)
                bands.append(intervals.interval(y, rest.u, rest.dt))
            else:
                y = np.concatenate(ys)
                lo, hi = np.concatenate([b.lo for b in bands]), np.concatenate([b.hi for b in bands])
                err = float(np.sqrt(np.mean((y - np.concatenate([b.y for b in bands])) ** 2)))
                out.append({"model": name, "kind": kind, "test": category, "level": level,
                            "coverage": coverage(y, lo, hi), "width": float(np.mean(hi - lo)),
                            "width_over_rmse": float(np.mean(hi - lo)) / err if err > 0 else float("nan"),
                            "outside": float(np.mean(np.concatenate([b.outside for b in bands]))),
                            "held_out_runs": len(held[name])})
    return out


def compare_policy(physics=AUTO, workers: Workers | None = None) -> PhysicsPolicy:
    """The physics policy of :func:`compare`: ``"auto"`` (chosen on each training set by leaving whole
    runs out; where the selection fails, :data:`PHYSICS` is tried) or specs tried in order (the first that
    fits is the hybrids' physics), the selection's fold fits run on ``workers`` (:class:`Workers`)."""
    physics = (physics,) if isinstance(physics, str) else tuple(physics)
    if AUTO in physics and physics != (AUTO,):
        raise ValueError(f"physics 'auto' chooses the spec itself; give it alone, not with {[p for p in physics if p != AUTO]}.")
    for spec in physics:
        if spec != AUTO:
            Series.from_spec(spec)  # a typo fails here, before any training
    return PhysicsPolicy(AUTO if physics == (AUTO,) else list(physics), if_selection_fails=PHYSICS,
                         select_options={} if workers is None else {"workers": workers})


def compare(data: CompareData, out: str | Path, preset: str = "quick", seed: int = 0, progress: bool | None = None,
            figures: bool = True, directions=("forward", "inverse"), networks=PAPER_NETWORKS,
            physics: str | tuple[str, ...] | PhysicsPolicy = AUTO, warmup: int = WARMUP, peers=PEERS,
            interval: float | None = None) -> CompareResult:
    """Train and score everything; write ``out/compare.csv``, ``out/compare.md``, ``out/run.json``, figures.

    ``networks`` are registry names (:data:`hybrid.networks.NETWORKS`): each is trained alone and as
    the residual of the physics; the default is the seed paper's three. ``physics="auto"`` (default)
    chooses the hybrids' physics on each training set by leave-one-run-out cross-validation (the
    candidates' held-out errors go to run.json's ``physics_selection``; where the selection fails,
    :data:`PHYSICS` is tried). Or specs tried in order: the first that fits is the hybrids' physics. Or a
    :class:`~identification.PhysicsPolicy` (:func:`compare_policy` builds compare's own), whose
    ``select_options`` reach ``select_physics``: ``{"workers": Workers(n_jobs=4)}`` fits the selection's
    folds in 4 worker processes, ``Workers(scheduler=address)`` on a Dask cluster (the same choice and
    numbers as one; run.json records them).
    ``warmup`` is the protocol: every model is given each test run's first ``warmup`` measured samples,
    sets its state from them and is scored on the rest (0: every model from rest at the first sample).
    ``peers`` (:data:`hybrid.peers.PEERS` names) are fitted on the same training runs and scored the
    same way, in rows of kind ``peer``; the table says where the best of ours stands against the best.
    ``interval`` (a level, e.g. 0.9) also calibrates every forward model's conformal intervals on folds
    of the training runs (every model fitted once more per fold, at most five) and reports their
    coverage and width per test category (``intervals.csv``, a table in compare.md).
    Every model runs at the rate of ``data``'s runs (run.json's ``rate_hz``). The networks train on the
    workers' ``device`` (``Workers(device="auto")``: a GPU where torch sees one); the models are scored
    on the CPU.
    """
    from hybrid.intervals import check_level
    from hybrid.learning._learned import _threads
    from hybrid.networks import make_network

    check_preset(preset)
    warmup = check_warmup_length(warmup)
    short = [t for runs in data.tests.values() for t in runs if t.n <= warmup]
    if short:
        raise ValueError(f"A warm-up of {warmup} samples leaves nothing to score in test run {short[0].source!r} "
                         f"({short[0].n} samples); give a shorter --warmup.")
    for m in networks:
        make_network(m)  # rejects unknown names, listing the registered ones
    from hybrid.peers import PEERS as PEER_CLASSES

    peers = tuple(peers)
    unknown = [p for p in peers if p not in PEER_CLASSES]
    if unknown:
        raise ValueError(f"Unknown peer(s) {unknown}. Must be among {list(PEER_CLASSES)}.")
    policy = physics if isinstance(physics, PhysicsPolicy) else compare_policy(physics)
    workers = policy.select_options.get("workers") or Workers()
    if interval is not None:
        check_level(interval)
        if len(data.train) < 2:
            raise ValueError(f"Intervals are calibrated on training runs held out of a fit: give at least 2 "
                             f"training runs (got {len(data.train)}) or leave --interval out.")
    job = _Job(BUDGETS[preset], tuple(networks), seed, progress, policy, warmup, peers, device=workers.device)
    out = Path(out)
    start, rows, fitted, bands = time.perf_counter(), [], {}, []
    with _threads(1):
        for direction in directions:
            models = _models(data.train, direction, job, True, True, "all")
            fitted[direction] = models
            rows += _score(models, direction, data.tests, warmup)
            if direction == "forward" and interval is not None:
                bands = _intervals(models, data, job, interval)
            # data_all: the id scores of the models trained on every run (the same numbers, renamed)
            rows += [Row(r.direction, r.model, r.kind, "data_all:" + r.test[3:], r.rmse, r.nrmse, r.n)
                     for r in rows if r.direction == direction and r.test.startswith("id:")]
            if direction not in job.cfg.extra_directions:
                continue
            extra = dict(data.subsets)
            if data.baseline is not None:
                extra["ood_baseline"] = data.baseline[0]
            for category, train in extra.items():
                models = _models(train, direction, job, job.cfg.ode_extra, False, category)
                tests = data.baseline[1] if category == "ood_baseline" else data.tests["id"]
                rows += _score(models, direction, {category: tests}, warmup)
    result = CompareResult(out, rows, job.timings, 0.0)
    write_tables(rows, out, data, bands, skipped={k: v for k, v in job.skipped.items() if k.startswith("intervals/")},
                 choices={k: v for k, v in job.hybrid_choice.items() if not k.startswith(FOLD)})
    if figures:
        plot_all(fitted, data, rows, out / "figures")
    result.seconds = time.perf_counter() - start
    write_json(out / "run.json", {"data": data.name, "rate_hz": _rate_hz(data), "preset": preset, "seed": seed,
                                  "warmup": warmup, **workers.to_dict(),
                                  "settings": _jsonable(job),
                                  "train": list(data.train.names),
                                  "tests": {k: list(v.names) for k, v in data.tests.items()},
                                  "fit_seconds": job.timings, "total_seconds": round(result.seconds, 1),
                                  "physics_used": job.physics_used, "physics_failed": job.physics_failed,
                                  "physics_selection": job.physics_selection,
                                  "physics_inverse": job.physics_inverse, "skipped": job.skipped,
                                  "hybrid_choice": job.hybrid_choice,
                                  "noise_floor": data.noise_floor, "python": platform.python_version()})
    return result


def _rate_hz(data: CompareData) -> float:
    """The rate the comparison's runs are sampled at, Hz: the loader's (``meta["rate_hz"]``), else the
    first training run's step."""
    first = data.train[0]
    return float(first.meta.get("rate_hz") or round(1.0 / first.dt, 9))


def _jsonable(job: _Job) -> dict[str, Any]:
    """The preset as run.json records it: the training settings of each network trained, and the rest
    of the budget compare reads."""
    cfg = {"networks": {m: job.settings(m).to_dict() for m in job.networks}, "ode": dict(job.cfg.ode),
           "inverse": dict(job.cfg.inverse), "extra_directions": list(job.cfg.extra_directions),
           "ode_extra": job.cfg.ode_extra, "peers": {k: dict(v) for k, v in job.cfg.peers.items()}}
    return cfg
