"""Figures like the seed paper's Fig. 7: predicted versus measured loops and time series."""

from __future__ import annotations

from pathlib import Path

from physics.data.io import atomic_path
from hybrid.networks import NETWORKS, network_label
from ._scoring import label

__all__ = ["plot_comparison", "plot_comparisons"]

#: A network's colour is its place in the registry (the paper's FNN red, FNN-HIB green, LSTM orange);
#: the measured data is tab:blue.
PALETTE = ("tab:red", "tab:green", "tab:orange", "tab:purple", "tab:brown", "tab:pink", "tab:olive", "tab:cyan")


def _color(name: str) -> str:
    order = list(NETWORKS)
    return PALETTE[order.index(name) % len(PALETTE)] if name in order else "k"


def _axis_label(name: str, unit: str) -> str:
    return f"{name} ({unit})" if unit else name


def plot_comparison(models: dict, traj, path: str | Path, title: str = "") -> Path:
    """One figure: a loop panel per model (predicted and measured output versus input) and
    the time series of all of them; ``models`` maps a model name to a fitted LearnedModel."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    from physics.data import rmse

    direction = next(iter(models.values())).direction
    view = traj.swap() if direction == "inverse" else traj
    preds = {name: m.predict(traj) for name, m in models.items()}
    n = len(models)
    fig, axes = plt.subplots(1, n + 1, figsize=(4.2 * (n + 1), 3.6), constrained_layout=True)
    xlabel = _axis_label(view.input_name, view.input_unit)
    ylabel = _axis_label(view.output_name, view.output_unit)
    for ax, (name, yhat) in zip(axes, preds.items()):
        ax.plot(view.u, view.y, color="tab:blue", lw=1.0, label="measured")
        ax.plot(view.u, yhat, color=_color(name), lw=1.0, label=network_label(name))
        ax.set_title(f"{network_label(name)} (RMSE {rmse(view.y, yhat):.3g} {view.output_unit})")
        ax.set_xlabel(xlabel)
        ax.set_ylabel(ylabel)
        ax.legend(loc="best", fontsize=8)
    ax = axes[-1]
    ax.plot(view.time, view.y, color="tab:blue", lw=1.2, label="measured")
    for name, yhat in preds.items():
        ax.plot(view.time, yhat, color=_color(name), lw=0.9, label=network_label(name))
    ax.set_xlabel("time (s)")
    ax.set_ylabel(ylabel)
    ax.set_title("time series")
    ax.legend(loc="best", fontsize=8)
    fig.suptitle(title or f"{direction}: {traj.source}")
    path = Path(path)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)
    return path


def plot_comparisons(fitted: dict, tests, folder: str | Path) -> list[Path]:
    """A figure per direction and test trajectory: ``folder/<direction>_<test>.png``."""
    folder = Path(folder)
    paths = []
    for direction in dict.fromkeys(d for d, _ in fitted):
        models = {name: m for (d, name), m in fitted.items() if d == direction}
        for traj in tests:
            paths.append(plot_comparison(models, traj, folder / f"{direction}_{label(traj)}.png"))
    return paths
