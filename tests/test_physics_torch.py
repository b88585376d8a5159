"""The CasADi graph called from torch: values and gradients are the graph's own."""

import numpy as np
import torch

from physics import model_from_spec, torch_function


def test_rollout_values_and_gradients_match_casadi():
    model = model_from_spec("lag+boucwen+linear")
    n = 40
    u = 3 - 3 * np.cos(np.linspace(0, 6, n))
    rollout = torch_function(model.rollout(n))
    x0 = torch.tensor(model.steady_state(u[0]), dtype=torch.float64)
    ut = torch.tensor(u[None, :], dtype=torch.float64)
    p = torch.tensor(model.params, dtype=torch.float64, requires_grad=True)
    _, y = rollout(x0, ut, p)
    np.testing.assert_allclose(y.detach().numpy().ravel(), model.simulate(u), atol=1e-12)
    # gradcheck: reverse mode against finite differences, parameters and inputs
    fixed = [0, 1, 2, 3, 5, 6]  # every parameter but n
    def loss(pf, uu):
        full = torch.cat([pf[:4], p.detach()[4:5], pf[4:]])
        return rollout(x0, uu, full)[1]
    pf = torch.tensor(model.params[fixed], dtype=torch.float64, requires_grad=True)
    uu = ut.clone().requires_grad_(True)
    assert torch.autograd.gradcheck(loss, (pf, uu), eps=1e-6, atol=1e-5, rtol=1e-4)
