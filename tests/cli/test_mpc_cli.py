"""``hyst export`` and ``hyst mpc`` from the command line."""

import json

import casadi as ca
import numpy as np
import pytest

from hybrid.cli._main import main
from hybrid.export import ExportedModel


@pytest.fixture()
def fit_json(tmp_path):
    path = tmp_path / "fit.json"
    path.write_text(json.dumps({"model": "lag+linear",
                                "parameters": {"lag.time_constant_s": 0.2, "linear.gain": 11.0,
                                               "linear.offset": 30.0}}))
    return path


def test_export_a_fit_json_and_c_code(tmp_path, fit_json, capsys):
    out = tmp_path / "step.casadi"
    assert main(["export", str(fit_json), "--out", str(out), "--c-code", str(tmp_path / "c")]) == 0
    f = ca.Function.load(str(out))
    m = ExportedModel.load(out)
    assert m.meta["parameters"]["lag.time_constant_s"] == 0.2 and m.dt == 0.04
    assert float(f(m.x0(1.0), 1.0)[1]) == pytest.approx(41.0)
    assert (tmp_path / "c" / "step.c").is_file() and (tmp_path / "c" / "step_demo.c").is_file()
    assert "wrote" in capsys.readouterr().out


def test_mpc_writes_table_summary_and_figure(tmp_path, fit_json):
    out = tmp_path / "mpc"
    assert main(["mpc", "--model", str(fit_json), "--reference", "sine", "--duration", "2",
                 "--horizon", "8", "--out", str(out)]) == 0
    table = np.genfromtxt(out / "closed_loop.csv", delimiter=",", names=True)
    assert table.size == 50 and "solve_time_s" in table.dtype.names
    summary = json.loads((out / "summary.json").read_text())
    assert summary["solves"] == 50 and summary["rmse_deg"] > 0
    assert (out / "closed_loop.png").stat().st_size > 1000


def test_mpc_reads_a_reference_file(tmp_path):
    ref = tmp_path / "ref.csv"
    ref.write_text("reference\n" + "\n".join(str(50 + i * 0.1) for i in range(20)))
    assert main(["mpc", "--model", "lag+boucwen+linear", "--reference", str(ref), "--horizon", "5",
                 "--out", str(tmp_path / "o"), "--no-figures"]) == 0
    assert json.loads((tmp_path / "o" / "summary.json").read_text())["solves"] == 20


def test_bad_input_is_one_line_and_exit_2(tmp_path, capsys):
    assert main(["export", "lag+nothing", "--out", str(tmp_path / "s.casadi")]) == 2
    assert main(["export", "lag", "--out", str(tmp_path / "s.bin")]) == 2
    assert main(["mpc", "--model", "lag+linear", "--reference", str(tmp_path / "none.csv"),
                 "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 3 and all(line.startswith("hyst ") for line in err)


def test_mpc_closes_the_loop_on_a_model_of_measured_data_in_its_own_units(tmp_path):
    """A fit in metres and radians at 200 Hz, controlled on a plant fitted to other runs of the same
    actuator: bounds, rate limit and references come from the range it was fitted on."""
    from physics import Series

    truth = Series.from_spec("lag+backlash+linear", dt=0.005).for_scales(1e-6, 1e-3)
    truth.set_params(**{"lag.time_constant_s": 0.05, "backlash.width": 4e-7, "linear.gain": 150.0,
                        "linear.offset": 2e-3})
    rng = np.random.default_rng(0)
    fits = []
    for k, f in enumerate((0.5, 1.3)):
        t = np.arange(0, 8, 0.005)
        u = 1e-5 * (1 - np.cos(2 * np.pi * f * t) * np.exp(-0.1 * t))  # 0..2e-5 m
        y = truth.simulate(u) + rng.normal(0, 2e-6, t.size)
        csv = tmp_path / f"run{k}.csv"
        np.savetxt(csv, np.c_[t, u, y], delimiter=",", header="time,u,y", comments="")
        fits.append(tmp_path / f"fit{k}.json")
        assert main(["identify", str(csv), "--model", "lag+backlash+linear", "--out", str(fits[-1])]) == 0
    out = tmp_path / "mpc"
    assert main(["mpc", "--model", str(fits[0]), "--plant", str(fits[1]), "--reference", "steps",
                 "--duration", "3", "--horizon", "10", "--out", str(out), "--no-figures"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    lo, hi = summary["u_bounds"]
    assert 0 <= lo < 1e-7 and 1.9e-5 < hi <= 2.01e-5  # the range of the input fitted on, in metres
    assert summary["du_max"] == pytest.approx((hi - lo) / 12)
    table = np.genfromtxt(out / "closed_loop.csv", delimiter=",", names=True)
    assert np.all((table["u"] >= lo - 1e-9 * hi) & (table["u"] <= hi * (1 + 1e-9)))  # (10 digits in the CSV)
    span = np.ptp(table["reference"])
    assert span > 1e-3 and summary["rmse"] < 0.15 * span  # steps between rest outputs of about 3e-3 rad
    assert main(["mpc", "--model", str(fits[0]), "--plant", str(fits[1]), "--u-bounds", "1,0",
                 "--out", str(out)]) == 2


def test_mpc_runs_at_the_models_own_rate_and_refuses_another(tmp_path, capsys):
    """A model fitted at 100 Hz: --duration is seconds of its clock, and --rate 25 is refused with both rates."""
    path = tmp_path / "fit100.json"
    path.write_text(json.dumps({"model": "lag+linear", "dt": 0.01,
                                "parameters": {"lag.time_constant_s": 0.2, "linear.gain": 11.0, "linear.offset": 30.0}}))
    out = tmp_path / "o"
    assert main(["mpc", "--model", str(path), "--duration", "0.5", "--horizon", "5", "--out", str(out),
                 "--no-figures"]) == 0
    table = np.genfromtxt(out / "closed_loop.csv", delimiter=",", names=True)
    assert table.size == 50 and np.allclose(np.diff(table["time_s"]), 0.01)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["rate_hz"] == 100.0
    assert "at 100 Hz" in capsys.readouterr().out
    assert main(["mpc", "--model", str(path), "--rate", "25", "--out", str(tmp_path / "p")]) == 2
    err = capsys.readouterr().err
    assert "25 Hz" in err and "100 Hz" in err


def test_mpc_with_a_measurement_every_n_samples_uses_the_estimator(tmp_path, fit_json, capsys):
    out = tmp_path / "m"
    assert main(["mpc", "--model", str(fit_json), "--duration", "2", "--horizon", "8", "--measure-every", "10",
                 "--out", str(out), "--no-figures"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["measure_every"] == 10 and summary["correction"] == "estimator"
    assert "% of solves converged" in capsys.readouterr().out
    assert main(["mpc", "--model", str(fit_json), "--duration", "2", "--horizon", "8", "--correction", "none",
                 "--out", str(tmp_path / "n"), "--no-figures"]) == 0
    blind = json.loads((tmp_path / "n" / "summary.json").read_text())
    # a lag+linear model of the virtual catheter (measured: 1.33 deg with the estimator, 2.16 without feedback)
    assert summary["rmse_deg"] < 0.75 * blind["rmse_deg"], (summary["rmse_deg"], blind["rmse_deg"])


def test_export_controller_writes_a_c_library_that_equals_the_python_controller(tmp_path):
    """`hyst export --controller DIR`: its main.c, built with the Makefile, closes the loop against the
    model's C step; the inputs and outputs equal the same loop run on the Python controller to 1e-6."""
    import shutil
    import subprocess

    from hybrid.control import TrackingMPC, reference_signal, rest_output
    from physics import Series

    if shutil.which("gcc") is None or shutil.which("make") is None:
        pytest.skip("gcc and make are needed to build the C controller")
    series = Series.from_spec("lag+boucwen+linear", dt=0.04)
    series.input_range = (0.0, 6.0)
    fit = tmp_path / "fit.json"
    fit.write_text(json.dumps({"model": series.spec, "series": series.to_dict(), "parameters": series.param_dict()}))
    folder = tmp_path / "ctrl"
    assert main(["export", str(fit), "--out", str(tmp_path / "step.casadi"), "--controller", str(folder),
                 "--horizon", "10", "--estimator", "20"]) == 0
    assert {"controller.c", "controller.h", "main.c", "Makefile"} <= {p.name for p in folder.iterdir()}
    subprocess.run(["make", "-s", "-C", str(folder)], check=True, capture_output=True)
    c_loop = np.loadtxt(subprocess.run([str(folder / "closed_loop")], capture_output=True, text=True,
                                       check=True).stdout.splitlines())
    assert c_loop.shape == (250, 3)  # 10 s at 25 Hz
    model = ExportedModel.load(tmp_path / "step.casadi")
    mpc = TrackingMPC(model, horizon=10, solver="fixed-sqp", solver_options={"iterations": 1, "compile": False})
    u0 = 0.5  # a twelfth inside the bounds, as main.c
    ref = reference_signal("sine", rest_output(model, u0), rest_output(model, 5.5), duration_s=10.4, dt=0.04)
    x, u_prev, rows = model.x0(u0), u0, []
    for k in range(c_loop.shape[0]):
        u = mpc.solve(x, ref[k:k + 10], u_prev=u_prev)
        x, y = model.step(x, u)
        x, u_prev = np.asarray(x, dtype=float).ravel(), u
        rows.append((k, u, float(y)))
    np.testing.assert_allclose(c_loop, np.array(rows), rtol=0, atol=1e-6)
    assert np.sqrt(np.mean((c_loop[50:, 2] - ref[50:250]) ** 2)) < 1.0  # and it tracks (deg)


def test_mpc_keeps_the_online_interval_inside_the_output_bounds(tmp_path, fitted_linear, capsys):
    """--y-bounds with --tighten and --measure-every: the band inside the bounds is the online one, its
    half-widths recorded; the model's output backs off from the bound by that band (narrower than the
    offline 3.4 deg of this folder), and --tighten without a calibrated interval or bounds is refused."""
    import numpy as np

    from hybrid.export._load import folder_intervals

    model = fitted_linear / "model"
    out = tmp_path / "band"
    assert main(["mpc", "--model", str(model), "--plant", "virtual", "--duration", "8", "--horizon", "10",
                 "--y-bounds", "20,52", "--tighten", "--measure-every", "10", "--out", str(out), "--no-figures"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    offline = folder_intervals(model)[0].quantile()
    assert summary["interval"] == "online" and summary["y_bounds"] == [20.0, 52.0]
    assert 0 < summary["mean_half_width"] < 0.6 * offline, (summary["mean_half_width"], offline)
    table = np.genfromtxt(out / "closed_loop.csv", delimiter=",", names=True)
    assert table["y_model_deg"].max() <= 52.0 - 0.3 + 1e-3  # backs off by the band (>= 0.3 deg here)
    capsys.readouterr()
    assert main(["mpc", "--model", str(model), "--tighten", "--out", str(tmp_path / "x")]) == 2
    assert "--y-bounds" in capsys.readouterr().err
    assert main(["mpc", "--model", "lag+linear", "--y-bounds", "20,52", "--tighten", "--out", str(tmp_path / "y")]) == 2
    assert "not a model folder" in capsys.readouterr().err


def test_mpc_fixed_sqp_keeps_the_online_interval_inside_the_output_bounds(tmp_path, fitted_linear):
    """--solver fixed-sqp (the C controller's) with --y-bounds --tighten --measure-every: the online band
    reaches its control function as the half-widths h; the model's output backs off from the bound by
    that band, up to the soft constraint's small excess (measured: max 50.65 deg, band 1.38 deg on
    average, bound 52; IPOPT: 51.01 with its 1.41 deg band)."""
    model = fitted_linear / "model"
    out = tmp_path / "fixed"
    assert main(["mpc", "--model", str(model), "--plant", "virtual", "--duration", "8", "--horizon", "10",
                 "--y-bounds", "20,52", "--tighten", "--measure-every", "10", "--solver", "fixed-sqp", "--out", str(out),
                 "--no-figures"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["solver"] == "fixed-sqp" and summary["interval"] == "online"
    table = np.genfromtxt(out / "closed_loop.csv", delimiter=",", names=True)
    assert table["y_model_deg"].max() <= 52.0 - 0.3 + 0.05  # backs off by the band (>= 0.3 deg), soft: +0.05
    assert table["y_model_deg"].max() > 52.0 - 3 * summary["mean_half_width"]  # and follows the reference up to it
    assert table["y_model_deg"].min() >= 20.0 - 0.05


def test_export_controller_with_output_bounds_feeds_the_half_width(tmp_path, fitted_linear, capsys):
    """`hyst export --controller DIR --y-bounds LO,HI`: the C control call takes the half-widths h, main.c
    feeds the model folder's offline one (3.39 deg here), and its closed loop keeps y + h under the bound
    up to the soft constraint's excess (measured: max y 48.647 against 52 - 3.390 = 48.610)."""
    import shutil
    import subprocess

    from hybrid.export._load import folder_intervals

    if shutil.which("gcc") is None or shutil.which("make") is None:
        pytest.skip("gcc and make are needed to build the C controller")
    model, folder = fitted_linear / "model", tmp_path / "ctrl"
    assert main(["export", str(model), "--out", str(tmp_path / "step.casadi"), "--controller", str(folder),
                 "--horizon", "10", "--y-bounds", "20,52"]) == 0
    assert "less the half-widths h" in capsys.readouterr().out
    q = folder_intervals(model)[0].quantile()
    assert f"half_width = {q!r};" in (folder / "main.c").read_text()
    subprocess.run(["make", "-s", "-C", str(folder)], check=True, capture_output=True)
    y = np.loadtxt(subprocess.run([str(folder / "closed_loop")], capture_output=True, text=True,
                                  check=True).stdout.splitlines())[:, 2]
    assert 52.0 - q - 0.5 < y.max() <= 52.0 - q + 0.06
    assert main(["export", str(model), "--out", str(tmp_path / "s.casadi"), "--y-bounds", "20,52"]) == 2
    assert "--controller" in capsys.readouterr().err


def test_export_controller_with_measure_every_runs_the_online_band(tmp_path, fitted_linear, capsys):
    """`hyst export --controller DIR --y-bounds LO,HI --measure-every N`: main.c runs the model folder's
    online band (AdaptiveIntervals(every=N) on its calibrated intervals, as `hyst mpc --tighten
    --measure-every N`): the offline half-width until the first measurement, then the band's, which
    moves; y + h stays under the bound up to the soft constraint's excess. Refused without the bounds
    or without intervals."""
    import shutil
    import subprocess

    from hybrid.export._load import folder_intervals
    from hybrid.intervals import AdaptiveIntervals
    from physics import Series

    if shutil.which("gcc") is None or shutil.which("make") is None:
        pytest.skip("gcc and make are needed to build the C controller")
    model, folder = fitted_linear / "model", tmp_path / "ctrl"
    assert main(["export", str(model), "--out", str(tmp_path / "step.casadi"), "--controller", str(folder),
                 "--horizon", "10", "--y-bounds", "20,52", "--measure-every", "10"]) == 0
    assert "the online band's, measured every 10 samples" in capsys.readouterr().out
    online = AdaptiveIntervals(every=10).fit(folder_intervals(model)[0])
    main_c = (folder / "main.c").read_text()
    assert f"offline = {online.offline_!r};" in main_c and "measure_every = 10;" in main_c
    subprocess.run(["make", "-s", "-C", str(folder), "closed_loop"], check=True, capture_output=True)
    c_loop = np.loadtxt(subprocess.run([str(folder / "closed_loop")], capture_output=True, text=True,
                                       check=True).stdout.splitlines())
    y, h = c_loop[:, 2], c_loop[:, 3]
    assert h[0] == pytest.approx(online.offline_, abs=1e-12) and np.ptp(h[1:]) > 0
    assert (y + h).max() <= 52.0 + 0.06
    series = Series.from_spec("lag+linear", dt=0.04)  # a fit JSON: an input range, no intervals
    series.input_range = (0.0, 6.0)
    fit = tmp_path / "fit.json"
    fit.write_text(json.dumps({"model": series.spec, "series": series.to_dict(), "parameters": series.param_dict()}))
    for argv, words in (([str(model), "--controller", str(tmp_path / "c2"), "--measure-every", "10"], "--y-bounds"),
                        ([str(model), "--measure-every", "10"], "--controller"),
                        ([str(fit), "--controller", str(tmp_path / "c3"), "--y-bounds", "20,52",
                          "--measure-every", "10"], "online interval")):
        assert main(["export", *argv, "--out", str(tmp_path / "s.casadi")]) == 2
        assert words in capsys.readouterr().err


def test_mpc_warns_when_the_reference_lies_outside_the_output_bounds(tmp_path, fitted_linear, capsys):
    """--y-bounds 1000,2000 on a model of 30-80 deg: 0 % of solves converged and exit 0 with nothing said;
    now one warning names the reference's range and the bounds. Bounds the reference crosses say nothing."""
    model = fitted_linear / "model"
    capsys.readouterr()
    assert main(["mpc", "--model", str(model), "--duration", "1", "--horizon", "5", "--y-bounds", "1000,2000",
                 "--out", str(tmp_path / "far"), "--no-figures"]) == 0
    lines = capsys.readouterr().err.splitlines()
    assert all(line.startswith("hyst mpc: warning: ") for line in lines)
    assert any("the reference (" in line and "--y-bounds 1000,2000 on every sample" in line for line in lines)
    assert main(["mpc", "--model", str(model), "--duration", "1", "--horizon", "5", "--y-bounds", "20,52",
                 "--out", str(tmp_path / "near"), "--no-figures"]) == 0
    assert capsys.readouterr().err == ""


def test_mpc_refuses_correction_none_with_measure_every(tmp_path, capsys):
    """The estimator corrects the output whatever --correction said (summary.json: 'estimator')."""
    capsys.readouterr()
    assert main(["mpc", "--model", "linear", "--measure-every", "5", "--correction", "none",
                 "--out", str(tmp_path / "m")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--correction none contradicts --measure-every" in err
    assert not (tmp_path / "m").exists()


def test_mpc_warns_when_the_plant_never_reaches_the_reference(tmp_path, fitted_linear, capsys):
    """A --plant fitted on the same runs in micro-units (y x 1e-7): exit 0, RMSE 41.8, nothing said; now a
    warning asks whether plant, reference and model share their units."""
    run = np.loadtxt(fitted_linear / "run.csv", delimiter=",", skiprows=1, usecols=(0, 1, 2))
    run[:, 2] *= 1e-7
    np.savetxt(tmp_path / "micro.csv", run, delimiter=",", header="time,u,y", comments="", fmt="%.17g")
    assert main(["fit", str(tmp_path / "micro.csv"), "--physics", "linear", "--residual", "none", "--no-progress",
                 "--out", str(tmp_path / "micro")]) == 0
    capsys.readouterr()
    assert main(["mpc", "--model", str(fitted_linear / "model"), "--plant", str(tmp_path / "micro"), "--duration", "1",
                 "--horizon", "5", "--no-figures", "--out", str(tmp_path / "mpc")]) == 0
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "warning: the plant's output (" in err and "never enters the reference's" in err


def test_mpc_on_a_lab_model_closes_the_loop_on_that_model_by_default(tmp_path, capsys):
    """A hysteretic actuator in motor counts (input 1400-2400, a play wider than a tenth of it) fitted with
    hyst fit: hyst mpc with no option closed the loop on the virtual catheter (0-6 mm, 30-90 deg), warned
    that the plant never reached the reference and tracked with an RMSE far off the card's; now it runs
    on the folder's own model with its training RMSE as noise, from rest mid-range, and tracks near it."""
    from physics import Series

    truth = Series.from_spec("lag+backlash+linear", dt=0.02).set_params(**{
        "lag.time_constant_s": 0.1, "backlash.width": 150.0, "linear.gain": 0.05, "linear.offset": -95.0})
    rng = np.random.default_rng(3)
    paths = []
    for k, (amp, f) in enumerate(((500.0, 0.3), (350.0, 0.5), (420.0, 0.4))):
        t = np.arange(0, 12, 0.02)
        u = 1900.0 + amp * np.sin(2 * np.pi * f * t)
        y = truth.simulate(u) + rng.normal(0, 0.2, t.size)
        paths.append(tmp_path / f"run{k}.csv")
        np.savetxt(paths[-1], np.c_[t, u, y], delimiter=",", header="time,u,y", comments="")
    model = tmp_path / "model"
    assert main(["fit", *map(str, paths[:2]), "--test", str(paths[2]), "--physics", "lag+backlash+linear",
                 "--residual", "none", "--no-progress", "--out", str(model)]) == 0
    capsys.readouterr()
    assert main(["mpc", "--model", str(model), "--duration", "4", "--no-figures", "--out", str(tmp_path / "mpc")]) == 0
    assert "never enters" not in capsys.readouterr().err
    summary = json.loads((tmp_path / "mpc" / "summary.json").read_text())
    card = json.loads((model / "card.json").read_text())
    test_rmse = [r["model_rmse"] for r in card["rows"] if r["set"] == "test"][0]
    assert summary["plant"] == str(model) and summary["noise_std"] == pytest.approx(0.2, rel=0.3)
    assert summary["rmse"] <= 2 * test_rmse, (summary["rmse"], test_rmse)
    assert main(["mpc", "--model", str(model), "--plant", "virtual", "--duration", "1", "--horizon", "5",
                 "--no-figures", "--out", str(tmp_path / "v")]) == 0  # the virtual catheter on request
    assert json.loads((tmp_path / "v" / "summary.json").read_text())["plant"] == "virtual"
