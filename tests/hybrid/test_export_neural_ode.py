"""The neural-ODE hybrid exports as a CasADi step equal to its torch model (values, Jacobians)."""

import casadi as ca
import numpy as np
import pytest

from hybrid.export import ExportedModel, export_model

torch = pytest.importorskip("torch")
from hybrid import NeuralODEHybrid  # noqa: E402
from physics.virtual import paper_protocol  # noqa: E402


@pytest.fixture(scope="module")
def fitted():
    split = paper_protocol(frequencies=(0.5,), tests=(0.45,), baselines=("mid",))
    model = NeuralODEHybrid("backlash+boucwen+linear", hidden=8, epochs=3, progress=False).fit(split.train)
    assert model.module_.net[-1].weight.abs().max() > 1e-4  # the correction is not zero any more
    return model, split.test[0], split.train


@pytest.mark.parametrize("symbolic", ["SX", "MX"])
def test_rollout_equals_torch(fitted, symbolic, tmp_path):
    model, test, _ = fitted
    exported = export_model(model, symbolic=symbolic)
    assert exported.kind == "neural-ode" and exported.state_names[-1] == "u_prev"
    np.testing.assert_allclose(exported.x0(test.u[0]), np.r_[model.initial_state(test.u[0])[0], test.u[0]])
    expected = model.predict(test.u)
    np.testing.assert_allclose(exported.simulate(test.u), expected, rtol=0, atol=1e-9)
    back = ExportedModel.load(exported.save(tmp_path / "node.casadi"))
    np.testing.assert_allclose(back.simulate(test.u[:50]), expected[:50], rtol=0, atol=1e-9)
    train_u = np.concatenate([t.u for t in fitted[2]])
    assert back.input_range == pytest.approx((train_u.min(), train_u.max()), rel=1e-12)


def test_step_jacobians_match_torch_autograd(fitted):
    model, test, _ = fitted
    exported = export_model(model)
    n = exported.n_x - 1
    x, u = ca.SX.sym("x", n + 1), ca.SX.sym("u")
    jac = ca.Function("j", [x, u], [ca.jacobian(ca.vertcat(*exported.step(x, u)), ca.vertcat(x, u))])

    def torch_step(z):  # state [xc; u_prev], input u -> [xc_next; u; y]
        xc, u_prev, uk = z[:n][None], z[n:n + 1], z[n + 1:n + 2]
        y, xs = model.module_.run(xc, u_prev, uk[None])
        return torch.cat([xs[0, -1], uk, y[0]])

    x0 = exported.x0(test.u[10])
    for k in (20, 40, 60):  # points on the test path, the input moving
        xv, _ = exported.rollout(k - 10)(x0, test.u[10:k][None])
        xv = np.asarray(xv)[:, -1]
        expected = torch.autograd.functional.jacobian(torch_step, torch.tensor(np.r_[xv, test.u[k]])).numpy()
        np.testing.assert_allclose(np.asarray(jac(xv, test.u[k])), expected, rtol=1e-9, atol=1e-10)


def test_approximation_is_the_physics_ode(fitted):
    model, test, _ = fitted
    exported = export_model(model)
    with torch.no_grad():
        saved = [p.clone() for p in model.module_.net[-1].parameters()]
        for p in model.module_.net[-1].parameters():
            p.zero_()
        physics_only = export_model(model)
        for p, s in zip(model.module_.net[-1].parameters(), saved):
            p.copy_(s)
    x = exported.x0(test.u[0])
    for u in test.u[1:30]:
        a, b = exported.approximation(x, u), physics_only.step(x, u)
        np.testing.assert_allclose(np.asarray(a[1]), np.asarray(b[1]), rtol=0, atol=1e-12)
        x = np.asarray(exported.step(x, u)[0]).ravel()
