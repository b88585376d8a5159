"""What :func:`discover` found: the steps, the gap closing, and figures of the evidence."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from physics import Series


@dataclass(frozen=True)
class Step:
    """One effect added to the model.

    ``rmse_before``/``rmse_after`` are held-out RMSEs (output units) of the
    model without and with the new block, both re-fitted to the training data.
    ``parameters`` are the new block's fitted parameters, ``first_estimate``
    the diagnosis' guess they started from; ``candidates`` the diagnosis
    (best first) and ``tried`` the blocks fitted at this step.
    ``revised_from`` names the sibling effect first added at this step when
    the final check (with all other effects in the model) preferred this one;
    ``removed`` is True when that check found the final model did as well
    without it (the effect is then not named).
    """

    effect: str
    block: str
    rmse_before: float
    rmse_after: float
    train_rmse_before: float
    train_rmse_after: float
    parameters: dict[str, float]
    first_estimate: dict[str, float]
    description: str
    spec_after: str
    candidates: list[dict] = field(default_factory=list)
    tried: list[dict] = field(default_factory=list)
    revised_from: str | None = None
    removed: bool = False

    def to_dict(self) -> dict:
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


@dataclass(frozen=True)
class DiscoveryReport:
    """The outcome of :func:`discover`.

    Attributes
    ----------
    start : str
        Spec of the starting model.
    named_effects : list of str
        Effects added, in order (names from ``identification.EFFECTS``).
    steps : list of Step
    rmse_start, rmse_final : float
        Held-out RMSE of the fitted start model and of the final model.
    noise_floor : float
        Measurement noise estimated from the data (high-order differences).
    final_model : str
        Spec of the final model, e.g. ``"lag+boucwen+linear"``;
        ``final_settings`` holds what a spec does not (delay samples, polynomial centre).
    whiteness : float
        Largest autocorrelation of the final held-out residual at lags 1-10.
    split : str
        ``"trajectories"`` (every third held out) or ``"time"`` (each one's tail).
    failed_fits : list of dict
        Fits that did not succeed on the way (``spec``, ``settings``, IPOPT ``status``,
        ``iterations``): the search went on with the ones that did (a failed candidate is
        judged on its held-out error like any other, and its training cost counts as infinite
        in a delay's local search).
    model, start_model : physics.Series
        The final and the fitted starting model (not in :meth:`to_dict`).
    """

    start: str
    named_effects: list[str]
    steps: list[Step]
    rmse_start: float
    rmse_final: float
    noise_floor: float
    final_model: str
    final_parameters: dict[str, float]
    final_settings: dict
    whiteness: float
    split: str
    n_trajectories: int
    wall_time_s: float
    failed_fits: list[dict] = field(default_factory=list)
    model: Series | None = field(default=None, repr=False, compare=False)
    start_model: Series | None = field(default=None, repr=False, compare=False)

    @property
    def gap_closed(self) -> float:
        """Share of the start model's excess mean square over the noise floor that was removed."""
        start = self.rmse_start**2 - self.noise_floor**2
        if start <= 0:
            return 0.0
        return float(1 - max(self.rmse_final**2 - self.noise_floor**2, 0.0) / start)

    def to_dict(self) -> dict:
        return {
            "start": self.start, "named_effects": list(self.named_effects),
            "steps": [s.to_dict() for s in self.steps], "rmse_start": self.rmse_start,
            "rmse_final": self.rmse_final, "noise_floor": self.noise_floor,
            "gap_closed": self.gap_closed, "final_model": self.final_model,
            "final_parameters": dict(self.final_parameters), "final_settings": dict(self.final_settings),
            "whiteness": self.whiteness, "split": self.split, "n_trajectories": self.n_trajectories,
            "wall_time_s": self.wall_time_s, "failed_fits": [dict(f) for f in self.failed_fits],
        }

    def summary(self) -> str:
        lines = [f"start '{self.start}': held-out RMSE {self.rmse_start:.3g} "
                 f"(noise floor {self.noise_floor:.3g})"]
        for s in self.steps:
            lines.append(f"missing effect: {s.description}; RMSE {s.rmse_before:.3g} -> {s.rmse_after:.3g}")
        if not self.steps:
            lines.append("no missing effect found")
        lines.append(f"final model '{self.final_model}': RMSE {self.rmse_final:.3g}")
        if self.failed_fits:
            lines.append(f"{len(self.failed_fits)} fit(s) failed on the way (went on with the others): "
                         + "; ".join(f"'{f['spec']}' {f['status']}" for f in self.failed_fits[:5])
                         + (" ..." if len(self.failed_fits) > 5 else ""))
        return "\n".join(lines)


# -- figures -----------------------------------------------------------------------------
class _Figures:
    """``plt.subplots`` on a bare Figure: never switches the user's backend (Jupyter)."""

    @staticmethod
    def subplots(*args, **kwargs):
        from matplotlib.figure import Figure

        fig = Figure(figsize=kwargs.pop("figsize", None))
        return fig, fig.subplots(*args, **kwargs)


def _plt():
    return _Figures


def plot_residual_signature(start_model: Series, trajectories, path) -> Path:
    """Residual of the start model against input rate, coloured by direction of motion."""
    plt = _plt()
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for t in trajectories:
        u, y = np.asarray(t.u, float), np.asarray(t.y, float)
        r = y - start_model.simulate(u)
        rate = np.gradient(u, start_model.dt)
        axes[0].scatter(rate, r, s=2, c=np.sign(rate), cmap="coolwarm", vmin=-1, vmax=1)
        axes[1].scatter(u, r, s=2, c=np.sign(rate), cmap="coolwarm", vmin=-1, vmax=1)
    axes[0].set(xlabel="input rate (unit/s)", ylabel="residual", title="residual vs input rate")
    axes[1].set(xlabel="input", ylabel="residual", title="residual vs input (red rising, blue falling)")
    return _save(fig, path, plt)


def plot_loops(before: Series, after: Series, trajectories, path, max_runs: int = 3) -> Path:
    """Measured output against input with the start and final models' loops."""
    plt = _plt()
    runs = list(trajectories)[:max_runs]
    fig, axes = plt.subplots(1, len(runs), figsize=(4.5 * len(runs), 4), squeeze=False)
    for ax, t in zip(axes[0], runs):
        u, y = np.asarray(t.u, float), np.asarray(t.y, float)
        ax.plot(u, y, ".", ms=2, color="0.6", label="measured")
        ax.plot(u, before.simulate(u), lw=1, label=f"start ({before.spec})")
        ax.plot(u, after.simulate(u), lw=1, label=f"final ({after.spec})")
        ax.set(xlabel="input", ylabel="output", title=str(getattr(t, "source", "")))
    axes[0][0].legend(fontsize=7)
    return _save(fig, path, plt)


def plot_gap(report: DiscoveryReport, path) -> Path:
    """Held-out RMSE after each step, against the noise floor."""
    plt = _plt()
    labels = [report.start] + [s.effect for s in report.steps]
    values = [report.rmse_start] + [s.rmse_after for s in report.steps]
    fig, ax = plt.subplots(figsize=(max(4, 1.3 * len(labels)), 3.5))
    ax.plot(range(len(values)), values, "o-", label="held-out RMSE")
    ax.axhline(report.noise_floor, ls="--", color="k", lw=1, label="noise floor")
    ax.set_xticks(range(len(values)), [f"+{v}" if i else v for i, v in enumerate(labels)],
                  rotation=20, fontsize=8)
    ax.set(ylabel="RMSE (log scale)", title="the gap closing step by step")
    ax.set_yscale("log")
    ax.legend(fontsize=8)
    return _save(fig, path, plt)


def _save(fig, path, plt) -> Path:
    from physics.data.io import atomic_path

    path = Path(path)
    with atomic_path(path) as tmp:
        fig.tight_layout()
        fig.savefig(tmp, format=path.suffix.lstrip(".") or "png", dpi=110)
    return path
