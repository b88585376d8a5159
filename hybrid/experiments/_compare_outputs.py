"""Physics, learned and hybrid models of several outputs side by side: ``compare(..., outputs=(...))``.

The tip's pose (``("Angle x", "Pos x", "Pos y")``) as one model of each kind, trained on the same runs and scored
per output on the same test runs, forward (one tendon, several outputs; the inverse of a pose follows one output:
:class:`~hybrid.control.ModelInverse` with ``output=j``):

``physics``         the chain :func:`identification.discovery.select_outputs` chooses on the first output (or the
                    specs given, the first that fits), read by a cubic map per output or, for three outputs, the
                    arc where it is lower held out (:func:`~hybrid.experiments.outputs_physics`, as ``hyst fit
                    --output`` does);
``NETWORK``         the network alone, one unit per output (``LearnedModel(outputs=...)``);
``NETWORK+physics`` that network as the residual of every output of the physics (``HybridModel(outputs=...)``);
``peer:NAME``       the peers of several outputs: a linear ARX of all outputs at once (``LinearARX(outputs=...)``),
                    a polynomial NARX per output (SysIdentPy's FROLS fits one) and deepSI's SUBNET of every output,
                    those whose optional package is missing skipped with a note in ``run.json``.

Every model sets its state from each test run's first ``warmup`` samples and is scored on the rest, per output:
``compare.csv`` (one row per model, output and test run, and pooled per category), ``compare.md`` (pooled RMSE per
output and category, each of ours beside the ARX) and ``run.json``; ``figures/rmse_per_output.png``.
"""

from __future__ import annotations

import platform
import time
from pathlib import Path

import numpy as np

from physics.data import DataError, check_warmup_length, nrmse, rmse
from physics.data.io import write_json, write_text

from ._compare_table import test_name
from ._fit_outputs import check_runs
from ._hybrid_or_alone import HybridChoice
from ._presets import BUDGETS, PAPER_NETWORKS, check_preset

__all__ = ["compare_outputs"]

#: The peers of several outputs (:mod:`hybrid.peers`, each with ``outputs=``): every one ``compare`` scores.
OUTPUT_PEERS = ("arx", "narx", "subnet")


def compare_outputs(data, out: str | Path, outputs, *, preset: str = "quick", seed: int = 0,
                    networks=PAPER_NETWORKS, physics="auto", warmup: int = 10, peers=OUTPUT_PEERS,
                    workers=None, progress: bool | None = None, figures: bool = True):
    """Train every model of ``outputs`` on ``data.train`` and score each output on every test category (see the
    module docstring); returns a :class:`~hybrid.experiments._compare.CompareResult` whose rows carry the output
    in their ``test`` (``"id:data_2_1/Pos y"``). ``physics``: ``"auto"`` or specs tried in order; ``workers``:
    where the selection's and the outputs fit's held-out fits run (:class:`~identification.discovery.Workers`)."""
    from hybrid.learning._learned import _threads
    from hybrid.networks import make_network

    from ._compare import CompareResult
    from ._compare_table import Row

    outputs = tuple(outputs)
    check_preset(preset)
    warmup = check_warmup_length(warmup)
    for m in networks:
        make_network(m)  # an unknown name: the registered ones listed
    unknown = [p for p in peers if p not in OUTPUT_PEERS]
    if unknown:
        raise DataError(f"Unknown peer(s) {unknown}. Must be among {list(OUTPUT_PEERS)}.")
    train, out, timings = list(data.train), Path(out), {}
    check_runs(train, [t for ts in data.tests.values() for t in ts], outputs, warmup)
    start = time.perf_counter()

    def timed(key, fn):
        t0 = time.perf_counter()
        value = fn()
        timings[key] = round(time.perf_counter() - t0, 2)
        return value

    with _threads(1):
        fit, chain, tried = timed("physics", lambda: _physics(train, outputs, physics, warmup, workers))
        models = {"physics": ("physics", fit.series)}
        training = {m: BUDGETS[preset].networks.for_network(m, seed=seed, progress=progress) for m in networks}
        choices: dict[str, dict] = {}
        models.update(_networks(train, outputs, fit.series, training, warmup, choices, timed))
        skipped = _peers(models, train, outputs, peers, preset, seed, timed)
        rows = []
        for name, (kind, model) in models.items():
            for category, tests in data.tests.items():
                rows += _score(name, kind, model, list(tests), outputs, category, warmup)
    result = CompareResult(out, [Row(*r) for r in rows], timings, 0.0)
    out.mkdir(parents=True, exist_ok=True)
    _write_tables(out, rows, outputs, data, choices)
    if figures:
        _plot(out / "figures" / "rmse_per_output.png", rows, outputs, data)
    result.seconds = time.perf_counter() - start
    write_json(out / "run.json", {
        "data": data.name, "outputs": list(outputs), "directions": ["forward"],
        "rate_hz": round(1.0 / train[0].dt, 9), "preset": preset, "seed": seed, "warmup": warmup,
        "networks": list(networks), "peers": list(peers), "skipped": skipped, "physics_used": fit.series.spec,
        "physics_chain": chain, "physics_tried": tried, "hybrid_choice": choices,
        "settings": {m: s.to_dict() for m, s in training.items()},
        "train": [str(t.source) for t in train], "tests": {k: [str(t.source) for t in v] for k, v in data.tests.items()},
        "fit_seconds": timings, "total_seconds": round(result.seconds, 1), "python": platform.python_version()})
    return result


def _physics(train, outputs, physics, warmup: int, workers):
    """``(fit, chain, tried)``: the chain chosen (``auto``) or the first given spec that fits, every output read
    from it as ``hyst fit --output`` reads it (:func:`~hybrid.experiments.outputs_physics`)."""
    from identification.discovery import select_outputs

    from ._fit_outputs import outputs_physics

    options = {} if workers is None else {"workers": workers}
    specs = [physics] if isinstance(physics, str) else list(physics)
    if specs == ["auto"]:
        specs = [select_outputs(train, outputs, warmup=warmup, progress=False, **options).spec]
    failed = {}
    for spec in specs:
        try:
            fit, tried, _ = outputs_physics(spec, train, outputs, warmup=warmup, **options)
            return fit, spec, {**tried, "failed": failed}
        except DataError as exc:
            failed[spec] = str(exc)
    raise DataError(f"no physics spec fitted the outputs {', '.join(outputs)}: "
                    + "; ".join(f"'{s}': {why}" for s, why in failed.items()))


def _networks(train, outputs, series, training: dict, warmup: int, choices: dict, timed) -> dict:
    """Each network (``training``: its TrainingSettings by name) alone and as the residual of ``series``, every
    output at once: name -> (kind, model); a hybrid whose network alone does better held out is that network
    (:func:`~hybrid.experiments._hybrid_or_alone.hybrid_or_alone`, the evidence in ``choices``)."""
    from hybrid.learning import LearnedModel
    from hybrid.models import HybridModel
    from hybrid.networks import make_network

    from identification import output_columns

    from ._fit_outputs import _spread, _standardized, predict_after
    from ._hybrid_or_alone import ALONE_KEPT, hybrid_or_alone

    spread = _spread(train, outputs, warmup)

    def score(model, runs):  # each output's mean square over its spread, averaged, as the folder's residual stage
        return _standardized(runs, [predict_after(model, t, output_columns(t, outputs), warmup) for t in runs],
                             outputs, warmup, spread)

    models = {}
    for m, s in training.items():
        models[m] = ("learned", timed(m, lambda: LearnedModel(make_network(m), outputs=outputs, training=s).fit(train)))
    for m, s in training.items():
        new = lambda: HybridModel(series, make_network(m), outputs=outputs, training=s)  # noqa: E731 (this iteration)
        # the network alone in the hybrid's place where it does better on runs held out of both fits
        choice = timed(f"{m}+physics/held-out", lambda: hybrid_or_alone(
            new, lambda: LearnedModel(make_network(m), outputs=outputs, training=s),
            score, train, warmup, make_network(m).history))
        choices[f"{m}+physics"] = choice.to_dict()
        models[f"{m}+physics"] = ("hybrid", models[m][1] if choice.kept == ALONE_KEPT else
                                  timed(f"{m}+physics", lambda: new().fit(train)))
    return models


def _peers(models: dict, train, outputs, peers, preset: str, seed: int, timed) -> dict[str, str]:
    """Each peer of several outputs fitted on ``train`` (its preset's settings, ``compare``'s), in ``models`` as
    ``peer:NAME``; returns those skipped (their optional package missing) with the note."""
    from ._compare import new_peer

    skipped = {}
    for name in peers:
        peer, note = new_peer(name, BUDGETS[preset], seed, outputs=outputs)
        if peer is None:
            skipped[name] = note
            continue
        models[f"peer:{name}"] = ("peer", timed(f"peer:{name}", lambda: peer.fit(train)))
    return skipped


def _score(name: str, kind: str, model, tests, outputs, category: str, warmup: int) -> list[tuple]:
    """Rows ``(direction, model, kind, "category:run/output", rmse, nrmse, n)`` of each test run and output, then
    pooled over the category's runs (``"category:all/output"``)."""
    from identification import output_columns

    from ._fit_outputs import predict_after

    measured, predicted, rows = [], [], []
    for t in tests:
        columns = output_columns(t, outputs, refuse_copies=False)
        measured.append(columns[warmup:])
        predicted.append(predict_after(model, t, columns, warmup))
    for run, y, p in [*((test_name(t), m, p) for t, m, p in zip(tests, measured, predicted)),
                      ("all", np.vstack(measured), np.vstack(predicted))]:
        for j, o in enumerate(outputs):
            rows.append(("forward", name, kind, f"{category}:{run}/{o}", rmse(y[:, j], p[:, j]),
                         nrmse(y[:, j], p[:, j]), int(y.shape[0])))
    return rows


def pooled_table(rows, outputs, category: str) -> dict[str, dict[str, float]]:
    """``{model: {output: pooled RMSE}}`` on ``category``."""
    table: dict[str, dict[str, float]] = {}
    for _, model, _, test, value, *_ in rows:
        cat, _, rest = test.partition(":")
        run, _, output = rest.rpartition("/")
        if cat == category and run == "all":
            table.setdefault(model, {})[output] = value
    return table


def _write_tables(out: Path, rows, outputs, data, choices: dict | None = None) -> None:
    lines = ["direction,model,kind,test,output,rmse,nrmse,n"]
    for direction, model, kind, test, value, nr, n in rows:
        where, _, output = test.rpartition("/")
        lines.append(f"{direction},{model},{kind},{where},{output},{value:.6g},{nr:.6g},{n}")
    write_text(out / "compare.csv", "\n".join(lines) + "\n")
    kinds = {model: kind for _, model, kind, *_ in rows}
    text = [f"# Comparison of {', '.join(outputs)} (forward)", "",
            f"Data `{data.name}`: {len(data.train)} training runs. Pooled test RMSE per output, each model from each "
            "test run's warm-up window; in brackets, each of ours over the best peer on that output.", ""]
    for category in data.tests:
        table = pooled_table(rows, outputs, category)
        peers = {m: s for m, s in table.items() if kinds[m] == "peer"}
        best_peer = {o: min(peers, key=lambda m: peers[m][o]) for o in outputs} if peers else {}
        text += [f"## {category}", "", "| model | kind | " + " | ".join(outputs) + " |",
                 "|---|---|" + "---|" * len(outputs)]
        for model, scores in table.items():
            cells = [f"{scores[o]:.4g}" + (f" ({scores[o] / peers[best_peer[o]][o]:.2f})" if model not in peers
                                           and best_peer and peers[best_peer[o]][o] > 0 else "") for o in outputs]
            text.append(f"| {model} | {kinds[model]} | " + " | ".join(cells) + " |")
        ours = {m: s for m, s in table.items() if kinds[m] != "peer"}
        best = {o: min(ours, key=lambda m: ours[m][o]) for o in outputs}
        text += ["", "Best of ours per output: " + ", ".join(
            f"{o} `{best[o]}` {ours[best[o]][o]:.4g}" + (f" ({ours[best[o]][o] / peers[best_peer[o]][o]:.2f}x the best "
                                                        f"peer, `{best_peer[o]}`)" if best_peer else "")
            for o in outputs) + ".", ""]
    if choices:
        text += ["## Hybrids or their networks alone", "",
                 "Held out: each output's mean square over its spread, averaged (run.json's hybrid_choice).", "",
                 *(f"- {HybridChoice(**c).line(name)}" for name, c in choices.items()), ""]
    write_text(out / "compare.md", "\n".join(text))


def _plot(path: Path, rows, outputs, data) -> None:
    """Pooled RMSE of every model per output (one panel per output, the first test category's)."""
    from ._card import _plt, _save

    plt = _plt()
    category = next(iter(data.tests))
    table = pooled_table(rows, outputs, category)
    models = list(table)
    fig, axes = plt.subplots(1, len(outputs), figsize=(3.4 * len(outputs), 3.2), squeeze=False)
    for ax, o in zip(axes[0], outputs):
        ax.barh(range(len(models)), [table[m][o] for m in models], color="C0")
        ax.set_yticks(range(len(models)), models if ax is axes[0][0] else [""] * len(models), fontsize=8)
        ax.set_xlabel(f"{o} RMSE ({category})")
        ax.invert_yaxis()
    path.parent.mkdir(parents=True, exist_ok=True)
    _save(fig, path, plt)
