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


def test_torch_expression_is_the_step_graph_batched():
    from physics import torch_expression
    model = model_from_spec("lag+backlash+boucwen+poly+linear+drift")
    step = model.step_function()
    tstep = torch_expression(step)
    rng = np.random.default_rng(0)
    x = rng.uniform(0, 3, (7, model.n_x))
    u = rng.uniform(0, 6, (7, 1))
    p = np.tile(model.params, (7, 1))
    x_next, y = tstep(torch.tensor(x), torch.tensor(u), torch.tensor(p))
    for i in range(7):
        xn_ref, y_ref = step(x[i], u[i], p[i])
        np.testing.assert_allclose(x_next[i].numpy(), np.asarray(xn_ref).ravel(), atol=1e-12)
        np.testing.assert_allclose(y[i].numpy(), np.asarray(y_ref).ravel(), atol=1e-12)
    # autograd through the derived graph equals CasADi's Jacobian
    pt = torch.tensor(model.params, requires_grad=True)
    _, yk = tstep(torch.tensor(x[0]), torch.tensor(u[0]), pt)
    yk.sum().backward()
    import casadi as ca
    xs, us, ps = ca.SX.sym("x", model.n_x), ca.SX.sym("u"), ca.SX.sym("p", model.n_p)
    jac = ca.Function("j", [xs, us, ps], [ca.jacobian(model.step_expr(xs, us, ps)[1], ps)])
    np.testing.assert_allclose(pt.grad.numpy(), np.asarray(jac(x[0], u[0], model.params)).ravel(),
                               atol=1e-10)


def test_torch_expression_of_a_poly_held_to_its_fitted_range():
    """The tangent continuation (CasADi fmin/fmax) translates to torch: same values inside and
    beyond the range, and autograd equals CasADi's Jacobian in the parameters."""
    import casadi as ca

    from physics import LinearMap, Poly, Series, torch_expression

    model = Series(Poly(c2=0.3, c3=-0.2, center=1.0, lo=0.0, hi=2.0), LinearMap(gain=2.0, offset=1.0))
    step = model.step_function()
    tstep = torch_expression(step)
    for v in (-2.0, 0.5, 1.5, 4.0):
        _, y = tstep(torch.zeros(model.n_x, dtype=torch.float64), torch.tensor([v]), torch.tensor(model.params))
        np.testing.assert_allclose(y.numpy(), np.asarray(step(np.zeros(model.n_x), v, model.params)[1]).ravel(),
                                   atol=1e-12)
        pt = torch.tensor(model.params, requires_grad=True)
        tstep(torch.zeros(model.n_x, dtype=torch.float64), torch.tensor([v]), pt)[1].sum().backward()
        us, ps = ca.SX.sym("u"), ca.SX.sym("p", model.n_p)
        jac = ca.Function("j", [us, ps], [ca.jacobian(model.step_expr(ca.SX.zeros(model.n_x), us, ps)[1], ps)])
        np.testing.assert_allclose(pt.grad.numpy(), np.asarray(jac(v, model.params)).ravel(), atol=1e-10)
