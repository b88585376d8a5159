"""Peers scored like our models: a linear ARX recovers a known system in any units, every peer takes a
warm-up window the same way, and the optional ones are deterministic and beat the mean."""

import numpy as np
import pytest

from hybrid.peers import PEERS, LinearARX, PolynomialNARX, SubnetPeer, available_peers
from physics.data import DataError, NotFittedError, Trajectory, warmup_split

DT = 0.04
T = np.arange(1500) * DT


def _arx_truth(u, a=(1.2, -0.4, 0.15), b=(0.3, 0.2, -0.1), c=0.05):
    """A stable third-order ARX system with a direct term (b[0] multiplies u[t])."""
    y = np.zeros_like(u)
    for t in range(3, u.size):
        y[t] = c + sum(a[i] * y[t - 1 - i] for i in range(3)) + sum(b[j] * u[t - j] for j in range(3))
    return y


def _runs(s_u=1.0, s_y=1.0):
    rng = np.random.default_rng(0)
    runs = []
    for k in range(3):
        u = np.sin(0.6 * T + k) + 0.5 * np.sin(2.1 * T) + 0.2 * rng.standard_normal(T.size)
        runs.append(Trajectory(T, s_u * u, s_y * _arx_truth(u), source=f"r{k}"))
    return runs


@pytest.mark.parametrize("s_u,s_y", [(1.0, 1.0), (1e-6, 1e-3), (1e4, 1e2)])
def test_arx_recovers_a_known_system_in_any_units(s_u, s_y):
    runs = _runs(s_u, s_y)
    arx = LinearARX(nk=0).fit(runs[:2])  # the truth has a direct term
    np.testing.assert_allclose(arx.a_, [1.2, -0.4, 0.15], atol=1e-8)
    window, rest = warmup_split(runs[2], 10)
    pred = arx.predict(rest, warmup=window)
    np.testing.assert_allclose(pred, rest.y, rtol=0, atol=1e-7 * np.ptp(rest.y))
    np.testing.assert_array_equal(arx.predict(rest.u, warmup=(window.u, window.y)), pred)  # both forms


def _two_outputs(scales=(1.0, 1.0), offsets=(0.0, 0.0)):
    """Runs of a known two-output ARX, ``y[t] = y[t-1] A + b u[t-1] + c``, outputs in their own units."""
    rng = np.random.default_rng(1)
    a, b, c = np.array([[0.8, 0.1], [-0.05, 0.7]]), np.array([0.5, -0.3]), np.array([0.1, 2.0])
    runs = []
    for k in range(3):
        u = 40.0 + np.sin(0.6 * T + k) + 0.2 * rng.standard_normal(T.size)  # far from zero, as real inputs are
        y = np.zeros((T.size, 2))
        for t in range(1, T.size):
            y[t] = y[t - 1] @ a + b * u[t - 1] + c
        y = y * scales + offsets
        runs.append(Trajectory(T, u, y[:, 0], output_name="angle", extra={"pos": y[:, 1]}, source=f"r{k}"))
    return runs, a, b, c


@pytest.mark.parametrize("scales,offsets", [((1.0, 1.0), (0.0, 0.0)), ((1e-3, 1e3), (5.0, -200.0))])
def test_an_arx_of_several_outputs_recovers_a_known_system_in_any_units(scales, offsets):
    runs, a, _, c = _two_outputs(scales, offsets)
    arx = LinearARX(na=1, nb=1, outputs=("angle", "pos")).fit(runs[:2])
    # the poles do not depend on the units: those of the truth's A
    np.testing.assert_allclose(np.sort_complex(arx.poles_), np.sort_complex(np.linalg.eigvals(a)), atol=1e-9)
    window, rest = warmup_split(runs[2], 10)
    pred = arx.predict(rest, warmup=window)
    truth = np.column_stack([rest.y, rest.extra["pos"]])
    assert pred.shape == truth.shape
    np.testing.assert_allclose(pred, truth, rtol=0, atol=1e-8 * np.ptp(truth, axis=0).max())
    pair = arx.predict(rest.u, warmup=(window.u, np.column_stack([window.y, window.extra["pos"]])))
    np.testing.assert_array_equal(pair, pred)  # both forms of the window
    again = LinearARX.from_dict(arx.to_dict())  # saved and read back: the same predictions
    np.testing.assert_array_equal(again.predict(rest, warmup=window), pred)
    # at rest: its steady output, as a long constant input settles to
    np.testing.assert_allclose(arx.rest_output(40.0), arx.predict(np.full(4000, 40.0))[-1], rtol=1e-9)
    one = LinearARX(na=1, nb=1).fit(runs[:2])
    assert "outputs" not in one.to_dict()  # a model of one output is saved as before


def test_an_arx_of_several_outputs_refuses_a_missing_column_and_a_bad_window():
    runs, *_ = _two_outputs()
    with pytest.raises(DataError, match="no output column 'tip'.*angle, pos"):
        LinearARX(outputs=("angle", "tip")).fit(runs)
    arx = LinearARX(na=1, nb=1, outputs=("angle", "pos")).fit(runs)
    with pytest.raises(DataError, match=r"\(k, 2\) output"):
        arx.predict(runs[0].u[10:], warmup=(runs[0].u[:10], runs[0].y[:10]))
    from hybrid.export import ExportError, export_arx

    with pytest.raises(ExportError, match="of one output"):
        export_arx(arx)


def test_arx_without_a_window_starts_at_its_rest_output():
    arx = LinearARX(nk=0).fit(_runs()[:2])
    u = np.full(50, 0.7)
    np.testing.assert_allclose(arx.predict(u), arx.predict(u)[0], rtol=0, atol=1e-9)  # at rest it stays there
    assert arx.predict(u)[0] == pytest.approx((0.05 + 0.4 * 0.7) / (1 - 0.95), rel=1e-6)


def test_an_inverse_peer_is_fitted_on_the_swapped_runs():
    runs = _runs()
    fwd, inv = LinearARX().fit(runs[:2]), LinearARX(direction="inverse").fit([r.swap() for r in runs[:2]])
    assert fwd.lags == 3 and LinearARX(nb=5, nk=2).lags == 6
    window, rest = warmup_split(runs[2], 10)
    np.testing.assert_allclose(inv.predict(rest.swap(), warmup=window.swap()), fwd.predict(rest, warmup=window),
                               rtol=0, atol=1e-9)


def test_bad_input_is_refused_with_what_to_fix():
    with pytest.raises(NotFittedError):
        LinearARX().predict(np.ones(5))
    with pytest.raises(DataError, match="direction"):
        LinearARX(direction="sideways").fit(_runs())
    with pytest.raises(DataError, match="longer than"):
        LinearARX(na=3).fit(Trajectory(T[:3], T[:3], T[:3]))
    with pytest.raises(DataError, match="'na' parameter"):
        LinearARX(na=-1).fit(_runs())
    with pytest.raises(DataError, match="'nk' parameter"):
        LinearARX(nk=-1).fit(_runs())
    with pytest.raises(DataError, match="same number"):
        LinearARX().fit(_runs()).predict(np.ones(5), warmup=(np.ones(4), np.ones(3)))


def test_every_peer_is_listed_with_whether_it_can_run():
    notes = available_peers()
    assert set(notes) == set(PEERS) and notes["arx"] is None
    for name, note in notes.items():
        assert note is None or "pip install" in note


def _nonlinear_runs():
    """A play (backlash) then a lag: the hysteresis a linear model cannot follow."""
    rng = np.random.default_rng(1)
    runs = []
    for k in range(3):
        u = 3 * np.sin(0.5 * T * (1 + 0.3 * k)) + 0.3 * rng.standard_normal(T.size)
        x, y = 0.0, np.zeros_like(u)
        for t in range(u.size):
            x = min(max(x, u[t] - 0.5), u[t] + 0.5)
            y[t] = (0.8 * y[t - 1] if t else 0.0) + 0.2 * x
        runs.append(Trajectory(T, u, y, source=f"n{k}"))
    return runs


def test_narx_is_deterministic_and_beats_the_mean():
    pytest.importorskip("sysidentpy", reason="the peers extra (sysidentpy) is not installed")
    runs = _nonlinear_runs()
    window, rest = warmup_split(runs[2], 10)
    preds = [PolynomialNARX().fit(runs[:2]).predict(rest, warmup=window) for _ in range(2)]
    np.testing.assert_array_equal(preds[0], preds[1])
    assert np.sqrt(np.mean((preds[0] - rest.y) ** 2)) < 0.3 * np.std(rest.y)


def test_subnet_is_deterministic_and_beats_the_mean():
    pytest.importorskip("deepSI", reason="the peers extra (deepsi) is not installed")
    runs = _nonlinear_runs()
    window, rest = warmup_split(runs[2], 10)
    preds = [SubnetPeer(iterations=150, batch_size=64, seed=3).fit(runs[:2]).predict(rest, warmup=window)
             for _ in range(2)]
    np.testing.assert_array_equal(preds[0], preds[1])
    assert np.sqrt(np.mean((preds[0] - rest.y) ** 2)) < 0.5 * np.std(rest.y)


def _with_a_second_output(runs):
    """The nonlinear runs with a second output: a delayed, shifted square of the first, in other units."""
    from dataclasses import replace

    return [replace(r, output_name="a", extra={"b": 50.0 + 3.0 * np.r_[r.y[:2], r.y[:-2]] ** 2}) for r in runs]


def test_narx_of_several_outputs_is_one_narx_per_output():
    """SysIdentPy's FROLS fits one output: the NARX of two outputs predicts each as the NARX of that output alone."""
    pytest.importorskip("sysidentpy", reason="the peers extra (sysidentpy) is not installed")
    from dataclasses import replace

    runs = _with_a_second_output(_nonlinear_runs())
    window, rest = warmup_split(runs[2], 10)
    both = PolynomialNARX(outputs=("a", "b")).fit(runs[:2])
    pred = both.predict(rest, warmup=window)
    assert pred.shape == (rest.n, 2) and both.predict(rest).shape == (rest.n, 2)
    for j, name in enumerate(("a", "b")):
        alone = [replace(r, y=r.y if name == "a" else r.extra["b"], extra={}) for r in runs]
        w, t = warmup_split(alone[2], 10)
        np.testing.assert_allclose(pred[:, j], PolynomialNARX().fit(alone[:2]).predict(t, warmup=w), rtol=1e-9,
                                   atol=1e-9 * np.ptp(t.y))


def test_subnet_of_several_outputs_ends_in_one_unit_per_output():
    pytest.importorskip("deepSI", reason="the peers extra (deepsi) is not installed")
    runs = _with_a_second_output(_nonlinear_runs())
    window, rest = warmup_split(runs[2], 10)
    peer = SubnetPeer(iterations=150, batch_size=64, seed=3, outputs=("a", "b")).fit(runs[:2])
    pred = peer.predict(rest, warmup=window)
    assert pred.shape == (rest.n, 2) and peer.predict(rest).shape == (rest.n, 2)
    measured = np.column_stack([rest.y, rest.extra["b"]])
    assert np.all(np.sqrt(np.mean((pred - measured) ** 2, axis=0)) < 0.5 * np.std(measured, axis=0))


@pytest.mark.parametrize("orders", [{}, {"nk": 0}, {"na": 2, "nb": 1}])
def test_the_arx_exports_as_a_step_whose_init_and_free_run_equal_predict(orders):
    from hybrid.export import export_model

    t = np.arange(600) * 0.04
    u = np.sin(0.7 * t) + 0.5 * np.sin(2.3 * t)
    y = np.zeros_like(u)
    for k in range(2, u.size):
        y[k] = 1.2 * y[k - 1] - 0.4 * y[k - 2] + 0.5 * u[k - 1] + 3
    arx = LinearARX(**orders).fit(Trajectory(t, u, y + np.random.default_rng(0).normal(0, 0.01, u.size)))
    test = Trajectory(t, np.cos(0.5 * t), y)
    step = export_model(arx, warmup=10)
    assert step.meta["warmup"] == 10 and step.kind == "arx"
    for x, rest, window in ((step.init(test.u[None, :10], test.y[None, :10]), test.segment(10), test.segment(0, 10)),
                            (step.x0(float(test.u[0])), test, None)):
        out = []
        for v in rest.u:
            x, yk = step.step(x, v)
            out.append(float(yk))
        assert np.max(np.abs(np.array(out) - arx.predict(rest, warmup=window))) < 1e-9
    again = LinearARX.from_dict(arx.to_dict())  # saved and read back: the same model
    assert np.array_equal(again.predict(test), arx.predict(test))
