"""A new network is one spec class (settings, torch module, CasADi step) plus one registry line.

The toy is a single-layer GRU run over the window of the last ``seq_len`` inputs
from a zero state, with a linear head. Nothing outside this file names it: it
trains, exports, checkpoints and serves as a hybrid's residual through the hooks
``AbstractNetwork`` declares.
"""

from dataclasses import dataclass
from typing import ClassVar

import casadi as ca
import numpy as np
import pytest

torch = pytest.importorskip("torch")
from torch import nn  # noqa: E402

from hybrid import HybridModel, LearnedModel, TrainingSettings  # noqa: E402
from hybrid.export import export_model, export_network  # noqa: E402
from hybrid.networks import NETWORKS, AbstractNetwork, CasadiStep, make_network, register_network  # noqa: E402
from physics.data import history_windows  # noqa: E402
from physics.virtual import DecayingSinusoid, VirtualCatheter, paper_protocol  # noqa: E402


class ToyModule(nn.Module):
    def __init__(self, n_features: int, hidden: int, seq_len: int, n_outputs: int):
        super().__init__()
        self.n_features, self.n_outputs, self.seq_len = n_features, n_outputs, seq_len
        self.gru = nn.GRU(n_features, hidden, batch_first=True)
        self.head = nn.Linear(hidden, n_outputs)

    def forward(self, windows):
        out, _ = self.gru(windows.to(self.head.weight.dtype))
        return self.head(out[:, -1])

    @torch.no_grad()
    def sequence(self, features, mode="window"):
        padded = torch.cat([features[:1].expand(self.seq_len - 1, -1), features])
        return self(padded.unfold(0, self.seq_len, 1).transpose(1, 2))

    @torch.no_grad()
    def initial_state(self, x0, mode="window"):
        return x0.reshape(1, -1).repeat(self.seq_len, 1)

    @torch.no_grad()
    def step(self, state, x):
        buf = torch.cat([state[1:], x.reshape(1, -1)])
        return buf, self(buf[None])[0]


@dataclass(frozen=True)
class ToyGRU(AbstractNetwork):
    hidden: int = 8
    seq_len: int = 6
    name: ClassVar[str] = "toy-gru"

    @property
    def history(self) -> int:
        return self.seq_len

    def windows(self, features):
        return history_windows(self.check_features(features), self.seq_len, pad="edge").astype(np.float32)

    @classmethod
    def module_class(cls) -> type:
        return ToyModule

    def build(self, n_features: int, n_outputs: int = 1):
        return ToyModule(n_features, self.hidden, self.seq_len, n_outputs)

    @classmethod
    def casadi_step(cls, module, inputs, outputs, mode=None, sym=ca.SX) -> CasadiStep:
        """State: the previous ``seq_len - 1`` inputs (physical units); the GRU reruns the window."""
        n_f, n, L = module.n_features, module.gru.hidden_size, module.seq_len
        w = {k: ca.DM(v.detach().double().numpy()) for k, v in module.named_parameters()}
        x, u = sym.sym("x", (L - 1) * n_f), sym.sym("u", n_f)
        rows = [x[i * n_f:(i + 1) * n_f] for i in range(L - 1)] + [u]
        h = ca.DM.zeros(n, 1)
        for row in rows:  # torch's gate order r, z, n
            gi = ca.mtimes(w["gru.weight_ih_l0"], inputs.to_scaled(row)) + w["gru.bias_ih_l0"]
            gh = ca.mtimes(w["gru.weight_hh_l0"], h) + w["gru.bias_hh_l0"]
            r, z = 1 / (1 + ca.exp(-(gi[:n] + gh[:n]))), 1 / (1 + ca.exp(-(gi[n:2 * n] + gh[n:2 * n])))
            h = (1 - z) * ca.tanh(gi[2 * n:] + r * gh[2 * n:]) + z * h
        y = outputs.to_physical(ca.mtimes(w["head.weight"], h) + w["head.bias"])
        step = ca.Function("step", [x, u], [ca.vertcat(*rows[1:]), y], ["x", "u"], ["x_next", "y"])
        u0 = ca.SX.sym("u0", n_f)
        x0 = ca.Function("x0", [u0], [ca.repmat(u0, L - 1, 1)], ["u0"], ["x0"])
        names = tuple(f"toy.v{j}[k-{L - 1 - i}]" for i in range(L - 1) for j in range(n_f))
        return CasadiStep(step, names, x0, kind=cls.name, meta={"seq_len": L})


@pytest.fixture(scope="module")
def toy():
    register_network(ToyGRU)  # the one registry line
    yield ToyGRU
    NETWORKS.pop(ToyGRU.name)


@pytest.fixture(scope="module")
def cath():
    return VirtualCatheter(seed=0)


@pytest.fixture(scope="module")
def run(cath):
    return cath.run(DecayingSinusoid(frequency_hz=0.5, baseline="end"))


def _on_float32_grid(model, u):
    """``u`` moved onto inputs whose scaled values float32 holds exactly (multiples of 1/256):
    ``predict`` feeds torch float32 inputs, the export scales in float64, and on these
    paths both see the same numbers, so they agree to float64 rounding."""
    lo, hi = float(model.input_scaler_.min_[0]), float(model.input_scaler_.max_[0])
    span = hi - lo
    return lo + span * np.round((u - lo) / span * 256) / 256


def test_toy_network_trains_exports_and_round_trips(toy, cath, run, tmp_path):
    assert make_network("toy-gru", hidden=4) == ToyGRU(hidden=4)
    model = LearnedModel(toy(hidden=8, seq_len=6), training=TrainingSettings(
        epochs=4, stride=1, batch_size=32, lr=1e-2, progress=False, threads=1, seed=0)).fit(run)
    loss = model.history_.train_loss
    assert loss[-1] < 0.5 * loss[0], loss
    held_out = cath.run(DecayingSinusoid(frequency_hz=0.3, baseline="mid"))
    u = _on_float32_grid(model, held_out.u[:150])
    again = LearnedModel.load(model.save(tmp_path / "toy.pt"))  # the registry rebuilds the spec
    assert again.network_ == model.network_
    np.testing.assert_array_equal(again.predict(u), model.predict(u))
    model.module_.double()  # float64 weights: the export equals torch to float64 rounding
    exported = export_model(model)
    assert exported.kind == "toy-gru" and exported.n_x == 5 and exported.state_names[0] == "toy.v0[k-5]"
    np.testing.assert_allclose(exported.simulate(u), model.predict(u), rtol=0, atol=1e-9)
    bare = export_network(model.module_, model.input_scaler_, model.output_scaler_)  # found by the registry
    assert bare.kind == "toy-gru"


def test_toy_network_is_a_hybrid_residual(toy, cath, run):
    hybrid = HybridModel(cath.truth_model(), toy(hidden=4, seq_len=4), training=TrainingSettings(
        epochs=2, stride=2, progress=False, threads=1, seed=0)).fit(run)
    yhat = hybrid.predict(run)
    assert yhat.shape == (run.n,) and np.all(np.isfinite(yhat))
    exported = export_model(hybrid)
    assert exported.kind == "hybrid" and exported.meta["residual"]["network"] == "toy-gru"
    np.testing.assert_allclose(exported.simulate(run.u), yhat, atol=1e-4)


def test_toy_network_appears_in_hyst_compare(toy, cath, tmp_path):
    import csv

    from hybrid.cli import main

    split = paper_protocol(cath, frequencies=(0.5,), tests=(0.45,), baselines=("mid",))
    for part, runs in (("train", split.train), ("test", split.test)):
        for traj in runs:
            traj.to_csv(tmp_path / "data" / part / f"{traj.source}.csv")
    out = tmp_path / "cmp"
    assert main(["compare", "--data", str(tmp_path / "data"), "--preset", "tiny", "--networks", "toy-gru",
                 "--physics", "backlash+linear", "--peers", "none",  # the selection and peers: test_compare
                 "--no-figures", "--no-progress", "--out", str(out)]) == 0
    with open(out / "compare.csv") as fh:
        pooled = {(r["direction"], r["model"]): float(r["rmse"]) for r in csv.DictReader(fh) if r["test"] == "id:all"}
    for direction in ("forward", "inverse"):
        for model in ("toy-gru", "toy-gru+physics"):
            assert np.isfinite(pooled[direction, model]), (direction, model)
    assert "| toy-gru | learned |" in (out / "compare.md").read_text()


def test_register_network_refuses_a_taken_name_or_a_non_network(toy):
    from physics.data import DataError

    with pytest.raises(DataError, match="'toy-gru' is taken by ToyGRU"):
        register_network(type("OtherToy", (ToyGRU,), {}))
    with pytest.raises(DataError, match="AbstractNetwork subclass"):
        register_network(ToyModule)
    assert register_network(ToyGRU) is ToyGRU  # registering the same class again is harmless


def test_toy_network_is_a_model_folders_residual(toy, cath, tmp_path, capsys):
    """``hyst fit --residual NAME`` and ``fit_model_dir`` take any registered network: the folder's
    model is a hybrid with the toy as its residual, and its exported step equals it."""
    from hybrid.cli import main
    from hybrid.experiments import fit_model_dir
    from hybrid.export import ExportedModel, load
    from hybrid.networks import RESIDUALS

    assert RESIDUALS[-1] == "toy-gru" and "toy-gru" in RESIDUALS
    split = paper_protocol(cath, frequencies=(0.5,), tests=(0.45,), baselines=("zero", "mid", "end"))
    result = fit_model_dir(split.train, tmp_path / "m", physics="backlash+linear", residual="toy-gru",
                           preset="tiny", progress=False)
    assert result.residual == "toy-gru" and result.model.network_ == ToyGRU()
    paths = [t.to_csv(tmp_path / f"run{i}.csv") for i, t in enumerate(split.train)]
    assert main(["fit", *map(str, paths), "--physics", "backlash+linear", "--residual", "toy-gru",
                 "--out", str(tmp_path / "cli"), "--no-progress"]) == 0
    assert "residual toy-gru" in capsys.readouterr().out
    model, step = load(tmp_path / "cli"), ExportedModel.load(tmp_path / "cli" / "step.casadi")
    assert isinstance(model, HybridModel) and model.network_ == ToyGRU()
    assert step.kind == "hybrid" and step.meta["residual"]["network"] == "toy-gru"
    u = split.test[0].u[:200]
    np.testing.assert_allclose(step.simulate(u), model.predict(u), atol=1e-4)
