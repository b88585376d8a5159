"""Torch layers written as CasADi expressions: values and Jacobians against torch in float64."""

import casadi as ca
import numpy as np
import pytest

torch = pytest.importorskip("torch")
from torch import nn  # noqa: E402

from hybrid.export import lstm_state_names, lstm_step_expr, mlp_expr  # noqa: E402


def _mlp():
    torch.manual_seed(0)
    return nn.Sequential(nn.Linear(3, 16), nn.ReLU(), nn.Linear(16, 8), nn.Tanh(),
                         nn.Identity(), nn.Linear(8, 2)).double()


@pytest.mark.parametrize("symbolic", [ca.SX, ca.MX])
def test_mlp_matches_torch_on_values_and_jacobian(symbolic):
    net = _mlp()
    x = symbolic.sym("x", 3)
    y = mlp_expr(net, x)
    f = ca.Function("f", [x], [y, ca.jacobian(y, x)])
    rng = np.random.default_rng(1)
    for _ in range(5):
        v = rng.normal(size=3)
        out, jac = (np.asarray(a) for a in f(v))
        t = torch.tensor(v, requires_grad=True)
        np.testing.assert_allclose(out.ravel(), net(t).detach().numpy(), rtol=0, atol=1e-12)
        np.testing.assert_allclose(jac, torch.autograd.functional.jacobian(net, t).numpy(), rtol=0, atol=1e-12)


def test_mlp_rejects_unknown_layers_and_wrong_sizes():
    with pytest.raises(TypeError, match="supports Linear"):
        mlp_expr(nn.Sequential(nn.Linear(1, 2), nn.GELU()), ca.SX.sym("x"))
    with pytest.raises(ValueError, match="expects 3 inputs"):
        mlp_expr(_mlp(), ca.SX.sym("x", 2))


def _torch_lstm_step(lstm, head, v, h, c):
    L, n = lstm.num_layers, lstm.hidden_size
    out, (h1, c1) = lstm(v.reshape(1, 1, -1), (h.reshape(L, 1, n), c.reshape(L, 1, n)))
    return torch.cat([head(out[0, 0]), h1.reshape(-1), c1.reshape(-1)])


@pytest.mark.parametrize("layers", [1, 2])
def test_lstm_step_matches_torch_on_values_and_jacobians(layers):
    torch.manual_seed(layers)
    lstm, head = nn.LSTM(2, 6, num_layers=layers).double(), nn.Linear(6, 1).double()
    n = 6 * layers
    v, h, c = ca.SX.sym("v", 2), ca.SX.sym("h", n), ca.SX.sym("c", n)
    y, h1, c1 = lstm_step_expr(lstm, head, v, h, c)
    out = ca.vertcat(y, h1, c1)
    args = ca.vertcat(v, h, c)
    f = ca.Function("f", [args], [out, ca.jacobian(out, args)])
    rng = np.random.default_rng(layers)
    for _ in range(3):
        a = rng.normal(size=2 + 2 * n)
        val, jac = (np.asarray(r) for r in f(a))
        t = torch.tensor(a, requires_grad=True)
        fun = lambda z: _torch_lstm_step(lstm, head, z[:2], z[2:2 + n], z[2 + n:])  # noqa: E731
        np.testing.assert_allclose(val.ravel(), fun(t).detach().numpy(), rtol=0, atol=1e-12)
        np.testing.assert_allclose(jac, torch.autograd.functional.jacobian(fun, t).numpy(), rtol=0, atol=1e-12)
    assert len(lstm_state_names(lstm)) == 2 * n
    assert lstm_state_names(lstm)[0] == "lstm.h_l0[0]"


def test_lstm_rejects_bidirectional():
    with pytest.raises(ValueError, match="bidirectional"):
        lstm_step_expr(nn.LSTM(1, 2, bidirectional=True), None, ca.SX.sym("v"), ca.SX.sym("h", 2),
                       ca.SX.sym("c", 2))
