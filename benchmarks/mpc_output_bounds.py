"""Output bounds in the fixed-iteration SQP (the C controller's): how far past the bound, tracking, time.

Run: ``.venv/bin/python benchmarks/mpc_output_bounds.py`` (about 7 minutes on 2 shared cores, mostly gcc and IPOPT). A sine reference whose top
fifth lies above the output bound (the rest outputs of 0.5 and 5.5 mm; the bound at 80 % of that
span), tracked by the MPC on the model itself (no noise) over 20 s at 25 Hz, horizons 10, 25 and 50:
the fixed-iteration SQP (1 iteration) without bounds, with ``y_bounds`` at the default
``bound_weight`` and at 1e4, and IPOPT with the bound as a constraint. Prints, per row, the largest
output past the bound (deg), the RMSE to the reference clipped at the bound (deg) and the median
solve time per control step (ms, compiled where gcc is there).
"""

from __future__ import annotations

import numpy as np

from hybrid.control import TrackingMPC, reference_signal, rest_output, run_closed_loop
from hybrid.export import export_model
from physics import Series


def row(model, ref, bound, horizon, solver, y_bounds, options=None) -> tuple[float, float, float]:
    mpc = TrackingMPC(model, u_bounds=(0.0, 6.0), horizon=horizon, solver=solver, y_bounds=y_bounds,
                      solver_options=options)
    result = run_closed_loop(mpc, model, ref, noise_std_deg=0.0)
    past = float(result.y_true.max() - bound)
    rmse = float(np.sqrt(np.mean((result.y_true - np.minimum(ref, bound)) ** 2)))
    return past, rmse, mpc.stats.summary()["median_ms"]


def main() -> None:
    print("| model | horizon | controller | past the bound (deg) | RMSE to the clipped reference (deg) | median step (ms) |")
    print("|---|---|---|---|---|---|")
    for spec in ("lag+boucwen+linear", "lag+backlash+linear"):
        model = export_model(Series.from_spec(spec, dt=0.04))
        low, high = rest_output(model, 0.5), rest_output(model, 5.5)
        ref = reference_signal("sine", low, high, duration_s=20.0)
        bound = low + 0.8 * (high - low)
        for horizon in (10, 25, 50):
            cases = (("fixed-sqp, no bounds", "fixed-sqp", None, None),
                     ("fixed-sqp, y_bounds", "fixed-sqp", (None, bound), None),
                     ("fixed-sqp, y_bounds, bound_weight 1e4", "fixed-sqp", (None, bound), {"bound_weight": 1e4}),
                     ("ipopt, y_bounds", "ipopt", (None, bound), None))
            for name, solver, y_bounds, options in cases:
                past, rmse, ms = row(model, ref, bound, horizon, solver, y_bounds, options)
                print(f"| {spec} | {horizon} | {name} | {past:.4f} | {rmse:.4f} | {ms:.3f} |", flush=True)


if __name__ == "__main__":
    main()
