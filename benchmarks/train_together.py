"""Seeds of one network trained one after another against one batched pass (issue 54 item 4).

    .venv/bin/python benchmarks/train_together.py [--epochs 5] [--device cpu]

The paper's FNN-HIB (buffer 50, hidden 64-64) and FNN on the catheter-sized windows of the virtual
catheter (two runs of 0.2 and 0.4 Hz at 25 Hz, 10 cycles), ``k`` seeds each, side by side in one run:
``train`` per seed against ``train_together`` over the seeds (``hybrid.learning``), with the largest
difference of their predictions (scaled units) and of their final training losses. One torch thread.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace

import numpy as np
import torch

from hybrid.learning import LearnedModel, TrainingSettings, train, train_together
from hybrid.networks import make_network
from physics.virtual import DecayingSinusoid, VirtualCatheter


def windows(net):
    cath = VirtualCatheter(seed=0)
    runs = [cath.run(DecayingSinusoid(f, "mid", cycles=10)) for f in (0.2, 0.4)]
    model = LearnedModel(net, training=TrainingSettings(progress=False))
    _, _, _, x, y = model._windows(runs)
    return x, y


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--epochs", type=int, default=5)
    parser.add_argument("--device", default="cpu")
    args = parser.parse_args()
    torch.set_num_threads(1)
    print(f"{'network':8s} {'seeds':>5s} {'alone s':>8s} {'together s':>10s} {'ratio':>6s} {'max |dy|':>9s} "
          f"{'max dloss':>9s}")
    for name in ("fnn-hib", "fnn"):
        net = make_network(name)
        x, y = windows(net)
        warm = TrainingSettings(epochs=1, progress=False, threads=1, device=args.device)
        train(net.build(x.shape[2], 1), x, y, warm)  # first calls pay torch's set-up: not timed
        train_together([net.build(x.shape[2], 1) for _ in range(2)], x, y, [warm, replace(warm, seed=1)])
        for k in (2, 4, 8):
            settings = [TrainingSettings(epochs=args.epochs, seed=s, progress=False, threads=1, device=args.device)
                        for s in range(k)]

            def built():
                out = []
                for s in settings:
                    torch.manual_seed(s.seed)
                    out.append(net.build(x.shape[2], 1))
                return out

            alone = built()
            t0 = time.perf_counter()
            ha = [train(m, x, y, s) for m, s in zip(alone, settings)]
            t_alone = time.perf_counter() - t0
            together = built()
            t0 = time.perf_counter()
            hb = train_together(together, x, y, settings)
            t_together = time.perf_counter() - t0
            probe = torch.from_numpy(x[:2000])
            with torch.no_grad():
                dy = max(float((a(probe) - b(probe)).abs().max()) for a, b in zip(alone, together))
            dloss = max(abs(a.train_loss[-1] - b.train_loss[-1]) for a, b in zip(ha, hb))
            print(f"{name:8s} {k:5d} {t_alone:8.2f} {t_together:10.2f} {t_alone / t_together:6.2f} {dy:9.2e} "
                  f"{dloss:9.2e}", flush=True)


if __name__ == "__main__":
    main()
