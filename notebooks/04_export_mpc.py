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
# # Exporting to CasADi and closing the loop with MPC
#
# A fitted model, physics or hybrid, becomes one pure CasADi function
# `step(x, u) -> (x_next, y)` in physical units: the physical parameters, the network's weights
# and the scalers are folded in as constants. The same graph gives values and exact Jacobians,
# is saved to a file that needs CasADi only, compiles to C, and is what a model-predictive
# controller optimises over. This notebook
#
# 1. fits a physics model and a hybrid on the virtual catheter;
# 2. exports both and checks the export against torch (values and a derivative);
# 3. saves, reloads and compiles the exported hybrid;
# 4. tracks a tip-angle reference on the virtual catheter with MPC on each model.
#
# `HYST_FAST=1` trains for a few epochs and runs a shorter closed loop.

# %%
import os
import tempfile
from pathlib import Path

import casadi as ca
import matplotlib.pyplot as plt
import numpy as np

from hybrid import FNNHIBNet, HybridModel, TrainingSettings
from hybrid.export import ExportedModel, export_model, has_compiler, load_compiled
from hybrid.control import TrackingMPC, reference_signal, rest_output, run_closed_loop
from physics.virtual import VirtualCatheter, paper_protocol
from identification import identify

FAST = os.environ.get("HYST_FAST", "") not in ("", "0")
OUT = Path(tempfile.mkdtemp(prefix="hyst_export_"))  # exported files land here

# %% [markdown]
# ## 1. Models
#
# The catheter of the quickstart (slack, hysteresis, a static nonlinearity). The physics is
# `boucwen+linear`: smooth, which suits a gradient-based controller (a sharp backlash has a dead
# band where `dy/du = 0`). The hybrid adds an FNN-HIB residual (10 samples of history).

# %%
catheter = VirtualCatheter(effects="lag,backlash,hysteresis,nonlinearity", seed=0)
freqs = (0.1, 0.3, 0.5) if FAST else (0.1, 0.2, 0.3, 0.4, 0.5)
data = paper_protocol(catheter, frequencies=freqs, tests=(0.45,), baselines=("mid", "end"))
physics = identify("boucwen+linear", data.train)
hybrid = HybridModel(physics, FNNHIBNet(buffer=10, hidden=(32, 32)),
                     training=TrainingSettings(epochs=5 if FAST else 60, seed=0, progress=False)).fit(data.train)
print(physics.parameters)
print(hybrid)

# %% [markdown]
# ## 2. Export
#
# `export_model` takes a `physics.Series`, a `LearnedModel` or a `HybridModel`. The hybrid's
# state is the physics state followed by the residual's input buffer (oldest first).

# %%
phys_ex = export_model(physics.model())
hyb_ex = export_model(hybrid)
for m in (phys_ex, hyb_ex):
    print(m, m.step.name_in(), "->", m.step.name_out())
print("hybrid state:", hyb_ex.state_names[:5], "...", hyb_ex.state_names[-2:])

# %% [markdown]
# The exported functions reproduce the models they came from: the physics to rounding, the
# hybrid to the float32 precision of the torch network.

# %%
test = data.test[0]
err_phys = np.max(np.abs(phys_ex.simulate(test.u) - physics.predict(test.u)))
err_hyb = np.max(np.abs(hyb_ex.simulate(test.u) - hybrid.predict(test)))
print(f"largest difference on {test.source} ({test.n} samples): physics {err_phys:.2e} deg, "
      f"hybrid {err_hyb:.2e} deg")

# %% [markdown]
# The MPC needs `dy/du`. CasADi differentiates the exported graph exactly; compare with a
# central difference of the torch hybrid's prediction when the last input moves.

# %%
k, h = test.n // 2, 1e-2
x_sym, u_sym = ca.SX.sym("x", hyb_ex.n_x), ca.SX.sym("u")
_, y_sym = hyb_ex.step(x_sym, u_sym)
dydu = ca.Function("dydu", [x_sym, u_sym], [ca.jacobian(y_sym, u_sym)])
x_k = np.asarray(hyb_ex.rollout(k)(hyb_ex.x0(test.u[0]), test.u[None, :k])[0])[:, -1]
jac_casadi = float(dydu(x_k, test.u[k]))
u_plus, u_minus = test.u[:k + 1].copy(), test.u[:k + 1].copy()
u_plus[k] += h
u_minus[k] -= h
jac_torch = float(hybrid.predict(u_plus)[k] - hybrid.predict(u_minus)[k]) / (2 * h)
print(f"dy/du at sample {k}: CasADi {jac_casadi:.4f}, torch central difference {jac_torch:.4f} deg/mm")

# %% [markdown]
# ## 3. Files and C code
#
# `save` writes the step (`casadi.Function.save`) and a JSON sidecar with the state names and
# the rule for the initial state; `ExportedModel.load` needs CasADi only, never torch. With a C
# compiler, `codegen` writes and compiles C code that `casadi.external` (or any C program) loads.

# %%
path = hyb_ex.save(OUT / "hybrid.casadi")
loaded = ExportedModel.load(path)
err_loaded = np.max(np.abs(loaded.simulate(test.u) - hyb_ex.simulate(test.u)))
print(f"saved {path.name} ({path.stat().st_size / 1e3:.0f} kB) and {path.name}.json; "
      f"reloaded difference {err_loaded:.1e}")
err_c = None
if has_compiler():
    compiled = load_compiled(hyb_ex.codegen(OUT / "c"))
    x0 = hyb_ex.x0(3.0)
    err_c = abs(float(compiled(x0, 3.2)[1]) - float(hyb_ex.step(x0, 3.2)[1]))
    print(f"compiled C step: difference {err_c:.1e} deg")
else:
    print("no C compiler on the PATH: skipping the C code")

# %% [markdown]
# ## 4. MPC on the virtual catheter
#
# `TrackingMPC` minimises the squared tracking error plus a penalty on input changes over a
# horizon, within the tendon's travel and rate limits, with CasADi's SQP method. The plant is the
# virtual catheter's true physics with 0.15 deg of sensor noise. The model's state is advanced on
# the inputs applied, and the filtered difference between measured and predicted angle is
# removed from the reference (offset-free MPC): that corrects a constant model error, not one
# that changes along the loop.

# %%
plant = catheter.truth_model()
horizon, duration = (15, 6.0) if FAST else (25, 20.0)
reference = reference_signal("sine", rest_output(phys_ex, 0.5), rest_output(phys_ex, 5.5), duration_s=duration)
results, stats = {}, {}
for name, model in (("physics", phys_ex), ("hybrid", hyb_ex)):
    mpc = TrackingMPC(model, u_bounds=(0.0, 6.0), horizon=horizon, solver="sqp")
    results[name] = run_closed_loop(mpc, plant, reference, noise_std_deg=0.15, seed=0)
    stats[name] = mpc.stats.summary()
    print(f"{name:<8} ({mpc.shooting} shooting, n_x {model.n_x}): tracking RMSE {results[name].rmse_deg:.3f} deg, "
          f"median solve {stats[name]['median_ms']:.1f} ms, converged {100 * stats[name]['success_rate']:.0f} %")

# %%
fig, axes = plt.subplots(3, 1, figsize=(10, 7), sharex=True)
t = results["physics"].time
axes[0].plot(t, reference, "k--", lw=1, label="reference")
for name, res in results.items():
    axes[0].plot(t, res.y_true, lw=1, label=f"tip angle, MPC on {name}")
    axes[1].plot(t, res.y_true - res.reference, lw=1, label=name)
    axes[2].plot(t, res.u, lw=1, label=name)
axes[0].set(ylabel="tip angle (deg)")
axes[1].set(ylabel="tracking error (deg)")
axes[2].set(ylabel="tendon (mm)", xlabel="time (s)")
for ax in axes:
    ax.legend(fontsize=8)
fig.tight_layout()
plt.show()

# %% [markdown]
# ## Checks
#
# The export equals the torch model in value and derivative, survives a file round trip (and C
# code), and the MPC tracks better on the hybrid than on the physics alone.

# %%
assert err_phys < 1e-9, err_phys
assert err_hyb < 1e-4, err_hyb
assert abs(jac_casadi - jac_torch) < 0.02 * abs(jac_torch) + 0.05, (jac_casadi, jac_torch)
assert err_loaded == 0.0, err_loaded
assert err_c is None or err_c < 1e-9, err_c
assert all(s["success_rate"] > 0.9 for s in stats.values()), stats
assert results["hybrid"].rmse_deg < 0.3, results["hybrid"].rmse_deg
assert results["hybrid"].rmse_deg < 0.7 * results["physics"].rmse_deg, {n: r.rmse_deg for n, r in results.items()}
print("all checks passed")
