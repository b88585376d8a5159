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
# # Quickstart: virtual catheter, physics, hybrid
#
# A tendon-driven catheter does not follow its kinematic model: the tip angle depends on the
# path of the tendon (hysteresis), on tendon slack (backlash) and on a static nonlinearity.
# This notebook
#
# 1. simulates a **virtual catheter** whose truth is known, with the seed paper's protocol;
# 2. **identifies** a physics model (CasADi + IPOPT) and checks the recovered parameters
#    against the truth;
# 3. fits a **hybrid** model, an incomplete physics model plus a small residual network, and
#    compares it with the physics alone and with a purely learned network trained as long;
# 4. plots the hysteresis loops.
#
# Set `HYST_FAST=1` for a run of a few seconds (fewer trajectories, a few epochs): the test
# suite runs every notebook that way.

# %%
import os

import matplotlib.pyplot as plt
import numpy as np

from hybrid import FNNHIBNet, HybridModel, LearnedModel, TrainingSettings, rmse
from physics.virtual import VirtualCatheter, paper_protocol
from identification import identify
from physics import Backlash, BoucWen, LinearMap, Poly, Series

FAST = os.environ.get("HYST_FAST", "") not in ("", "0")
EPOCHS = 5 if FAST else 60
print("fast mode" if FAST else "full mode", f"({EPOCHS} epochs)")

# %% [markdown]
# ## 1. Data from a virtual catheter
#
# The virtual catheter integrates its physics finely and adds 0.15 deg of sensor noise. Its
# input `u` is the measured tendon displacement (mm), its output `y` the tip angle (deg). We
# switch on tendon slack, Bouc-Wen hysteresis and a static cubic nonlinearity (the actuator
# lag acts before the measured displacement). `paper_protocol` runs the seed paper's decaying
# sinusoids at several frequencies and baselines; 0.15 and 0.45 Hz are held out.

# %%
catheter = VirtualCatheter(effects="lag,backlash,hysteresis,nonlinearity", seed=0)
if FAST:
    data = paper_protocol(catheter, frequencies=(0.1, 0.3, 0.5), tests=(0.15, 0.45), baselines=("mid", "end"))
else:
    data = paper_protocol(catheter)
truth = catheter.truth_model()
print(f"{len(data.train)} training and {len(data.test)} test trajectories at {1 / data.train[0].dt:.0f} Hz")
print("truth:", truth.spec, truth.param_dict())
print("noise floor (deg):", catheter.noise_floor)

# %%
fig, axes = plt.subplots(1, 2, figsize=(11, 3.5))
for traj in data.train[:3]:
    axes[0].plot(traj.time, traj.y, lw=0.8, label=traj.source)
    axes[1].plot(traj.u, traj.y, lw=0.6)
axes[0].set(xlabel="time (s)", ylabel="tip angle (deg)", title="training runs")
axes[0].legend(fontsize=7)
axes[1].set(xlabel="tendon displacement (mm)", ylabel="tip angle (deg)", title="hysteresis loops")
fig.tight_layout()
plt.show()

# %% [markdown]
# ## 2. Identify the physics
#
# With the truth's structure (`backlash+boucwen+poly+linear`), IPOPT recovers the parameters
# that made the data, and the held-out error sits at the noise floor.


# %%
def test_rmse(predict) -> float:
    """RMSE (deg) pooled over every held-out sample."""
    return rmse(np.concatenate([t.y for t in data.test]), np.concatenate([predict(t) for t in data.test]))


full = identify(Series(Backlash(), BoucWen(), Poly(center=3.0), LinearMap(), dt=truth.dt), data.train)
print(full.report())
rmse_full = test_rmse(lambda t: full.predict(t.u))
print(f"held-out RMSE of the complete physics: {rmse_full:.3f} deg")

# %% [markdown]
# In practice the physics is rarely complete. Leave out the static nonlinearity
# (`backlash+boucwen+linear`): the fit is good but misses about half a degree everywhere.

# %%
simple = identify(Series(Backlash(), BoucWen(), LinearMap(), dt=truth.dt), data.train)
rmse_physics = test_rmse(lambda t: simple.predict(t.u))
print(simple.parameters)
print(f"held-out RMSE of the incomplete physics: {rmse_physics:.3f} deg")

# %% [markdown]
# ## 3. A hybrid: physics plus a residual network
#
# `HybridModel` takes the fitted physics and trains an FNN with a history buffer (FNN-HIB) on
# what the physics leaves, `y - y_physics`, from the tendon path and the physics output. For
# comparison, the same network is trained alone to predict the whole angle, for as many epochs.
# How to train is one `TrainingSettings` object (epochs, batch size, learning rate, seed, ...),
# shared here by both models; scikit-learn sees its fields as `training__epochs` etc.

# %%
network = FNNHIBNet(buffer=10, hidden=(32, 32))
training = TrainingSettings(epochs=EPOCHS, seed=0, progress=False)
hybrid = HybridModel(simple, network, training=training).fit(data.train)
learned = LearnedModel(network, training=training).fit(data.train)
rmse_hybrid = test_rmse(hybrid.predict)
rmse_learned = test_rmse(learned.predict)
print(f"held-out RMSE (deg): physics {rmse_physics:.3f}, hybrid {rmse_hybrid:.3f}, "
      f"FNN-HIB alone {rmse_learned:.3f}, noise floor {catheter.noise_floor:.3f}")

# %% [markdown]
# ## 4. Loops
#
# On a held-out run, the incomplete physics' loop is bent the wrong way at the ends; the hybrid
# follows the measurement, and so does its error in time.

# %%
test = data.test[-1]
y_phys, y_hyb, y_learn = simple.predict(test.u), hybrid.predict(test), learned.predict(test)
fig, axes = plt.subplots(1, 2, figsize=(11, 4))
axes[0].plot(test.u, test.y, ".", ms=2, color="0.6", label="measured")
axes[0].plot(test.u, y_phys, lw=1, label="physics (no nonlinearity)")
axes[0].plot(test.u, y_hyb, lw=1, label="hybrid")
axes[0].set(xlabel="tendon displacement (mm)", ylabel="tip angle (deg)", title=test.source)
axes[0].legend(fontsize=8)
axes[1].plot(test.time, y_phys - test.y, lw=0.8, label="physics")
axes[1].plot(test.time, y_learn - test.y, lw=0.8, label="FNN-HIB alone")
axes[1].plot(test.time, y_hyb - test.y, lw=0.8, label="hybrid")
axes[1].set(xlabel="time (s)", ylabel="error (deg)", title="prediction error")
axes[1].legend(fontsize=8)
fig.tight_layout()
plt.show()

# %% [markdown]
# ## Checks
#
# The recovered parameters are those of the truth; the hybrid removes most of the incomplete
# physics' error and beats the network trained alone for as long.

# %%
p = full.parameters
assert abs(p["linear.gain"] - 11.4) < 0.02 * 11.4, p["linear.gain"]
assert abs(p["linear.offset"] - 30.0) < 0.5, p["linear.offset"]
assert abs(p["boucwen.A"] - 0.45) < 0.1 * 0.45, p["boucwen.A"]
assert abs(p["poly.c3"] - (-0.015)) < 0.1 * 0.015, p["poly.c3"]
assert abs(p["backlash.width"] - 0.2) < 0.05, p["backlash.width"]
assert rmse_full < 1.1 * catheter.noise_floor, rmse_full
assert rmse_physics > 2 * catheter.noise_floor, rmse_physics
assert rmse_hybrid < 0.6 * rmse_physics, (rmse_hybrid, rmse_physics)
assert rmse_hybrid < 0.5 * rmse_learned, (rmse_hybrid, rmse_learned)
print("all checks passed")
