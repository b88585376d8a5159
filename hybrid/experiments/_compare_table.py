"""The tables of ``hyst compare``: one row per score, ``compare.csv`` and the pooled ``compare.md``.

The job (:mod:`._compare`) and its figures (:mod:`._compare_plots`) both read them.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from physics.data import Trajectory
from physics.data.io import write_text
from ._datasets import CompareData
from ._hybrid_or_alone import HybridChoice
from ._scoring import Score, label

__all__ = ["Row", "rows", "test_name", "pooled", "write_tables", "markdown", "interval_markdown"]


@dataclass(frozen=True)
class Row:
    """One score: ``kind`` is "physics", "learned", "hybrid" or "peer" (another tool's model, ``hybrid.peers``);
    ``test`` is "<category>:<run>" or "<category>:all"."""

    direction: str
    model: str
    kind: str
    test: str
    rmse: float
    nrmse: float
    n: int


def _run_name(test: str) -> str:
    return test[5:] if test.startswith("test_") else test


def test_name(traj: Trajectory) -> str:
    """A test run's name in the table: its label without the ``test_`` prefix."""
    return _run_name(label(traj))


def rows(scores: list[Score], kind: str, category: str) -> list[Row]:
    """The scores of one model on one test category as table rows."""
    return [Row(s.direction, s.model, kind, f"{category}:{_run_name(s.test)}", s.rmse, s.nrmse, s.n) for s in scores]


def write_tables(rows: list[Row], out: Path, data: CompareData, intervals: list[dict] = (),
                 skipped: dict[str, str] | None = None, choices: dict[str, dict] | None = None) -> None:
    lines = ["direction,model,kind,test,rmse,nrmse"] + [
        f"{r.direction},{r.model},{r.kind},{r.test},{r.rmse:.6g},{r.nrmse:.6g}" for r in rows]
    write_text(out / "compare.csv", "\n".join(lines) + "\n")
    text = markdown(rows, data)
    if choices:  # a hybrid row whose network alone did better held out is that network: said, with the evidence
        text += ("\n## Hybrids or their networks alone\n\nEach hybrid and its network alone trained without the runs "
                 "(or each run's last branch) below and scored on them after the warm-up; where the network alone "
                 "does better there, it is the hybrid's row (run.json's hybrid_choice).\n\n" + "".join(
                     f"- {HybridChoice(**c).line(key)}\n" for key, c in choices.items()))
    if intervals:
        keys = ("model", "kind", "test", "level", "coverage", "width", "width_over_rmse", "outside", "held_out_runs")
        write_text(out / "intervals.csv", "\n".join([",".join(keys)] + [
            ",".join(f"{r[k]:.6g}" if isinstance(r[k], float) else str(r[k]) for k in keys) for r in intervals]) + "\n")
        text += "\n" + interval_markdown(intervals, data)
    if skipped:  # asked for, and not calibrated: the table says why rather than leaving them out unsaid
        text += "\n## Intervals not calibrated\n\n" + "".join(
            f"- {key.split('/', 1)[1]}: {reason}\n" for key, reason in skipped.items())
    write_text(out / "compare.md", text)


def interval_markdown(intervals: list[dict], data: CompareData) -> str:
    """The forward models' intervals per test category: coverage, width, width / RMSE, share outside."""
    unit = data.train[0].output_unit or "output units"
    level = intervals[0]["level"]
    lines = [f"## Forward, {level:.0%} conformal intervals", "",
             "Calibrated on training runs held out of each model's fit (intervals.csv); coverage is the share of "
             f"test samples inside; width the mean of hi - lo ({unit}); outside the share of samples flagged "
             "outside the training data.", "", "| model | kind | test | coverage | width | width / RMSE | outside |",
             "|---|---|---|---|---|---|---|"]
    lines += [f"| {r['model']} | {r['kind']} | {r['test']} | {r['coverage']:.1%} | {r['width']:.4g} | "
              f"{r['width_over_rmse']:.2f} | {r['outside']:.1%} |" for r in intervals]
    return "\n".join(lines) + "\n"


def pooled(rows: list[Row], direction: str) -> dict[tuple[str, str], Row]:
    return {(r.model, r.test.split(":")[0]): r for r in rows if r.direction == direction and r.test.endswith(":all")}


def markdown(rows: list[Row], data: CompareData) -> str:
    first = data.train[0]
    units = {"forward": first.output_unit or "output units", "inverse": first.input_unit or "input units"}
    lines = [f"# Physics, learned and hybrid models on {data.name or 'data'}", "",
             "Pooled RMSE per test category (per-run rows in compare.csv). id: the paper's tests; "
             "ood_*: out of distribution; data_k: trained on k runs; diverged: the prediction is not "
             "finite on a test run.", ""]
    if data.noise_floor is not None:
        lines += [f"Noise floor of the virtual catheter: {data.noise_floor:.3g} deg (forward).", ""]
    for direction in dict.fromkeys(r.direction for r in rows):
        table = pooled(rows, direction)
        cats = list(dict.fromkeys(c for _, c in table))
        models = list(dict.fromkeys(m for m, _ in table))
        kinds = {r.model: r.kind for r in rows}
        lines += [f"## {direction.capitalize()}, RMSE ({units[direction]})", "",
                  "| model | kind | " + " | ".join(cats) + " |", "|---" * (len(cats) + 2) + "|"]
        for m in models:
            cells = [("diverged" if table[m, c].rmse == float("inf") else f"{table[m, c].rmse:.4g}")
                     if (m, c) in table else "-" for c in cats]
            lines.append(f"| {m} | {kinds[m]} | " + " | ".join(cells) + " |")
        lines += ["", *summary(table, cats, kinds, data.noise_floor if direction == "forward" else None), ""]
    return "\n".join(lines) + "\n"


def summary(table, cats, kinds, noise_floor) -> list[str]:
    """Best hybrid against the best pure network (and the noise floor), and the best of ours against the
    best peer, per category."""
    out = []
    for c in cats:
        best = {k: min(((r.rmse, m) for (m, cc), r in table.items() if cc == c and kinds[m] == k), default=None)
                for k in ("learned", "hybrid", "physics")}
        peer = min(((r.rmse, m) for (m, cc), r in table.items() if cc == c and kinds[m] == "peer"), default=None)
        ours = min((b for b in best.values() if b is not None), default=None)
        if best["hybrid"] is not None and best["learned"] is not None:
            (h, hm), (p, pm) = best["hybrid"], best["learned"]
            text = f"- {c}: best hybrid {hm} {h:.4g} vs best pure network {pm} {p:.4g} (ratio {h / p:.2f})"
            if noise_floor:
                text += f"; {h / noise_floor:.2f}x the noise floor"
            out.append(text)
        if peer is not None and ours is not None:
            out.append(f"- {c}: best of ours {ours[1]} {ours[0]:.4g} vs best peer {peer[1]} {peer[0]:.4g} "
                       f"(ratio {ours[0] / peer[0]:.2f})")
    return out
