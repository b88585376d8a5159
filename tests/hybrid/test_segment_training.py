"""The segment-training loop shared by the neural ODE and joint fine-tuning."""

import numpy as np
import pytest
import torch

from hybrid.learning._segments import train_on_segments


class _Run:
    def __init__(self, n):
        self.n = n


def _fit(nan_when):
    """Fit ``w`` to 2 on four segments; the loss is NaN for the batches ``nan_when(batch)`` picks."""
    w = torch.nn.Parameter(torch.zeros(1, dtype=torch.float64))

    def loss(_, batch):
        value = ((w - 2.0) ** 2).sum()
        return value * float("nan") if nan_when(batch) else value

    losses = train_on_segments([{"params": [w], "lr": 0.1}], [_Run(40)], 10, epochs=30, batch_size=1, seed=0,
                               prepare=lambda: None, loss=loss)
    return float(w.detach()), losses


def test_a_batch_whose_loss_is_not_finite_is_skipped_not_stepped_on():
    w, losses = _fit(lambda batch: batch[0][1] == 10)  # the segment starting at sample 10 blows up
    assert np.isfinite(w) and abs(w - 2.0) < 0.05 and np.all(np.isfinite(losses))
    with pytest.raises(FloatingPointError, match="every batch's loss was non-finite in epoch 1"):
        _fit(lambda batch: True)
