"""The standard list of physics specs fitted to every real data set: failures, nested checks, times.

    .venv/bin/python benchmarks/identify_real.py [--only catheter_1|catheter_2|niti|boucwen]

One row per (data set, spec): the status, starts run (multi-start by default for specs with a
lag, backlash or Bouc-Wen block), train and test RMSE (open-loop simulation from the steady
state at the first input), the wall time, and two checks the identification promises: the fit
succeeded, and its train RMSE is no worse than that of every simpler spec of the list nested in
it (``worse than ...`` is printed otherwise). Nested means a special case: the simpler spec's
blocks in the same order, each block it lacks able to pass its input through
(:func:`identification._nested.is_nested`; a one-sample ``delay`` cannot, so ``delay+lag+linear``
does not contain ``lag+linear``). Each fit is given the fits of its nested specs
(``identify(..., nested=...)``): it never ends above them (``Nested_Start_Kept`` when IPOPT
could not do better than the best of them). Data are read from ../shared/data (or
$HYST_DATA_DIR); a data set that is absent is skipped with a message.

* catheter_1 / catheter_2: catheter_2023 set 1 -> set 2 and set 2 -> set 1, 25 Hz, mm -> deg.
* niti: niti_frequency_trials, tension (N) -> tip angle (deg), 25 Hz, its train/test split.
* boucwen: the Bouc-Wen benchmark (Noel & Schoukens), force (N) -> displacement (m) at 750 Hz;
  test: the multisine's second period of a two-period run.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from identification import identify  # noqa: E402
from identification._nested import is_nested  # noqa: E402
from physics import Series  # noqa: E402
from physics.data import DataNotFoundError, Trajectory, data_root, load_preset  # noqa: E402

SPECS = ("linear", "lag+linear", "delay+linear", "backlash+linear", "boucwen+linear", "preisach+linear",
         "poly+linear", "drift+linear", "backlash+boucwen+linear", "lag+backlash+boucwen+linear",
         "boucwen+poly+linear", "delay+lag+backlash+linear", "resonance+linear", "resonance+boucwen+linear")


def _catheter(a: int):
    split = load_preset("catheter_2023", rate_hz=25.0)
    sets = {1: list(split.train), 2: list(split.test)}
    return sets[a], sets[3 - a], 0.04, lambda m, t: m.simulate(t.u)


def _niti():
    split = load_preset("niti_frequency_trials", rate_hz=25.0, input="Tension")
    return list(split.train), list(split.test), 0.04, lambda m, t: m.simulate(t.u)


def _boucwen():
    from scipy.io import loadmat

    path = data_root() / "boucwen_benchmark" / "bouc-wen.mat"
    if not path.exists():
        raise DataNotFoundError(f"{path} is missing")
    d = loadmat(path)
    dt = 1 / 750
    u, y = d["u"].ravel(), d["y"].ravel()
    uv, yv = d["uval_multisine"].ravel(), d["yval_multisine"].ravel()
    train = [Trajectory(np.arange(u.size) * dt, u, y, source="boucwen train")]
    test = [Trajectory(np.arange(uv.size) * dt, uv, yv, source="boucwen multisine")]
    return train, test, dt, lambda m, t: m.simulate(np.tile(t.u, 2))[-t.n:]


DATA = {"catheter_1": lambda: _catheter(1), "catheter_2": lambda: _catheter(2), "niti": _niti,
        "boucwen": _boucwen}


def _rmse(model, trajs, predict) -> float:
    return float(np.sqrt(np.mean(np.concatenate([(t.y - predict(model, t)) ** 2 for t in trajs]))))


def run(name: str) -> None:
    try:
        train, test, dt, predict = DATA[name]()
    except DataNotFoundError as exc:
        print(f"\n{name}: skipped ({exc})")
        return
    print(f"\n{name}: {len(train)} train / {len(test)} test trajectories, {1 / dt:g} Hz")
    print(f"{'spec':<30} {'status':<28} {'starts':>6} {'iter':>5} {'train':>10} {'test':>10} {'time s':>7}  checks")
    done: dict = {}
    for spec in SPECS:
        t0 = time.perf_counter()
        nested = [f for s, f in done.items() if is_nested(s, spec)]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            fit = identify(Series.from_spec(spec, dt=dt), train, allow_failure=True, nested=nested)
        wall = time.perf_counter() - t0
        checks = [] if fit.success else ["FAILED"]
        worse = [s for s, f in done.items() if is_nested(s, spec) and fit.train_rmse > f.train_rmse * (1 + 1e-3)]
        if worse:
            checks.append("worse than " + ", ".join(worse))
        done[spec] = fit
        test_rmse = _rmse(fit.model(), test, predict)
        print(f"{spec:<30} {fit.status[:28]:<28} {len(fit.starts):>6} {fit.iterations:>5} {fit.train_rmse:>10.4g} "
              f"{test_rmse:>10.4g} {wall:>7.1f}  {', '.join(checks) or 'ok'}", flush=True)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", choices=sorted(DATA), help="one data set")
    args = parser.parse_args(argv)
    for name in DATA:
        if not args.only or name == args.only:
            run(name)


if __name__ == "__main__":
    main()
