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
# # From measured data to a controller
#
# A researcher's day with the tool: fetch the seed paper's catheter recordings, fit a model in one
# call (`hyst fit` on the command line), read its model card, check that the exported step
# function is the model, and track a tip-angle reference with MPC on it.
#
# `HYST_FAST=1` gives the physics spec and the residual network instead of choosing them.

# %%
import os
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from hybrid.control import TrackingMPC, reference_signal, rest_output, run_closed_loop
from hybrid.datasets import fetch_catheter_2023
from hybrid.experiments import fit_model_dir
from hybrid.export import ExportedModel, load
from identification import identify

FAST = os.environ.get("HYST_FAST", "") not in ("", "0")
OUT = Path(tempfile.mkdtemp(prefix="hyst_fit_"))

# %% [markdown]
# ## 1. Data
#
# `fetch_catheter_2023` downloads the ten runs once (checked by SHA-256) and loads them offline
# afterwards, resampled to 25 Hz: set 1 (decaying towards 3 mm) to fit, set 2 (towards 0 mm) to test.

# %%
split = fetch_catheter_2023()
train, test = list(split.train), list(split.test)
print([t.source for t in train], "->", [t.source for t in test])

# %% [markdown]
# ## 2. One call: physics, residual, export, model card

# %%
settings = dict(physics="lag+backlash+linear", residual="fnn-hib") if FAST else {}
result = fit_model_dir(train, OUT / "model", test=test, **settings)
print(f"physics {result.spec}, residual {result.residual}, stage times {result.seconds}")
print((OUT / "model" / "report.md").read_text()[:1500])

# %%
fig, ax = plt.subplots(figsize=(12, 3))
ax.imshow(plt.imread(OUT / "model" / "loops.png"))
ax.axis("off")
plt.show()

# %% [markdown]
# ## 3. The exported step is the model
#
# `step.casadi` starts a run from the same state as the model's own prediction (the rule is in
# its sidecar), so the two agree from the first sample on.

# %%
model = load(OUT / "model")
step = ExportedModel.load(OUT / "model" / "step.casadi")
run = test[0]
y_model = model.simulate(run.u) if result.residual == "none" else model.predict(run)
gap = np.abs(step.simulate(run.u) - y_model)
print(f"largest gap export vs model on {run.source}: {gap.max():.1e} deg (sample 0: {gap[0]:.1e})")

# %% [markdown]
# ## 4. Closing the loop
#
# The controller uses the exported model; the plant it drives is a twin of the catheter in its other
# state (set 2, never fitted on) with other physics (`lag+backlash+linear`), so the controller meets a
# catheter it does not know. The SQP stops after 30 iterations and applies its iterate ("converged"
# counts the solves that met the tolerance).

# %%
plant = identify("lag+backlash+linear", test).model()
horizon, duration = (10, 8.0) if FAST else (20, 20.0)
reference = reference_signal("sine", rest_output(step, 1.0), rest_output(step, 4.5), duration_s=duration)
mpc = TrackingMPC(step, u_bounds=(0.0, 6.0), horizon=horizon, solver="sqp")
loop = run_closed_loop(mpc, plant, reference, noise_std_deg=0.15, seed=0)
stats = mpc.stats.summary()
print(f"tracking RMSE {loop.rmse_deg:.3f} deg, median solve {stats['median_ms']:.1f} ms, "
      f"converged {100 * stats['success_rate']:.0f} %")

# %%
fig, axes = plt.subplots(2, 1, figsize=(10, 5), sharex=True)
axes[0].plot(loop.time, loop.reference, "k--", lw=1, label="reference")
axes[0].plot(loop.time, loop.y_true, lw=1, label="tip angle (plant)")
axes[1].plot(loop.time, loop.u, lw=1)
axes[0].set(ylabel="tip angle (deg)")
axes[1].set(ylabel="tendon (mm)", xlabel="time (s)")
axes[0].legend(fontsize=8)
fig.tight_layout()
plt.show()

# %% [markdown]
# ## Checks

# %%
test_rmse = np.sqrt(np.mean([r["model_rmse"] ** 2 for r in result.rows if r["set"] == "test"]))
assert (OUT / "model" / "report.md").is_file() and (OUT / "model" / "step.casadi").is_file()
assert gap.max() < 1e-4, gap.max()  # float64 export of a float32 network
assert test_rmse < 5.0, test_rmse  # set 2, never trained on (a linear map alone: 4.3 deg)
assert loop.rmse_deg < 2.0, loop.rmse_deg  # the plant is not the model: a twin of set 2
assert np.max(np.abs(np.diff(loop.u))) <= mpc.du_max + 1e-6 and loop.u.min() >= mpc.u_bounds[0] - 1e-9
print("all checks passed")
