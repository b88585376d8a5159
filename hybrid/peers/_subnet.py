"""deepSI's SUBNET: a neural state-space model whose state an encoder reads off past samples."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ._base import EXTRA, AbstractPeer, past

__all__ = ["SubnetPeer"]


class SubnetPeer(AbstractPeer):
    """deepSI's ``SUBNET`` (Beintema, Schoukens and Toth, 2023): ``x+ = f(x, u)``, ``y = h(x)``, residual
    MLPs, the initial state from an encoder of the last ``encoder_window`` inputs and outputs, trained
    on simulations of ``horizon`` samples (truncated simulation loss, Adam, deepSI's own batcher and
    normalised MSE), ``iterations`` batches of ``batch_size``. Training is deepSI's
    ``fit_minimal_implementation`` without its validation prints and checkpoint files, ending on the
    last iterate. Seeded: the same data and ``seed`` give the same model.

    Needs the optional extra ``peers`` (``deepsi==0.4.4``).

    ``outputs`` (a sequence of column names, as :class:`LinearARX`'s): one model of several outputs, its output
    map ``h`` ending in one unit per output (deepSI's ``ny``), each output normalised by its own spread;
    ``predict`` then returns ``(n, k)``.
    """

    name = "subnet"

    def __init__(self, nx: int = 6, encoder_window: int = 10, iterations: int = 3000, horizon: int = 50,
                 batch_size: int = 256, seed: int = 0, direction: str = "forward", outputs=None):
        self.nx = nx
        self.encoder_window = encoder_window
        self.iterations = iterations
        self.horizon = horizon
        self.batch_size = batch_size
        self.seed = seed
        self.direction = direction
        self.outputs = outputs

    @property
    def lags(self) -> int:
        return int(self.encoder_window)

    def _fit(self, runs) -> None:
        try:
            import deepSI
            import torch
            from deepSI.fitting import compute_NMSE, data_batcher
        except ImportError as exc:
            raise ImportError(f"SubnetPeer needs deepSI: {EXTRA}") from exc
        data = [deepSI.Input_output_data(u=u, y=y, sampling_time=1.0) for u, y in runs]
        nu, ny, norm = deepSI.get_nu_ny_and_auto_norm(data)
        torch.manual_seed(int(self.seed))
        k = int(self.encoder_window)
        model = deepSI.SUBNET(nu, ny, norm, nx=int(self.nx), nb=k, na=k)
        arrays, indices = model.create_arrays(data, T=int(self.horizon))
        batches = data_batcher(*arrays, batch_size=min(int(self.batch_size), len(indices)), seed=int(self.seed),
                               indices=indices)
        optimizer = torch.optim.Adam(model.parameters())
        for _, batch in zip(range(int(self.iterations)), batches):
            loss = compute_NMSE(model, *batch)
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
        self.model_ = model.eval()

    def _simulate(self, u_past, y_past, u) -> NDArray:
        import torch

        k = int(self.encoder_window)
        as_t = lambda a: torch.as_tensor(np.asarray(a, dtype=np.float32))[None]  # noqa: E731
        with torch.no_grad():
            y = self.model_(as_t(past(u_past, k)), as_t(past(y_past, k)), as_t(u))
        return y[0].double().numpy()
