"""Training and prediction speed of FNN, FNN-HIB and LSTM on the seed paper's protocol.

Run: ``.venv/bin/python benchmarks/training.py [--epochs 2] [--threads 1]``. Prints seconds per
epoch on every window of the 15 virtual training trajectories (batch 16, the paper's setting),
the estimated time of the paper's 500 epochs, and the prediction time per sample run step by
step (a controller's view) and batched over the 0.15 Hz test trajectory.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch

from hybrid import FNNHIBNet, FNNNet, LearnedModel, LSTMNet, TrainingSettings
from physics.virtual import paper_protocol


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--epochs", type=int, default=2, help="epochs timed per model (default 2)")
    parser.add_argument("--threads", type=int, default=1, help="torch threads (default 1)")
    parser.add_argument("--steps", type=int, default=300, help="samples predicted step by step")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    split = paper_protocol()
    test = split.test[0]
    print(f"{len(split.train)} training trajectories, {sum(t.n for t in split.train)} windows; "
          f"torch {torch.__version__}, {args.threads} thread(s)\n")
    header = (f"{'model':<16}{'s/epoch':>9}{'500 ep (min)':>14}{'step us/sample':>16}"
              f"{'batched us/sample':>19}")
    print(header)
    print("-" * len(header))
    nets = [("fnn", FNNNet(), None), ("fnn-hib", FNNHIBNet(), None),
            ("lstm (window)", LSTMNet(), "window"), ("lstm (carried)", LSTMNet(), "carried")]
    fitted: dict[str, LearnedModel] = {}
    for label, net, mode in nets:
        key = net.name
        if key not in fitted:
            training = TrainingSettings(epochs=args.epochs, progress=False, threads=args.threads)
            fitted[key] = LearnedModel(net, training=training).fit(split.train)
        model = fitted[key]
        per_epoch = model.history_.seconds / model.history_.epochs_run
        t0 = time.perf_counter()
        model.predict(test, mode=mode)
        batched = (time.perf_counter() - t0) / test.n
        state = model.initial_state(test.u[0], mode=mode)
        t0 = time.perf_counter()
        for u in test.u[:args.steps]:
            state, _ = model.step(state, u)
        stepped = (time.perf_counter() - t0) / args.steps
        print(f"{label:<16}{per_epoch:>9.2f}{per_epoch * 500 / 60:>14.1f}{stepped * 1e6:>16.0f}{batched * 1e6:>19.1f}")
    total = sum(m.history_.seconds / m.history_.epochs_run for m in fitted.values()) * 500 * 2 / 60
    print(f"\n--preset paper estimate (3 models x 2 directions x 500 epochs): {total:.0f} min")


if __name__ == "__main__":
    np.set_printoptions(precision=3)
    main()
