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
# # Discovering a missing effect
#
# A model that misses an effect leaves a residual with that effect's signature. This notebook
# follows `identification.discover` step by step on data whose truth is known: a virtual
# catheter driven by the **motor command**, so the actuator's first-order lag lies between the
# input and the tip. The starting model has the hysteresis but not the lag. We
#
# 1. fit the start model and look at its residual against the input rate;
# 2. ask `diagnose` which effect the residual shows;
# 3. let `discover` add the block, re-fit and check it on held-out runs;
# 4. start from a bare linear map and watch it name both effects.
#
# `HYST_FAST=1` uses shorter runs.

# %%
import os
import tempfile
from pathlib import Path

import matplotlib
import matplotlib.pyplot as plt
import numpy as np

from physics.virtual import DecayingSinusoid, VirtualCatheter
from identification import (diagnose, discover, identify, noise_floor, plot_gap, plot_loops,
                            plot_residual_signature, residual_traces)

FAST = os.environ.get("HYST_FAST", "") not in ("", "0")
FIGURES = Path(tempfile.mkdtemp(prefix="hyst_discover_"))  # the report's figures are files


def show(plot, *args):
    """Draw one of the report's figures into FIGURES and show it here."""
    backend = matplotlib.get_backend()
    path = plot(*args, FIGURES / f"{plot.__name__}.png")
    matplotlib.use(backend)  # the report's plots switch pyplot to Agg: keep the notebook's backend
    fig, ax = plt.subplots(figsize=(11, 4.5))
    ax.imshow(plt.imread(path))
    ax.set_axis_off()
    plt.show()


# %% [markdown]
# ## The data
#
# Three decaying sinusoids at a low, a middle and a high frequency (several rates let the
# diagnosis tell rate-dependent effects from rate-independent ones), 0.15 deg of sensor noise.
# `discover` holds out every third run when it has three or more.

# %%
catheter = VirtualCatheter(effects="lag,hysteresis", input="command", seed=1)
cycles = 3 if FAST else 6
runs = [catheter.run(DecayingSinusoid(f, baseline, cycles=cycles))
        for f, baseline in ((0.1, "mid"), (0.3, "end"), (0.6, "zero"))]
truth = catheter.truth_model()
print("truth:", truth.spec, truth.param_dict())
print("noise floor estimated from the data:", round(noise_floor([r.y for r in runs]), 3), "deg (true 0.15)")

# %% [markdown]
# ## Step 1: the start model and its residual
#
# `boucwen+linear` fits the loops' shape but not their rate dependence. Coloured by the direction
# of motion, the residual grows with the input rate: the output trails the command by an amount
# proportional to its speed, the signature of a lag (or a delay).

# %%
START = "boucwen+linear"
start_fit = identify(START, runs)
start_model = start_fit.model()
print(f"start model '{START}': train RMSE {start_fit.train_rmse:.3f} deg")
show(plot_residual_signature, start_model, runs)

# %%
fig, ax = plt.subplots(figsize=(9, 3))
for r in runs:
    ax.plot(r.time, r.y - start_model.simulate(r.u), lw=0.7, label=f"{r.meta['frequency_hz']} Hz")
ax.set(xlabel="time (s)", ylabel="residual (deg)", title="the faster the run, the larger the residual")
ax.legend(fontsize=8)
plt.show()

# %% [markdown]
# ## Step 2: name the effect
#
# `diagnose` fits a library of terms labelled by effect to the residual (pysindy's STLSQ),
# after projecting out what re-fitting the existing blocks could explain. Each candidate comes
# with a first estimate of its block's parameters.

# %%
candidates = diagnose(residual_traces(start_model, runs), exclude=("hysteresis",))
for c in candidates:
    print(f"{c.effect:<20} score {c.score:.3f}  explains {c.explained_rms:.3f} deg  "
          f"block '{c.block}' first estimate {c.parameters}")

# %% [markdown]
# ## Step 3: discover
#
# `discover` repeats the fit-diagnose-insert loop: it inserts the best candidate's block in
# signal order, re-fits, and keeps it only if the held-out error drops by a clear margin. It
# stops at the noise floor.

# %%
report = discover(runs, start=START)
print(report.summary())
for step in report.steps:
    print(f"step: +{step.block} ({step.effect}) first estimate {step.first_estimate} -> fitted {step.parameters}")
print(f"gap to the noise floor closed: {100 * report.gap_closed:.0f} %")

# %%
show(plot_loops, report.start_model, report.model, runs)

# %%
show(plot_gap, report)

# %% [markdown]
# ## Step 4: from a bare linear map
#
# Starting from `linear`, the same loop names both effects, one per step (the lag first: it
# explains more of the residual), and the final model is the same.

# %%
from_linear = discover(runs, start="linear")
print(from_linear.summary())
show(plot_gap, from_linear)

# %% [markdown]
# ## Checks
#
# The hidden effect is named, the final model has the truth's structure and its lag's time
# constant, and it predicts the held-out run at the noise floor.

# %%
tau = report.final_parameters["lag.time_constant_s"]
assert candidates and candidates[0].effect == "actuator_lag", [c.effect for c in candidates]
assert report.named_effects == ["actuator_lag"], report.named_effects
assert report.final_model == "lag+boucwen+linear", report.final_model
assert abs(tau - catheter.truth.lag_time_constant_s) < 0.05 * catheter.truth.lag_time_constant_s, tau
assert report.rmse_final < 1.15 * catheter.noise_std_deg, report.rmse_final
assert report.rmse_start > 5 * report.rmse_final and report.gap_closed > 0.95, report.to_dict()
assert sorted(from_linear.named_effects) == ["actuator_lag", "hysteresis"], from_linear.named_effects
assert from_linear.rmse_final < 1.15 * catheter.noise_std_deg, from_linear.rmse_final
print("all checks passed")
