"""Exported models equal the models they come from: rollouts, Jacobians, files, protocol."""

import json
import subprocess
import sys
import textwrap

import casadi as ca
import numpy as np
import pytest

from hybrid.export import (
    ExportedModel, ExportError, compose_hybrid, export_model, export_network, register_exporter,
)
from physics import Series

torch = pytest.importorskip("torch")
from physics.data import MinMaxScaler  # noqa: E402
from hybrid.networks._fnn import BufferMLP  # noqa: E402
from hybrid.networks._lstm import FlaggedLSTM  # noqa: E402

N = 1000
U = 3 - 2.8 * np.cos(2 * np.pi * 0.3 * np.arange(N) * 0.04) + 0.1 * np.sin(2 * np.pi * 1.7 * np.arange(N) * 0.04)
IN = MinMaxScaler().fit(np.array([[0.0], [6.0]]))
OUT = MinMaxScaler().fit(np.array([[30.0], [100.0]]))


def _torch_sequence(module, u, mode):
    scaled = torch.tensor(IN.transform(np.asarray(u)[:, None]))
    return OUT.inverse_transform(module.sequence(scaled, mode=mode).numpy()).ravel()


@pytest.mark.parametrize("spec", ["lag+boucwen+linear", "lag+delay+backlash+boucwen+poly+linear+drift",
                                  "lag+preisach+linear"])
def test_physics_export_equals_simulate(spec):
    model = Series.from_spec(spec)
    exported = export_model(model)
    assert exported.state_names == tuple(model.state_names) and exported.dt == model.dt
    np.testing.assert_allclose(exported.x0(U[0]), model.steady_state(U[0]), atol=1e-12)
    np.testing.assert_allclose(exported.simulate(U), model.simulate(U), rtol=0, atol=1e-9)


def _modules():
    torch.manual_seed(0)
    return {
        "fnn": (BufferMLP(1, 1, (16, 16), 1, "edge").double(), None),
        "fnn-hib-edge": (BufferMLP(1, 6, (16, 16), 1, "edge").double(), None),
        "fnn-hib-pad": (BufferMLP(1, 6, (16, 16), 1, -1.0).double(), None),
        "lstm-carried": (FlaggedLSTM(1, 8, 2, 10, -1.0, 1).double(), "carried"),
        "lstm-window": (FlaggedLSTM(1, 4, 2, 5, -1.0, 1).double(), "window"),
    }


@pytest.mark.parametrize("name", list(_modules()))
def test_network_rollout_matches_torch_over_1000_steps(name):
    module, mode = _modules()[name]
    exported = export_network(module, IN, OUT, mode=mode)
    y = exported.simulate(U)  # from x0(U[0]): the state torch starts from
    np.testing.assert_allclose(y, _torch_sequence(module, U, mode or "window"), rtol=0, atol=1e-9)


def _torch_step_physical(module, mode, x, u):
    """The exported step's maths written with torch ops, for autograd."""
    lo, span = float(IN.min_[0]), float(IN.max_[0] - IN.min_[0])
    olo, ospan = float(OUT.min_[0]), float(OUT.max_[0] - OUT.min_[0])
    v = ((u - lo) / span).reshape(1, 1)
    if mode is None:
        window = torch.cat([(x - lo) / span, v.reshape(-1)])
        return torch.cat([x[1:], u.reshape(1)]), module.net(window[None])[0] * ospan + olo
    L, n = module.lstm.num_layers, module.lstm.hidden_size
    h, c = x[:L * n].reshape(L, 1, n), x[L * n:].reshape(L, 1, n)
    out, (h1, c1) = module.lstm(v.reshape(1, 1, 1), (h, c))
    return torch.cat([h1.reshape(-1), c1.reshape(-1)]), module.head(out[0, 0]) * ospan + olo


@pytest.mark.parametrize("name", ["fnn-hib-edge", "lstm-carried"])
def test_step_jacobians_match_torch_autograd(name):
    module, mode = _modules()[name]
    exported = export_network(module, IN, OUT, mode=mode)
    x, u = ca.SX.sym("x", exported.n_x), ca.SX.sym("u")
    xn, y = exported.step(x, u)
    jac = ca.Function("step_jacobian", [x, u], [ca.jacobian(ca.vertcat(xn, y), ca.vertcat(x, u))])
    rng = np.random.default_rng(0)
    for _ in range(3):
        xv = rng.uniform(0, 6, exported.n_x) if mode is None else rng.normal(0, 0.5, exported.n_x)
        uv = rng.uniform(0, 6)
        z = torch.tensor(np.r_[xv, uv])
        fun = lambda a: torch.cat(_torch_step_physical(module, mode, a[:-1], a[-1]))  # noqa: E731
        expected = torch.autograd.functional.jacobian(fun, z).numpy()
        np.testing.assert_allclose(np.asarray(jac(xv, uv)), expected, rtol=1e-10, atol=1e-11)


def test_mx_and_sx_exports_agree():
    module, _ = _modules()["lstm-carried"]
    sx, mx = (export_network(module, IN, OUT, mode="carried", symbolic=s) for s in ("SX", "MX"))
    assert mx.step.is_a("MXFunction") and sx.step.is_a("SXFunction")
    np.testing.assert_allclose(mx.simulate(U[:200]), sx.simulate(U[:200]), rtol=0, atol=1e-12)


def test_hybrid_is_physics_plus_residual():
    physics = export_model(Series.from_spec("lag+boucwen+linear"))
    torch.manual_seed(3)
    res_module = BufferMLP(2, 4, (8,), 1, "edge").double()
    in2 = MinMaxScaler().fit(np.array([[0.0, 30.0], [6.0, 100.0]]))
    out2 = MinMaxScaler().fit(np.array([[-2.0], [2.0]]))
    residual = export_network(res_module, in2, out2)
    hybrid = compose_hybrid(physics, residual, features=("u", "y_phys"))
    assert hybrid.state_names[0] == "physics.lag.position" and hybrid.n_x == 4 + 6
    y_phys = physics.simulate(U)
    feats = torch.tensor(in2.transform(np.column_stack([U, y_phys])))
    y_res = out2.inverse_transform(res_module.sequence(feats).numpy()).ravel()
    np.testing.assert_allclose(hybrid.simulate(U), y_phys + y_res, rtol=0, atol=1e-9)
    with pytest.raises(ExportError, match="features"):
        compose_hybrid(physics, residual, features=("u", "tip"))


def test_x0_is_the_state_torch_starts_a_run_from():
    """One initial-state rule (issue #15): x0(u0) is the module's own start of a run."""
    module, _ = _modules()["lstm-carried"]
    m = export_network(module, IN, OUT, mode="carried")
    h, c = module.initial_state(torch.zeros(1, dtype=torch.float64), mode="carried")
    np.testing.assert_allclose(m.x0(2.0), np.r_[h.numpy().ravel(), c.numpy().ravel()], rtol=0, atol=1e-12)
    hib = export_network(_modules()["fnn-hib-pad"][0], IN, OUT)
    np.testing.assert_allclose(hib.x0(2.0), np.full(5, IN.min_[0] - (IN.max_[0] - IN.min_[0])))  # pad -1, scaled
    edge = export_network(_modules()["fnn-hib-edge"][0], IN, OUT)
    np.testing.assert_allclose(edge.x0(2.0), np.full(5, 2.0))


def test_save_load_round_trip(tmp_path):
    module, _ = _modules()["lstm-carried"]
    m = export_network(module, IN, OUT, mode="carried")
    path = m.save(tmp_path / "lstm.casadi")
    info = json.loads((tmp_path / "lstm.casadi.json").read_text())
    assert info["state_names"][:2] == ["lstm.h_l0[0]", "lstm.h_l0[1]"] and info["kind"] == "lstm"
    back = ExportedModel.load(path)
    np.testing.assert_allclose(back.simulate(U[:100]), m.simulate(U[:100]), rtol=0, atol=1e-13)
    with pytest.raises(ExportError, match=r"\.casadi"):
        m.save(tmp_path / "lstm.bin")
    with pytest.raises(ExportError, match="No exported model"):
        ExportedModel.load(tmp_path / "missing.casadi")


def test_casadi_file_runs_without_torch(tmp_path):
    module, _ = _modules()["fnn-hib-edge"]
    m = export_network(module, IN, OUT)
    path = m.save(tmp_path / "hib.casadi")
    expected = m.simulate(U[:50])
    np.save(tmp_path / "expected.npy", expected)
    script = textwrap.dedent(f"""
        import sys

        class BlockTorch:  # any import of torch now fails
            def find_spec(self, name, path=None, target=None):
                if name == "torch" or name.startswith("torch."):
                    raise ImportError("torch is blocked in this test")

        sys.meta_path.insert(0, BlockTorch())
        import numpy as np, casadi as ca
        from hybrid.export import ExportedModel
        f = ca.Function.load({str(path)!r})
        m = ExportedModel.load({str(path)!r})
        u = np.load({str(tmp_path / 'expected.npy')!r})
        y = m.simulate({U[:50].tolist()!r})
        assert np.max(np.abs(y - u)) < 1e-13, np.max(np.abs(y - u))
        assert f.name_in() == ["x", "u"]
        assert "torch" not in sys.modules
        print("ok")
    """)
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, cwd=str(tmp_path))
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "ok"


def test_export_protocol_and_errors():
    class Custom:
        def to_casadi(self, **options):
            return export_model(Series.from_spec("linear"))

    class Registered:
        pass

    register_exporter(Registered)(lambda model, **o: export_model(Series.from_spec("lag")))
    assert export_model(Custom()).kind == "physics"
    assert export_model(Registered()).state_names == ("lag.position", "lag.u_prev")
    with pytest.raises(ExportError, match="No exporter for object. Must be one of"):
        export_model(object())
    with pytest.raises(ExportError, match="'SX' or 'MX'"):
        export_model(Series.from_spec("lag"), symbolic="DM")


def test_learned_model_exports_through_the_registry():
    from hybrid.learning._learned import LearnedModel
    from hybrid.networks import FNNHIBNet

    model = LearnedModel(FNNHIBNet(buffer=5, hidden=(8, 8)))
    torch.manual_seed(0)
    model.module_ = model.network_.build(1, 1).eval()
    model.input_scaler_, model.output_scaler_, model.n_features_in_ = IN, OUT, 1
    exported = export_model(model)
    assert exported.kind == "fnn-hib" and exported.n_x == 4
    assert exported.input_range == (0.0, 6.0)  # the input scaler's range: the MPC's default bounds
    # the torch model runs in float32: agreement to float32 rounding
    np.testing.assert_allclose(exported.simulate(U), model.predict(U), rtol=0, atol=1e-4)
    model.direction = "inverse"
    with pytest.raises(ExportError, match="forward"):
        export_model(model)


@pytest.mark.parametrize("symbolic", ["SX", "MX"])
def test_wide_layers_match_torch_in_blocks(symbolic):
    """Layers wider than MAC_BLOCK columns are multiply-accumulate chains on MX (with a
    partial last block here: 20 = 8 + 8 + 4); values and Jacobians stay torch's."""
    torch.manual_seed(5)
    module = FlaggedLSTM(1, 20, 2, 10, -1.0, 1).double()
    exported = export_network(module, IN, OUT, mode="carried", symbolic=symbolic)
    y = exported.simulate(U)
    np.testing.assert_allclose(y, _torch_sequence(module, U, "carried"), rtol=0, atol=1e-9)
    x, u = ca.MX.sym("x", exported.n_x), ca.MX.sym("u")
    jac = ca.Function("j", [x, u], [ca.jacobian(ca.vertcat(*exported.step(x, u)), ca.vertcat(x, u))])
    xv, uv = np.random.default_rng(1).normal(0, 0.5, exported.n_x), 2.5
    fun = lambda a: torch.cat(_torch_step_physical(module, "carried", a[:-1], a[-1]))  # noqa: E731
    expected = torch.autograd.functional.jacobian(fun, torch.tensor(np.r_[xv, uv])).numpy()
    np.testing.assert_allclose(np.asarray(jac(xv, uv)), expected, rtol=1e-10, atol=1e-11)


def test_hybrid_carries_its_physics_as_approximation(tmp_path):
    physics = export_model(Series.from_spec("lag+boucwen+linear"))
    torch.manual_seed(3)
    residual = export_network(BufferMLP(1, 4, (8,), 1, "edge").double(), IN, OUT)
    hybrid = compose_hybrid(physics, residual)
    x = hybrid.x0(2.0)
    x_next, y = hybrid.approximation(x, 2.7)
    xp_next, yp = physics.step(x[:physics.n_x], 2.7)
    np.testing.assert_allclose(np.asarray(x_next).ravel(), np.r_[np.asarray(xp_next).ravel(), x[physics.n_x:]])
    assert float(y) == pytest.approx(float(yp), abs=1e-12)
    back = ExportedModel.load(hybrid.save(tmp_path / "h.casadi"))
    np.testing.assert_allclose(np.asarray(back.approximation(x, 2.7)[1]), np.asarray(y), atol=1e-13)
    assert physics.approximation is None
    with pytest.raises(ExportError, match="approximation"):
        ExportedModel(hybrid.step, hybrid.state_names, hybrid.x0_base, approximation=physics.step)
