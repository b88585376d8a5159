"""identify() on measured data: the catheter, the NiTi robot, and the Bouc-Wen benchmark.

    .venv/bin/python benchmarks/real_data_identification.py [--only catheter|niti|boucwen] [--select]

Data are read from ../shared/data (or $HYST_DATA_DIR); a section whose data are
absent is skipped with a message. RMSEs are open-loop simulation errors (every
model simulated from its steady state at the first input, no output feedback).

* catheter_2023: fit on set 1 (baseline 3 mm), test on set 2 (baseline 0 mm), 25 Hz,
  tendon displacement (mm) -> tip angle (deg).
* niti_frequency_trials: tension (N) -> tip angle and displacement (mm) -> tip
  angle, 25 Hz, train f001_2, f002_2, f010, f020, f030, test f015, f015_2, random.
* Bouc-Wen benchmark: m y'' + c y' + k y + z = u with a Bouc-Wen force is the
  library's ``hysteretic_oscillator+linear`` (force in, displacement out), identified
  by identify() with its default starts on the 40960 training samples; the fitted
  values are mapped back to m, c, k, alpha, beta*gamma, beta*delta beside the
  published ones. Test: simulation RMSE on the multisine (steady state: the last of
  two periods) and on the sine sweep (from rest). ``--select``: the default path instead,
  the spec ``select_physics`` chooses (default vocabulary, warm-up 10; about 22 minutes), fitted
  from its fold fits and scored the same way, against the target of issue 33 (below 7.53e-6 m).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from physics.data import DataNotFoundError, data_root, load_preset  # noqa: E402
from identification import identify  # noqa: E402
from physics import Series  # noqa: E402

CATHETER_MODELS = ("linear", "boucwen+linear", "backlash+boucwen+linear", "preisach+linear",
                   "lag+boucwen+linear", "lag+backlash+boucwen+linear")
NITI_MODELS = ("linear", "boucwen+linear")
HEADER = f"{'data':<28} {'model':<28} {'train':>7} {'test':>7} {'iter':>5} {'time s':>7}  status"


def _row(data: str, spec: str, fit, test: float) -> str:
    return (f"{data:<28} {spec:<28} {fit.train_rmse:>7.3f} {test:>7.3f} {fit.iterations:>5} "
            f"{fit.wall_time_s:>7.2f}  {fit.status[:40]}")


def _fit_table(name: str, split, specs) -> None:
    for spec in specs:
        fit = identify(Series.from_spec(spec, dt=0.04), split.train, allow_failure=True)
        test, _ = fit.rmse(split.test)
        print(_row(name, spec, fit, test))


def catheter() -> None:
    split = load_preset("catheter_2023", rate_hz=25.0)
    print("catheter_2023, set 1 -> set 2, RMSE in deg (FINDINGS: static linear 3.9-4.9 test)")
    print(HEADER)
    _fit_table("catheter disp.->angle", split, CATHETER_MODELS)


def niti() -> None:
    print("\nniti_frequency_trials, RMSE in deg")
    print(HEADER)
    for inp, label in (("Tension", "NiTi tension->angle"), ("Stroke", "NiTi disp.->angle")):
        _fit_table(label, load_preset("niti_frequency_trials", rate_hz=25.0, input=inp),
                   NITI_MODELS)


#: The benchmark's true values (m, c, k, alpha, beta*gamma, beta*delta; Noel and Schoukens, 2016).
PUBLISHED = {"mass_kg": 2.0, "damping_Ns_per_m": 10.0, "stiffness_N_per_m": 5e4,
             "alpha_N_per_m": 5e4, "beta_gamma": 800.0, "beta_delta": -1100.0}


def _physical(p: dict[str, float]) -> dict[str, float]:
    """The benchmark's parameters from ``hysteretic_oscillator+linear``'s (x = k y in newtons)."""
    k = 1.0 / p["linear.gain"]
    w = 2 * np.pi * p["hysteretic_oscillator.natural_frequency_hz"]
    m = k / w**2
    return {"mass_kg": m, "damping_Ns_per_m": 2 * p["hysteretic_oscillator.damping_ratio"] * np.sqrt(k * m),
            "stiffness_N_per_m": k, "alpha_N_per_m": p["hysteretic_oscillator.A"] * k,
            "beta_gamma": p["hysteretic_oscillator.beta"] * k, "beta_delta": p["hysteretic_oscillator.gamma"] * k}


def _from_physical(q: dict[str, float]) -> dict[str, float]:
    k, m = q["stiffness_N_per_m"], q["mass_kg"]
    return {"hysteretic_oscillator.natural_frequency_hz": np.sqrt(k / m) / (2 * np.pi),
            "hysteretic_oscillator.damping_ratio": q["damping_Ns_per_m"] / (2 * np.sqrt(k * m)),
            "hysteretic_oscillator.A": q["alpha_N_per_m"] / k, "hysteretic_oscillator.beta": q["beta_gamma"] / k,
            "hysteretic_oscillator.gamma": q["beta_delta"] / k, "linear.gain": 1 / k, "linear.offset": 0.0}


def boucwen(select: bool = False) -> None:
    from scipy.io import loadmat

    path = data_root() / "boucwen_benchmark" / "bouc-wen.mat"
    if not path.exists():
        raise DataNotFoundError(f"{path} is missing")
    d = loadmat(path)
    u, y = d["u"].ravel(), d["y"].ravel()
    dt = 1 / 750
    named = "hysteretic_oscillator+linear"  # the benchmark's own equations
    spec, guesses = named, []
    if select:
        from identification import select_physics

        sel = select_physics(list(load_preset("boucwen_benchmark", rate_hz=None).train), warmup=10, verbose=True)
        print(sel.table())
        spec, guesses = sel.spec, sel.fold_parameters.get(sel.spec, [])
    fit = identify(Series.from_spec(spec, dt=dt), [SimpleNamespace(u=u, y=y)], allow_failure=True, guesses=guesses)
    model = fit.model()
    uv, yv = d["uval_multisine"].ravel(), d["yval_multisine"].ravel()
    us, ys = d["uval_sinesweep"].ravel(), d["yval_sinesweep"].ravel()

    def errors(m):
        ms = np.sqrt(np.mean((m.simulate(np.tile(uv, 2))[-uv.size:] - yv) ** 2))
        return ms, np.sqrt(np.mean((m.simulate(us) - ys) ** 2))

    ms, sweep = errors(model)
    ms_true, _ = errors(Series.from_spec(named, dt=dt).set_params(**_from_physical(PUBLISHED)))
    print(f"\nBouc-Wen benchmark (Noel & Schoukens), {spec}, simulation RMSE in m")
    if spec == named:
        for name, value in _physical(fit.parameters).items():
            print(f"  {name:<20} {value:12.5g}   (published {PUBLISHED[name]:.5g})")
    print(f"train RMSE {fit.train_rmse:.3e}; {fit.wall_time_s:.1f} s, {fit.iterations} iterations, {fit.status}")
    print(f"test multisine RMSE {ms:.3e}   (published best 7.53e-06; the true parameters "
          f"with this integrator give {ms_true:.3e})")
    print(f"test sine-sweep RMSE {sweep:.3e}")
    if select:
        print(f"target (issue 33, default path below the best published 7.53e-06): {'met' if ms < 7.53e-6 else 'missed'}")


SECTIONS = {"catheter": catheter, "niti": niti, "boucwen": boucwen}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", choices=sorted(SECTIONS), help="run one section")
    parser.add_argument("--select", action="store_true", help="Bouc-Wen benchmark: the spec select_physics "
                        "chooses (the default path), not the named oscillator")
    args = parser.parse_args(argv)
    for name, section in SECTIONS.items():
        if args.only and name != args.only:
            continue
        try:
            section(args.select) if name == "boucwen" else section()
        except DataNotFoundError as exc:
            print(f"[skipped {name}: data not found: {exc}]")


if __name__ == "__main__":
    main()
