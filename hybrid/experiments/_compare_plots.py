"""Figures of ``hyst compare``: pooled RMSE per category, and one id test run with the best models."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from physics.data.io import atomic_path
from ._compare_table import pooled, test_name

__all__ = ["plot_all"]

COLORS = {"physics": "tab:blue", "learned": "tab:red", "hybrid": "tab:green", "peer": "tab:gray"}


def _save(fig, path: Path) -> Path:
    import matplotlib.pyplot as plt

    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)
    return path


def plot_all(fitted: dict, data, rows, folder: str | Path) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    folder, paths = Path(folder), []
    for direction, models in fitted.items():
        table = pooled(rows, direction)
        cats = list(dict.fromkeys(c for _, c in table))
        names = list(dict.fromkeys(m for m, _ in table))
        kinds = {r.model: r.kind for r in rows}
        fig, ax = plt.subplots(figsize=(1.6 + 1.3 * len(cats), 4.2), constrained_layout=True)
        width = 0.8 / max(len(names), 1)
        for j, m in enumerate(names):
            vals = [table[m, c].rmse if (m, c) in table and np.isfinite(table[m, c].rmse) else np.nan for c in cats]
            ax.bar(np.arange(len(cats)) + j * width, vals, width, label=m,
                   color=COLORS[kinds[m]], alpha=0.35 + 0.65 * (j + 1) / len(names))
        ax.set_xticks(np.arange(len(cats)) + 0.4 - width / 2, cats, rotation=20)
        ax.set_yscale("log")
        ax.set_ylabel("pooled RMSE")
        ax.set_title(f"{direction}: physics (blue), learned (red), hybrid (green), peers (gray)")
        ax.legend(fontsize=7, ncol=2)
        paths.append(_save(fig, folder / f"{direction}_pooled.png"))

        tests = list(data.tests["id"])
        traj = next((t for t in tests if "0.45_mid" in test_name(t)), tests[0])
        ranked = {k: min(((table[m, "id"].rmse, m) for m in names if kinds[m] == k and (m, "id") in table),
                         default=None) for k in ("physics", "learned", "hybrid", "peer")}
        fig, ax = plt.subplots(figsize=(9, 3.8), constrained_layout=True)
        truth = traj.y if direction == "forward" else traj.u
        ax.plot(traj.time, truth, color="k", lw=1.4, label="measured")
        for kind, best in ranked.items():
            if best is not None:
                ax.plot(traj.time, models[best[1]][1].predict(traj), color=COLORS[kind], lw=0.9,
                        label=f"{best[1]} ({kind})")
        ax.set_xlabel("time (s)")
        ax.set_ylabel("tip angle" if direction == "forward" else "tendon displacement")
        ax.set_title(f"{direction}, id test {test_name(traj)}")
        ax.legend(fontsize=8)
        paths.append(_save(fig, folder / f"{direction}_id_{test_name(traj)}.png"))
    return paths
