# ---
# jupyter:
#   jupytext:
#     formats: ipynb,py:percent
#     text_representation:
#       extension: .py
#       format_name: percent
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # Reading an ablation's results
#
# An ablation sweeps model settings: a TOML file declares the data, the grid and the metrics,
# and `hybrid.experiments.ablation.run_ablation` (or `hyst ablate CONFIG.toml --out DIR`) trains one model
# per grid point on Dask, writes one resumable result file per run, then `results.csv` and
# summary figures. This notebook runs the tiny sweep of the bundled config `tiny` (FNN-HIB, two
# buffer lengths x two seeds, 2 epochs), reads `results.csv` with the standard `csv` module,
# checks it against the run files, plots it, and then runs a small sweep of its own: purely
# learned against hybrid.
#
# `HYST_FAST=1` trains the second sweep for fewer epochs.

# %%
import csv
import json
import os
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
from dask.distributed import LocalCluster

from hybrid.experiments.ablation import AblationConfig, config_path, run_ablation

FAST = os.environ.get("HYST_FAST", "") not in ("", "0")
OUT = Path(tempfile.mkdtemp(prefix="hyst_ablation_"))

# %% [markdown]
# ## 1. Run the tiny sweep
#
# `hyst ablate` starts a local cluster of worker *processes*. Inside a notebook or a script run
# top to bottom, we start a one-thread cluster in this process instead and hand its address to
# `run_ablation`: worker processes would re-run a script that has no `if __name__ == "__main__"`
# guard, and runs in parallel threads would share torch's global random state (one at a time,
# each run is reproducible from its seed).

# %%
config = AblationConfig.from_toml(config_path("tiny"))  # shipped with the package: `hyst ablate tiny`
print(config.description)
print("varied:", config.varied, "->", len(config.runs()), "runs")
cluster = LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=":0",
                       local_directory=OUT / "dask")  # not ./dask-scratch-space
tiny = run_ablation(config, OUT / "tiny", scheduler=cluster.scheduler_address, progress=False)
print(f"ran {len(tiny.ran)}, failed {len(tiny.failed)} in {tiny.seconds:.1f} s")
print(sorted(str(p.relative_to(OUT)) for p in (OUT / "tiny").rglob("*") if p.is_file()))

# %% [markdown]
# ## 2. Read results.csv
#
# One row per run: its id and status, the settings (empty where a setting does not apply to the
# model), the number of training runs, then the pooled test RMSE and NRMSE, one column per test
# trajectory, and the training time. The csv module reads strings; turn numbers into floats.


# %%
def read_results(path: Path) -> list[dict]:
    """Rows of results.csv, numbers as floats and empty cells as None."""
    def value(text: str):
        if text == "":
            return None
        try:
            return float(text)
        except ValueError:
            return text

    with open(path, newline="") as f:
        return [{k: value(v) for k, v in row.items()} for row in csv.DictReader(f)]


rows = read_results(OUT / "tiny" / "results.csv")
per_test = [k for k in rows[0] if k.startswith("rmse_")]
print(f"{'run':<22}{'buffer':>7}{'seed':>5}{'RMSE':>8}  " + "  ".join(per_test) + "   fit (s)")
for r in rows:
    print(f"{r['run_id']:<22}{r['buffer']:>7.0f}{r['seed']:>5.0f}{r['rmse']:>8.2f}  "
          + "  ".join(f"{r[k]:>{len(k)}.2f}" for k in per_test) + f"   {r['fit_seconds']:.2f}")

# %% [markdown]
# The table is a summary of the run files: each run's JSON record holds the same metrics. The
# pooled RMSE is the root of the mean squared error over every test sample; the test runs here
# have equal lengths, so it is the root mean square of the per-test RMSEs.

# %%
records = {r["run_id"]: json.loads((OUT / "tiny" / "runs" / f"{r['run_id']}.json").read_text()) for r in rows}
mismatch = max(abs(r["rmse"] - records[r["run_id"]]["metrics"]["rmse"]) for r in rows)
pooled = max(abs(r["rmse"] - np.sqrt(np.mean([r[k] ** 2 for k in per_test]))) for r in rows)
print(f"largest difference from the run files {mismatch:.1e}, from the per-test RMSEs {pooled:.1e}")

# %% [markdown]
# The sweep resumes: run again into the same folder, every finished run is skipped.

# %%
again = run_ablation(config, OUT / "tiny", scheduler=cluster.scheduler_address, progress=False, figures=False)
print(f"second call: ran {len(again.ran)}, skipped {len(again.skipped)}")

# %% [markdown]
# ## 3. Plot
#
# Each seed as a point, the mean over seeds as a line. Two epochs teach the network little, and
# the spread between seeds is as large as the effect of the buffer: the tiny sweep is for trying
# the machinery, not for conclusions. `run_ablation` drew its own summary figure as well.

# %%
buffers = sorted({r["buffer"] for r in rows})
fig, axes = plt.subplots(1, 2, figsize=(11, 4))
for seed in sorted({r["seed"] for r in rows}):
    pts = sorted((r["buffer"], r["rmse"]) for r in rows if r["seed"] == seed)
    axes[0].plot(*zip(*pts), "o", label=f"seed {seed:.0f}")
means = [np.mean([r["rmse"] for r in rows if r["buffer"] == b]) for b in buffers]
axes[0].plot(buffers, means, "k-", label="mean over seeds")
axes[0].set(xlabel="FNN-HIB buffer (samples)", ylabel="test RMSE (deg)", title="tiny.toml, read from results.csv")
axes[0].legend(fontsize=8)
axes[1].imshow(plt.imread(tiny.figures[0]))
axes[1].set_axis_off()
axes[1].set_title(tiny.figures[0].name)
fig.tight_layout()
plt.show()

# %% [markdown]
# ## 4. A sweep of our own: purely learned against hybrid
#
# The same data, one buffer length, and the physics as the varied setting: `"none"` (purely
# learned) against `"backlash+boucwen+linear"` (the physics identified on the training runs, the
# network learning the residual). A config is a dictionary as well as a file.

# %%
table = config.to_dict()
table["name"] = "pure_vs_hybrid"
table["requires"] = ["HybridModel"]
table["grid"].update(physics=["none", "backlash+boucwen+linear"], buffer=[10], hidden=[16],
                     epochs=[10 if FAST else 40], stride=[2], seed=[0, 1])
pure_vs_hybrid = AblationConfig.from_dict(table)
result = run_ablation(pure_vs_hybrid, OUT / "pure_vs_hybrid", scheduler=cluster.scheduler_address, progress=False)
cluster.close()
rows2 = read_results(OUT / "pure_vs_hybrid" / "results.csv")
by_physics = {p: [r["rmse"] for r in rows2 if r["physics"] == p] for p in dict.fromkeys(r["physics"] for r in rows2)}
for p, values in by_physics.items():
    print(f"physics {p!r:<28} test RMSE {np.mean(values):.3f} deg (seeds: {', '.join(f'{v:.3f}' for v in values)})")

# %%
fig, ax = plt.subplots(figsize=(6, 3.5))
for i, (p, values) in enumerate(by_physics.items()):
    ax.plot([i] * len(values), values, "o")
    ax.bar(i, np.mean(values), 0.5, alpha=0.3)
ax.set_xticks(range(len(by_physics)), ["purely learned" if p == "none" else f"hybrid ({p})" for p in by_physics])
ax.set(ylabel="test RMSE (deg)", yscale="log", title="FNN-HIB alone and as a residual")
fig.tight_layout()
plt.show()

# %% [markdown]
# ## Checks

# %%
assert len(rows) == 4 and all(r["status"] == "ok" for r in rows), [r["status"] for r in rows]
assert all(np.isfinite(r["rmse"]) and r["rmse"] > 0 and r["n_train"] == 4 for r in rows), rows
assert mismatch < 1e-9 and pooled < 1e-9, (mismatch, pooled)
assert len(again.ran) == 0 and len(again.skipped) == 4, (again.ran, again.skipped)
assert tiny.figures and tiny.figures[0].is_file()
assert all(r["status"] == "ok" for r in rows2) and len(rows2) == 4, rows2
assert max(by_physics["backlash+boucwen+linear"]) < 0.5 * min(by_physics["none"]), by_physics
print("all checks passed")
