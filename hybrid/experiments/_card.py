"""The model card of a model folder: ``report.md`` and the figures it shows."""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any

import numpy as np

from hybrid.networks import ALONE
from identification.discovery import substitution
from physics.data.io import atomic_path

__all__ = ["write_card", "short_name", "pooled", "physics_report", "substitution_line"]

MAX_RUNS = 6


def write_card(out: Path, result: Any, fit: dict, spec_info: dict, chosen: dict) -> Path:
    """Write ``out/report.md``, ``out/loops.png`` and ``out/residual.png``; returns the report's path."""
    runs = [r["run"] for r in result.rows]
    _plot_loops(out / "loops.png", result)
    _plot_residuals(out / "residual.png", result)
    first = result.predictions[0][0]
    unit = first.output_unit or "output units"
    peer = chosen.get("peer")
    report = physics_report(fit, spec_info)
    alone, network = result.residual.endswith(ALONE), result.residual.removesuffix(ALONE)
    title = ("physics only" if result.residual == "none" else f"the {network} network alone"
             if alone else f"{result.residual} residual")
    what = (f"**The model is the peer {peer}**: it beat every physics spec on the selection's held-out folds "
            f"(below). The best physics, `{result.spec}`, is fitted beside it for comparison (the physics column). "
            if peer else f"**The model is the {network} network alone**: on the runs held out of "
            f"the residual's fits it beat the physics `{result.spec}` ({_how(report)}) and every hybrid on it, whose "
            "networks the physics misled (below); the physics is fitted beside it for comparison. "
            if alone else f"Physics `{result.spec}` ({_how(report)}), residual network: **{result.residual}**. ")
    files = {"physics.json": "fit", "peer.json": "the peer's coefficients", "model.pt": "checkpoint"}
    lines = [f"# Model card: {peer + ' (peer)' if peer else result.spec + ', ' + title}", "", _data_line(result), "",
             what + f"Fitted on {sum(r['set'] == 'train' for r in result.rows)} runs, "
             f"{sum(r['set'] == 'test' for r in result.rows)} held out. Files: "
             + "".join(f"`{f}` ({files[f]}), " for f in dict.fromkeys(["physics.json", chosen.get("model") or
                                                                         ("physics.json" if result.residual == "none"
                                                                          else "model.pt")]))
             + "`step.casadi` (CasADi step for MPC; its sidecar states the initial-state rule).", "",
             *([f"**Warning: {note}.**", ""] if (note := substitution_line(fit, spec_info)) else []),
             "## RMSE per run", "", _protocol(result.warmup), "",
             f"| run | set | physics RMSE ({unit}) | model RMSE ({unit}) | linear ARX (peer) RMSE ({unit}) |",
             "|---|---|---|---|---|"]
    lines += [f"| {r['run']} | {r['set']} | {r['physics_rmse']:.4g} | {r['model_rmse']:.4g} | {r['arx_rmse']:.4g} |"
              for r in result.rows]
    ratios = {}
    for part in ("train", "test"):
        sel = [r for r in result.rows if r["set"] == part]
        if sel:
            mean = {k: pooled(sel, k) for k in ("physics_rmse", "model_rmse", "arx_rmse")}
            ratios[part] = mean["model_rmse"] / mean["arx_rmse"] if mean["arx_rmse"] > 0 else math.nan
            lines.append(f"| **pooled ({part})** | {part} | {mean['physics_rmse']:.4g} | {mean['model_rmse']:.4g} | "
                         f"{mean['arx_rmse']:.4g} |")
    part = "test" if "test" in ratios else "train"
    if part in ratios:
        lines += ["", f"Against the peer: this model's error is {ratios[part]:.2f}x a linear ARX's (na = nb = 3, "
                      f"fitted on the same runs, same protocol) on the {part} runs"
                  + ("." if part == "test" else " (no held-out runs given: `--test`).")]
    lines += _remarks(result)
    lines += _intervals(result, unit)
    lines += ["", "![loops](loops.png)", "", "![residual over time](residual.png)", "",
              "## Physics parameters", "", "| parameter | value | standard error | unit |", "|---|---|---|---|"]
    units = {"input unit": first.input_unit or "input unit", "output unit": first.output_unit or "output unit"}
    for name, value in fit["parameters"].items():
        se = fit["standard_errors"].get(name)
        err = "fixed" if name in fit.get("fixed", {}) else "unavailable" if se is None else f"{se:.3g}"
        unit = fit["units"].get(name, "")
        for generic, actual in units.items():
            unit = unit.replace(generic, actual)
        lines.append(f"| {name} | {value:.6g} | {err} | {unit} |")
    lines += ["", f"IPOPT status {fit['status']}, {fit['iterations']} iterations, train RMSE "
              f"{fit['train_rmse']:.4g}, noise std {fit['noise_std']:.4g}."]
    if report["failed"]:
        lines += ["", "Specs that did not fit (the next was used):", ""] + [f"- '{k}': {v}"
                                                                             for k, v in report["failed"].items()]
    lines += ["", "## Why this physics", ""] + _why(spec_info, report)
    lines += ["", "## Why this residual", ""] + _why_residual(chosen, getattr(result, "dropped", ()))
    lines += ["", f"Stage times (s): {', '.join(f'{k} {v:.1f}' for k, v in result.seconds.items())}.",
              f"Runs: {', '.join(runs)}."]
    path = out / "report.md"
    with atomic_path(path) as tmp:
        tmp.write_text("\n".join(lines) + "\n")
    return path


def _intervals(result, unit: str) -> list[str]:
    """The intervals' section: how they were calibrated, coverage and width per test run, or why none."""
    cal = getattr(result, "calibration", None) or {}
    if result.intervals is None:
        return ["", "## Prediction intervals", "", f"None: {cal.get('why', 'not calibrated')}"] if cal else []
    level, held = result.intervals.level, result.intervals.runs_
    pieces = all(str(r).endswith("]") for r in held)  # "run.csv[40:80]": a piece of a run
    widened = " widened for a new run's offset" if getattr(result.intervals, "shift", False) else ""
    lines = ["", "## Prediction intervals", "",
             f"Split-conformal {level:.0%} intervals{widened}, calibrated on {len(held)} {'pieces of runs' if pieces else 'runs'} "
             f"held out of a fit ({', '.join(short_name(r) for r in held)}): half-width {cal['half_width']:.4g} "
             f"{unit} inside the training data, growing with the input's distance beyond it "
             "(`hyst predict --interval`). The band is drawn in the residual figure."]
    report = cal.get("report")
    if report:  # what the calibration saw and whether it is enough, from the training runs alone
        if cal.get("source"):
            lines += ["", f"Held-out predictions: {cal['source']}; conditions: {cal.get('conditions', 'none')}."]
        lines += ["", ("" if report["enough"] else "**Too few for the stated level**: ") + " ".join(report["notes"])]
    elif pieces:
        lines += ["", "**A weaker assumption than held-out runs**: with fewer than 3 runs the calibration groups are "
                      "pieces of the same recordings, which share their day, mounting and drift; a new recording may "
                      "differ more than the pieces differ from each other. Record more runs for intervals that hold "
                      "across recordings."]
    lines += ["", "With the tip measured now and then, `hyst predict --interval 0.9 --measure-every N` centres the band on the last "
                  "measured error and adapts its width from the misses (adaptive conformal inference)."]
    rows = [r for r in result.rows if "coverage" in r]
    test = [r for r in rows if r["set"] == "test"]
    if not test:
        return lines + ["", "No test runs to check the coverage on (`--test`)."]
    beyond = [f"{r['run']} ({r['run_outside']})" for r in test if r.get("run_outside")]
    if beyond:  # from the training runs alone, whatever the test then scores
        reaches = getattr(result.intervals, "reaches_", [])
        floor = (f"at least as wide as the {sum(d > 0 for d in reaches)} held-out run(s) that lay outside their fits' "
                 "runs needed, and " if any(d > 0 for d in reaches) else "")
        lines += ["", f"**Outside the training runs**, before any test is scored: {'; '.join(beyond)}. There the band "
                      f"is {floor}widens with that distance, and no {level:.0%} coverage is promised."]
    lines += ["", f"| run | coverage | mean width ({unit}) | width / RMSE | samples outside the data |",
              "|---|---|---|---|---|"]
    lines += [f"| {r['run']} | {r['coverage']:.1%} | {r['width']:.4g} | {r['width'] / r['model_rmse']:.2f} | "
              f"{r['outside']:.1%} |" for r in test]
    n = np.array([len(t.y) for r, (t, *_) in zip(result.rows, result.predictions) if r in test], dtype=float)
    pooled = {k: float(np.sum(n * [r[k] for r in test]) / n.sum()) for k in ("coverage", "width", "outside")}
    lines.append(f"| **all test runs** | {pooled['coverage']:.1%} | {pooled['width']:.4g} | | {pooled['outside']:.1%} |")
    if pooled["outside"] > 0:
        lines += ["", f"{pooled['outside']:.1%} of the test samples are outside the training data (input, rate or "
                      "output beyond its range, or far from every training sample): there the model extrapolates "
                      "and the interval is wider but not guaranteed (marked in the residual figure)."]
    if pooled["coverage"] < level - 0.05:
        lines += ["", f"**The test runs are covered less than asked ({pooled['coverage']:.1%} of {level:.0%})**: "
                      "they differ from the training runs in a way the held-out runs did not show."]
    return lines


def pooled(rows, key: str) -> float:
    """The RMSE ``key`` of the rows pooled over their scored samples (``identify`` pools its runs so)."""
    n = np.array([r.get("samples", 1) for r in rows], dtype=float)
    return float(math.sqrt(np.sum(n * np.square([r[key] for r in rows])) / n.sum()))


def short_name(source) -> str:
    """A run's name for tables and figures: its file's stem, not its absolute path."""
    text = str(source or "")
    piece = re.search(r"\[\d+:\d+\]$", text)  # a piece of a run: "data/run.csv[40:80]" -> "run[40:80]"
    if piece:
        return short_name(text[:piece.start()]) + piece.group()
    return Path(text).stem if text else "run"


def _data_line(result) -> str:
    """The data the model was fitted on, as a reader needs it: rate, channels, units."""
    first = result.predictions[0][0]
    rate = 1.0 / first.dt if first.dt else math.nan
    name = lambda n, u: f"`{n or '?'}`" + (f" ({u})" if u else "")  # noqa: E731
    return (f"Data: {sum(r['set'] == 'train' for r in result.rows)} training and "
            f"{sum(r['set'] == 'test' for r in result.rows)} test runs at {rate:.6g} Hz (the model's rate); input "
            f"{name(first.input_name, first.input_unit)}, output {name(first.output_name, first.output_unit)}.")


def _remarks(result) -> list[str]:
    """What a reader should not miss: test runs far worse than the training runs, and test inputs
    outside the range the model was fitted on."""
    train = [t for r, (t, *_) in zip(result.rows, result.predictions) if r["set"] == "train"]
    test = [(r, t) for r, (t, *_) in zip(result.rows, result.predictions) if r["set"] == "test"]
    if not train or not test:
        return []
    out = []
    mean = lambda rows: pooled(rows, "model_rmse")  # noqa: E731
    train_rmse, test_rmse = mean([r for r in result.rows if r["set"] == "train"]), mean([r for r, _ in test])
    lo = min(float(np.min(t.u)) for t in train)
    hi = max(float(np.max(t.u)) for t in train)
    span = max(hi - lo, 1e-12)
    outside = np.concatenate([(t.u < lo - 0.01 * span) | (t.u > hi + 0.01 * span) for _, t in test])
    if test_rmse > 2 * train_rmse:
        out.append(f"**The test runs are {test_rmse / train_rmse:.1f}x worse than the training runs** "
                   f"({test_rmse:.4g} against {train_rmse:.4g}): they differ from what the model was fitted on "
                   "(another baseline, range or rate); fit on runs that cover them, or expect this error there.")
    if outside.any():
        t_lo = min(float(np.min(t.u)) for _, t in test)
        t_hi = max(float(np.max(t.u)) for _, t in test)
        out.append(f"**{100 * outside.mean():.1f} % of the test samples have an input outside the training range** "
                   f"({t_lo:.4g} to {t_hi:.4g} against {lo:.4g} to {hi:.4g}): there the model extrapolates.")
    return [""] + [f"- {line}" for line in out] if out else []


#: How the physics policy reached the spec (``PhysicsReport.how``), in the card's words.
HOW = {"selection": "chosen on runs left out of the fit", "first": "given", "given": "given",
       "ranking": "the first of the ranked specs that fitted",
       "fallback": "a fallback: the specs before it did not fit"}


def substitution_line(fit: dict, spec_info: dict) -> str:
    """The card's and ``hyst fit``'s line when the physics asked for could not be fitted: ``"--physics
    'gpi+linear' could not be fitted (why); used 'backlash+linear' instead"`` (the selection's best
    physics, with ``auto``); "" when it was used."""
    note = substitution(physics_report(fit, spec_info))
    asked = "the selection's best physics" if spec_info.get("how") == "selection" else "--physics"
    return f"{asked} {note}" if note else ""


def physics_report(fit: dict, spec_info: dict) -> dict:
    """The physics policy's report kept with the fit (``PhysicsReport.to_dict``: the spec, how it was
    reached, the specs tried and why each failed). A fit from before the report was kept (a folder
    resumed) has its failures only: ``how`` is the physics stage's."""
    if "physics_report" in fit:
        return fit["physics_report"]
    failed = dict(f[1:].split("': ", 1) for f in fit.get("failures", []) if f.startswith("'") and "': " in f)
    return {"spec": fit.get("spec", ""), "how": "first" if spec_info["how"] == "given" else spec_info["how"],
            "tried": [*failed, fit.get("spec", "")], "failed": failed, "candidates": list(spec_info["ranked"]),
            "selection_error": None}


def _how(report: dict) -> str:
    return HOW.get(report["how"], report["how"])


def _why(spec_info: dict, report: dict) -> list[str]:
    from identification.discovery import evidence

    if spec_info["how"] != "selection":
        tried = "" if len(report["tried"]) < 2 else (
            f" Tried in order: {', '.join(f'`{s}`' for s in report['tried'])}; the first that fitted is used.")
        return ["The spec was given (`--physics`)." + tried]
    sel = spec_info["selection"]
    out = [f"Each candidate was fitted without some training runs and scored on them ({sel['how']}, "
           f"{len(sel['folds'])} folds); a block was kept only if it lowered that error by more than the "
           f"margin. Path: {' -> '.join(f'`{p}`' for p in sel['path'])}.", "",
           "| spec | held-out RMSE | train RMSE |", "|---|---|---|"]
    cv, peers = sel["cv_rmse"], sel.get("peers", [])
    stopped = sel.get("stopped", {})
    for spec in sorted(cv, key=lambda k: (k in stopped, math.inf if cv[k] is None else cv[k])):  # partial ones last
        held = f"failed: {sel.get('failed', {}).get(spec, '')}".rstrip(": ") if cv[spec] is None else f"{cv[spec]:.4g}"
        if spec in stopped:
            held += f" (over {stopped[spec]} folds: stopped once it could not win)"
        label = " (chosen)" if spec == sel["spec"] else " (peer, same folds and warm-up)" if spec in peers else ""
        out.append(f"| {spec}{label} | {held} | {sel['train_rmse'].get(spec, math.nan):.4g} |")
    out += ["", "A block is kept when it beats the spec held on the errors paired per fold: lower by more than the "
                "margin pooled, lower on most folds, and lower by more than one standard error of the paired "
                "differences; candidates equal on that evidence each grow, and of the ends equal to the best the "
                f"simplest (fewest parameters) is kept. {evidence(len(sel['folds']), sel['how'])}"]
    if sel.get("peer"):
        out += ["", f"**The peer {sel['peer']} beats `{sel['spec']}` on the same held-out folds** by the same rule "
                    "(by the margin pooled and on most folds), so it is the model: the physics adds no evidence over "
                    "it on these runs. Record runs that show the effect you expect, or give `--physics` to use "
                    "physics anyway."]
    return out


def _why_residual(chosen: dict, dropped=()) -> list[str]:
    if chosen.get("peer"):
        return [f"None: {chosen['how']}, so it is the model (no network is trained on it)."]
    scores = chosen.get("validation_rmse") or {}
    if not scores:
        return [f"The residual was given (`--residual {chosen['residual']}`)."]
    held = ", ".join(short_name(r) for r in chosen.get("held_out_runs", []))
    how = f" ({chosen['how']})" if chosen.get("how") else ""
    what = f"trained without {held}{how} and scored on them" if held else f"trained and scored on the training runs{how}"
    out = [f"Each candidate was {what} (RMSE): "
           + ", ".join(f"{k} {v:.4g}" for k, v in scores.items()) + f"; kept: **{chosen['residual']}**."
           + (" (\"alone\": the network without the physics, so that a hybrid is never kept where the network "
              "alone does better.)" if any(k.endswith(ALONE) for k in scores) else "")]
    if dropped:
        out.append(f"The measured input(s) {', '.join(f'`{m}`' for m in dropped)} are **not read**: the physics "
                   "alone, which ignores them, did better held out than every network that reads them.")
    return out


def _plt():
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


def _predictions(result):
    """Up to MAX_RUNS rows with their run and model output, test runs first (what users look at)."""
    both = list(zip(result.rows, result.predictions))
    both = [b for b in both if b[0]["set"] == "test"] + [b for b in both if b[0]["set"] == "train"]
    return [(r, t, y, y_phys, band) for r, (t, y, y_phys, band) in both[:MAX_RUNS]]


def _plot_loops(path: Path, result) -> None:
    plt = _plt()
    preds = _predictions(result)
    fig, axes = plt.subplots(1, len(preds), figsize=(3.2 * len(preds), 3.0), squeeze=False)
    for ax, (r, t, y, *_) in zip(axes[0], preds):
        ax.plot(t.u, t.y, color="0.7", lw=2.2, label="measured")
        ax.plot(t.u, y, color="C0", lw=0.8, label="model")
        ax.set_title(f"{r['run']} ({r['set']})", fontsize=9)
        ax.set_xlabel(_label(t.input_name, t.input_unit, "input"))
    axes[0][0].set_ylabel(_label(preds[0][1].output_name, preds[0][1].output_unit, "output"))
    axes[0][0].legend(fontsize=8)
    _save(fig, path, plt)


def _plot_residuals(path: Path, result) -> None:
    plt = _plt()
    preds = _predictions(result)
    fig, axes = plt.subplots(len(preds), 1, figsize=(7, 1.6 * len(preds)), squeeze=False, sharex=False)
    unit = preds[0][1].output_unit
    for ax, (r, t, y, y_phys, band) in zip(axes[:, 0], preds):
        if band is not None:
            ax.fill_between(t.time, -band.half_width, band.half_width, color="C0", alpha=0.18, lw=0,
                            label=f"{result.intervals.level:.0%} interval")
            if band.outside.any():
                ax.plot(t.time[band.outside], np.zeros(int(band.outside.sum())), "|", color="k", ms=6,
                        label="outside the data")
        ax.plot(t.time, t.y - y_phys, color="0.6", lw=0.8, label="physics")
        ax.plot(t.time, t.y - y, color="C3", lw=0.8, label="model")
        ax.axhline(0, color="0.5", lw=0.5)
        ax.set_title(f"{r['run']} ({r['set']})", fontsize=9, loc="left")
        ax.set_ylabel(f"error ({unit})" if unit else "error", fontsize=8)
    axes[0, 0].legend(fontsize=8, loc="upper right")
    axes[-1, 0].set_xlabel("time (s)")
    _save(fig, path, plt)


def _save(fig, path: Path, plt) -> None:
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=150, format="png")
    plt.close(fig)


def _label(name: str | None, unit: str | None, fallback: str) -> str:
    """An axis label: the quantity and its unit (``Angle x (deg)``)."""
    return f"{name or fallback}" + (f" ({unit})" if unit else "")


def _protocol(warmup: int) -> str:
    if not warmup:
        return "Each run simulated free from rest at its first input, scored on every sample."
    return (f"Each run simulated free after its first {warmup} measured samples, which set the model's state "
            "(the export's `init` does the same), and scored on the samples after them.")
