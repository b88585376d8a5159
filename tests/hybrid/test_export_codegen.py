"""Generated C code: compiled with gcc, loaded back by casadi.external, called from a C program."""

import numpy as np
import pytest

from hybrid.export import compile_c_demo, export_model, export_network, has_compiler, load_compiled
from physics import Series

needs_gcc = pytest.mark.skipif(not has_compiler("gcc"), reason="gcc is not installed")


@needs_gcc
def test_compiled_physics_step_equals_the_vm(tmp_path):
    m = export_model(Series.from_spec("lag+backlash+boucwen+linear"))
    lib = m.codegen(tmp_path)
    f = load_compiled(lib)
    rng = np.random.default_rng(0)
    for _ in range(5):
        x, u = m.x0(rng.uniform(0, 6)) + rng.normal(0, 0.1, m.n_x), rng.uniform(0, 6)
        for a, b in zip(f(x, u), m.step(x, u)):
            np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=0, atol=1e-12)


@needs_gcc
def test_small_lstm_compiles_and_a_c_program_calls_it(tmp_path):
    torch = pytest.importorskip("torch")
    from hybrid.networks._lstm import FlaggedLSTM

    torch.manual_seed(0)
    m = export_network(FlaggedLSTM(1, 8, 2, 5, -1.0, 1).double(), mode="carried")
    x = m.x0(0.3)
    out = compile_c_demo(m.step, tmp_path, x, 0.7)
    x_next, y = m.step(x, 0.7)
    np.testing.assert_allclose(out, np.r_[float(y), np.asarray(x_next).ravel()], rtol=0, atol=1e-14)
    f = load_compiled(m.codegen(tmp_path / "lib"))
    np.testing.assert_allclose(np.asarray(f(x, 0.7)[1]), np.asarray(y), atol=1e-14)
