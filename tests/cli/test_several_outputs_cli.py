"""``--output A,B,C`` (issue 55): ``hyst identify`` fits one model of every output; the commands that model one
output refuse several in one line; a named output that is missing, constant or a copy of the input is refused."""

import json

import numpy as np
import pytest

from _cli import write_pose

from hybrid.cli._main import main
from hybrid.virtual import DecayingSinusoid, TipArc, VirtualCatheter

COLUMNS = ("time", "Tendon Disp.", "Angle x", "Pos x", "Pos y")


def _write(path, run, **replace):
    return write_pose(path, run, COLUMNS, **replace)


@pytest.fixture(scope="module")
def runs():
    cath = VirtualCatheter(seed=6, tip=TipArc())
    return [cath.run(DecayingSinusoid(frequency_hz=f, baseline=b)) for f, b in ((0.2, "zero"), (0.5, "end"), (0.3, "mid"))]


def test_identify_fits_the_angle_and_the_tips_position_as_one_model(runs, tmp_path, capsys):
    files = [_write(tmp_path / f"r{i}.csv", r) for i, r in enumerate(runs)]
    out = tmp_path / "pose.json"
    status = main(["identify", *files[:2], "--test", files[2], "--input", "Tendon Disp.", "--output",
                   "Angle x,Pos x,Pos y", "--model", "backlash+boucwen+linear+arc", "--warmup", "10", "--rate", "25",
                   "--out", str(out)])
    printed = capsys.readouterr().out
    fit = json.loads(out.read_text())
    assert status == (0 if fit["status"] == "Converged" else 1)
    assert fit["outputs"] == ["Angle x", "Pos x", "Pos y"] and fit["warmup"] == 10
    assert fit["parameters"]["arc.length"] == pytest.approx(75.0, rel=0.02)
    assert fit["test_rmse"]["Angle x"] < 0.2 and fit["test_rmse"]["Pos x"] < 0.15 and fit["test_rmse"]["Pos y"] < 0.15
    assert "arc.length" in printed and "Pos y" in printed and "test RMSE" in printed
    # the fit predicts every output, named, beside its measurement, after the fit's warm-up: its test RMSE
    pred = tmp_path / "pred.csv"
    assert main(["predict", str(out), files[2], "--input", "Tendon Disp.", "--out", str(pred)]) == 0
    assert "after a warm-up of 10 measured samples (the fit's)" in capsys.readouterr().out
    header = pred.read_text().splitlines()[0].split(",")
    assert header == ["time", "u", "Angle x", "Angle x_pred", "Pos x", "Pos x_pred", "Pos y", "Pos y_pred"]
    table = np.loadtxt(pred, delimiter=",", skiprows=1)
    for j, name in enumerate(fit["outputs"]):
        err = table[:, 3 + 2 * j] - table[:, 2 + 2 * j]
        assert np.sqrt(np.mean(err**2)) == pytest.approx(fit["test_rmse"][name], rel=1e-6)
    # the exported step returns the output vector, as the fitted model simulates it
    from hybrid.export import ExportedModel, load

    step = tmp_path / "pose.casadi"
    assert main(["export", str(out), "--out", str(step)]) == 0
    exported, series = ExportedModel.load(step), load(str(out))
    assert exported.n_y == 3
    np.testing.assert_allclose(exported.simulate(runs[2].u), series.simulate(runs[2].u), rtol=1e-12, atol=1e-9)
    assert main(["export", str(out), "--out", str(step), "--controller", str(tmp_path / "ctrl")]) == 2
    assert "--controller (without --track) takes a model of one output" in capsys.readouterr().err
    # the tip's position tracked on the virtual catheter with its tip, as the angle is: within the sensors' noise
    for track, noise in (("Angle x", 0.15), ("Pos y", 0.1)):
        folder = tmp_path / f"mpc_{track[-1]}"
        assert main(["mpc", "--model", str(out), "--track", track, "--plant", "virtual", "--duration", "4",
                     "--no-figures", "--out", str(folder)]) == 0
        summary = json.loads((folder / "summary.json").read_text())
        assert summary["track"] == track and summary["rmse"] < noise, summary["rmse"]
    # the estimator on the tracked output's measurements alone, and output bounds on the tracked output
    folder = tmp_path / "mpc_measured"
    assert main(["mpc", "--model", str(out), "--track", "Pos y", "--plant", "virtual", "--measure-every", "25",
                 "--duration", "4", "--no-figures", "--out", str(folder)]) == 0
    assert json.loads((folder / "summary.json").read_text())["rmse"] < 0.1
    # the position tracked while the tracker measures the angle alone: the estimator of every output's one state
    folder = tmp_path / "mpc_angle_measured"
    assert main(["mpc", "--model", str(out), "--track", "Pos y", "--plant", "virtual", "--measure-every", "25",
                 "--measure-outputs", "Angle x", "--duration", "4", "--no-figures", "--out", str(folder)]) == 0
    summary = json.loads((folder / "summary.json").read_text())
    assert summary["measure_outputs"] == ["Angle x"] and summary["noise_std"] == [0.15, 0.1, 0.1]
    assert summary["rmse"] < 0.1
    for extra, message in ((["--measure-outputs", "Angle x"], "give --track and --measure-every too"),
                           (["--measure-every", "25", "--measure-outputs", "Pos z"], "among the model's outputs"),
                           (["--measure-every", "25", "--measure-outputs", "Angle x", "--y-bounds", "50,65",
                             "--tighten"], "leave --tighten out")):
        assert main(["mpc", "--model", str(out), "--track", "Pos y", *extra, "--out", str(tmp_path / "m")]) == 2
        assert message in capsys.readouterr().err
    folder = tmp_path / "mpc_bounded"
    assert main(["mpc", "--model", str(out), "--track", "Pos y", "--plant", "virtual", "--y-bounds", "50,65",
                 "--solver", "fixed-sqp", "--duration", "4", "--no-figures", "--out", str(folder)]) == 0
    table = np.loadtxt(folder / "closed_loop.csv", delimiter=",", skiprows=1)
    assert table[:, 1].min() < 49 and table[:, 1].max() > 68  # the reference leaves the band on both sides
    assert 50 - 0.05 < table[:, 4].min() and table[:, 4].max() < 65 + 0.05  # measured 49.991 to 64.989 mm
    _angle_bounded_while_the_position_is_tracked(out, tmp_path, capsys)
    _c_controller_tracks(out, tmp_path)
    capsys.readouterr()
    _estimator_of_every_output(out, tmp_path, capsys)
    for extra, message in ((["--track", "Pos z"], "is not an output of --model"), ([], "name the one to track")):
        assert main(["mpc", "--model", str(out), *extra, "--out", str(tmp_path / "m")]) == 2
        assert message in capsys.readouterr().err
    for extra, message in ((["--interval", "0.9"], "is not a model folder written by `hyst fit`"),
                           (["--measure-every", "5", "--interval", "0.9"], "takes a model of one output"),
                           (["--measure-outputs", "Pos x"], "give --measure-every too"),
                           (["--measure-every", "5", "--measure-outputs", "Pos z"], "among the model's outputs"),
                           (["--output", "Pos x"], "models the outputs Angle x, Pos x, Pos y")):
        assert main(["predict", str(out), files[2], "--input", "Tendon Disp.", *extra, "--out", str(pred)]) == 2
        assert message in capsys.readouterr().err
    _measured_position_corrects_its_offset(out, runs[2], tmp_path, capsys)


def _angle_bounded_while_the_position_is_tracked(fit, tmp_path, capsys):
    """``--track "Pos y" --y-bounds "Angle x:LO,HI"``: the reference asks the position for more than an angle inside
    LO-HI gives, on either side of the arc's peak (the position the reference asks for is reached at a higher angle
    and at a lower one, and which of the two a solver heads for depends on its iterates: bounding one side only
    tested the solver's branch, not the bound); the angle stays inside the bounds on the plant (the model itself:
    the summary's range along the applied inputs) and reaches one of them while the position gets as near as it
    may, with IPOPT and with the C controller's fixed-iteration SQP (a soft bound: within a few hundredths). The
    run starts at 64 deg, inside the bounds."""
    capsys.readouterr()
    runs = {}
    for solver, bounds in (("auto", None), ("auto", "Angle x:50,70"), ("fixed-sqp", "Angle x:50,70")):
        folder = tmp_path / f"mpc_angle_{solver}_{bounds is not None}"
        extra = [] if bounds is None else ["--y-bounds", bounds]
        assert main(["mpc", "--model", str(fit), "--track", "Pos y", "--duration", "2", "--horizon", "10",
                     "--solver", solver, *extra, "--no-figures", "--out", str(folder)]) == 0
        runs[solver, bounds] = json.loads((folder / "summary.json").read_text())
    printed = capsys.readouterr().out
    assert "Angle x (bounded to 50,70) ran from" in printed
    free, ipopt, fixed = (runs[k] for k in (("auto", None), ("auto", "Angle x:50,70"), ("fixed-sqp", "Angle x:50,70")))
    assert "bounded_range" not in free and free["rmse"] < 0.05  # unbounded: tracked
    assert ipopt["solver"] == "ipopt" and ipopt["bound"] == fixed["bound"] == "Angle x"
    for summary, slack in ((ipopt, 1e-3), (fixed, 0.05)):  # a bound reached and both kept
        lo, hi = summary["bounded_range"]
        assert 50 - slack <= lo and hi <= 70 + slack and (lo < 50.1 or hi > 69.9), summary["bounded_range"]
    assert ipopt["rmse"] > 2.0 and fixed["rmse"] > 2.0  # the position stops short where the angle may not follow
    for extra, message in ((["--y-bounds", "Pos z:0,55"], "is not an output of"),
                           (["--y-bounds", "Angle x:0,70", "--tighten"], "needs the model's calibrated interval"),
                           (["--y-bounds", ":0,55"], "expected OUTPUT:LO,HI")):
        assert main(["mpc", "--model", str(fit), "--track", "Pos y", *extra, "--out", str(tmp_path / "m")]) == 2
        assert message in capsys.readouterr().err


def _measured_position_corrects_its_offset(fit, run, tmp_path, capsys):
    """The tracker reads Pos y 2 mm high; only the position is measured, every 5 samples: Pos y's prediction
    loses the offset, the angle (never measured) keeps its free-run error, and the rows say which samples
    were measured."""
    data = _write(tmp_path / "offset.csv", run, **{"Pos y": run.extra["Pos y"] + 2.0})
    errors = {}
    for how, extra in (("free", []), ("measured", ["--measure-every", "5", "--measure-outputs", "Pos x,Pos y"])):
        pred = tmp_path / f"{how}.csv"
        assert main(["predict", str(fit), data, "--input", "Tendon Disp.", *extra, "--out", str(pred)]) == 0
        printed = capsys.readouterr().out
        header = pred.read_text().splitlines()[0].split(",")
        table = np.loadtxt(pred, delimiter=",", skiprows=1)
        errors[how] = {o: np.sqrt(np.mean((table[:, header.index(f"{o}_pred")] - table[:, header.index(o)]) ** 2))
                       for o in ("Angle x", "Pos x", "Pos y")}
    assert "from the measurements of Pos x, Pos y before it (one every 5 samples" in printed
    assert header[-1] == "measured" and table[:, -1].sum() == np.ceil(len(table) / 5)
    free, fed = errors["free"], errors["measured"]
    assert free["Pos y"] > 1.9 and fed["Pos y"] < 0.15, errors  # tracker noise 0.1 mm
    assert fed["Angle x"] < 1.1 * free["Angle x"], errors


def test_identify_with_no_model_chooses_the_chain_and_tries_the_arc_held_out(runs, tmp_path, capsys):
    """``hyst identify --output A,B,C`` with no ``--model``: the chain the selection chooses for the angle, read by
    a cubic map per output and by the arc, each fitted without the held-out branches; the kept one in the JSON
    beside what was tried, as ``hyst fit`` and ``hyst discover`` choose."""
    files = [_write(tmp_path / f"r{i}.csv", r) for i, r in enumerate(runs)]
    out = tmp_path / "auto.json"
    assert main(["identify", *files, "--input", "Tendon Disp.", "--output", "Angle x,Pos x,Pos y", "--warmup", "10",
                 "--rate", "25", "--out", str(out)]) in (0, 1)
    fit = json.loads(out.read_text())
    tried = fit["tried"]
    assert len(tried["specs"]) == 2 and any(s.endswith("+arc") for s in tried["specs"])
    assert all(isinstance(v, float) for v in tried["specs"].values())
    kept = tried["kept"]
    assert fit["model"] == (kept if kept.endswith("+arc") else kept.removesuffix("linear") + "maps")
    assert "held out:" in capsys.readouterr().out
    assert all(fit["train_rmse"][o] < 2 * noise for o, noise in zip(fit["outputs"], (0.15, 0.1, 0.1)))


def test_discover_names_the_effects_on_the_angle_and_reads_every_output_from_its_chain(runs, tmp_path, capsys):
    """``hyst discover --output A,B,C``: the effects named on the first output (the virtual catheter's hysteresis
    and play), then the chain read by every output, a cubic map each and the arc tried held out; the model of
    every output in DIR/physics.json predicts a run it was not fitted on to each sensor's noise."""
    files = [_write(tmp_path / f"r{i}.csv", r) for i, r in enumerate(runs)]
    out = tmp_path / "discovery"
    assert main(["discover", *files, "--input", "Tendon Disp.", "--output", "Angle x,Pos x,Pos y", "--rate", "25",
                 "--no-figures", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    report = json.loads((out / "report.json").read_text())
    several = report["outputs"]
    assert "hysteresis" in report["named_effects"] and several["outputs"] == ["Angle x", "Pos x", "Pos y"]
    assert set(several["tried"]["specs"]) == {report["final_model"], report["final_model"] + "+arc"}
    assert "every output:" in printed and "physics.json" in printed
    fit = json.loads((out / "physics.json").read_text())
    assert fit["chain"] == {"spec": report["final_model"], "how": "discovery"} and fit["outputs"] == several["outputs"]
    pred = tmp_path / "pred.csv"
    held = _write(tmp_path / "held.csv", VirtualCatheter(seed=9, tip=TipArc()).run(
        DecayingSinusoid(frequency_hz=0.35, baseline="mid")))
    assert main(["predict", str(out / "physics.json"), held, "--input", "Tendon Disp.", "--out", str(pred)]) == 0
    header = pred.read_text().splitlines()[0].split(",")
    table = np.loadtxt(pred, delimiter=",", skiprows=1)
    for name, noise in zip(several["outputs"], (0.15, 0.1, 0.1)):
        err = table[:, header.index(f"{name}_pred")] - table[:, header.index(name)]
        assert np.sqrt(np.mean(err ** 2)) < 2 * noise, name


def test_a_hybrid_of_several_outputs_trains_predicts_and_exports(runs, tmp_path, capsys):
    """``hyst train --physics SPEC --output A,B,C``: one chain fitted to every output (a cubic map each), one residual
    network ending in three units; ``hyst predict`` writes each output, the checkpoint and the exported step
    (``--track``) agree with it, and the residual lowers each output's error below the physics' alone."""
    from hybrid.export import ExportedModel
    from hybrid.models import HybridModel

    files = [_write(tmp_path / f"r{i}.csv", r) for i, r in enumerate(runs)]
    model = tmp_path / "hybrid.pt"
    assert main(["train", *files[:2], "--model", "fnn-hib", "--physics", "lag+linear", "--input", "Tendon Disp.",
                 "--output", "Angle x,Pos x,Pos y", "--epochs", "60", "--validation", "0", "--out", str(model)]) == 0
    pred = tmp_path / "pred.csv"
    assert main(["predict", str(model), files[2], "--input", "Tendon Disp.", "--warmup", "10", "--out",
                 str(pred)]) == 0
    header = pred.read_text().splitlines()[0].split(",")
    assert header == ["time", "u", "Angle x", "Angle x_pred", "Pos x", "Pos x_pred", "Pos y", "Pos y_pred"]
    table = np.loadtxt(pred, delimiter=",", skiprows=1)
    hybrid = HybridModel.load(model)
    assert tuple(hybrid.outputs) == ("Angle x", "Pos x", "Pos y") and hybrid.physics_.n_y == 3
    from physics.data import warmup_split

    window, rest = warmup_split(runs[2], 10)
    physics = hybrid.predict_physics(rest, warmup=window)
    for j in range(3):
        truth, ours = table[:, 2 + 2 * j], table[:, 3 + 2 * j]
        err, alone = np.sqrt(np.mean((ours - truth) ** 2)), np.sqrt(np.mean((physics[:, j] - truth) ** 2))
        assert err < 0.9 * alone, (header[2 + 2 * j], err, alone)
    step = tmp_path / "y.casadi"
    assert main(["export", str(model), "--track", "Pos y", "--out", str(step)]) == 0
    exported = ExportedModel.load(step)
    np.testing.assert_allclose(exported.simulate(runs[2].u), hybrid.predict(runs[2])[:, 2], rtol=1e-5, atol=1e-4)


def test_a_network_alone_trains_on_several_outputs_and_the_rest_refuse_in_one_line(runs, tmp_path, capsys):
    """``hyst train --output A,B,C`` (a network alone): one FNN-HIB ending in three units, predicted per output by
    ``hyst predict`` and exported per output; an inverse of several outputs, and a command of one output, one
    line each."""
    files = [_write(tmp_path / f"r{i}.csv", r) for i, r in enumerate(runs)]
    model = tmp_path / "pose.pt"
    assert main(["train", *files[:2], "--model", "fnn-hib", "--input", "Tendon Disp.", "--output", "Angle x,Pos x,Pos y",
                 "--epochs", "30", "--validation", "0", "--out", str(model)]) == 0
    pred = tmp_path / "pred.csv"
    assert main(["predict", str(model), files[2], "--input", "Tendon Disp.", "--out", str(pred)]) == 0
    header = pred.read_text().splitlines()[0].split(",")
    assert header == ["time", "u", "Angle x", "Angle x_pred", "Pos x", "Pos x_pred", "Pos y", "Pos y_pred"]
    table = np.loadtxt(pred, delimiter=",", skiprows=1)
    for j in range(3):
        truth = table[:, 2 + 2 * j]
        assert np.sqrt(np.mean((table[:, 3 + 2 * j] - truth) ** 2)) < 0.1 * np.ptp(truth), header[2 + 2 * j]
    assert main(["export", str(model), "--track", "Pos y", "--out", str(tmp_path / "y.casadi")]) == 0
    capsys.readouterr()
    for extra, message in ((["--direction", "inverse"], "an inverse predicts the one input"),):
        status = main(["train", files[0], "--model", "fnn", "--input", "Tendon Disp.", "--output", "Angle x,Pos x",
                       *extra, "--out", str(tmp_path / "o.pt")])
        err = capsys.readouterr().err.strip()
        assert status == 2 and err.count("\n") == 0 and message in err, err
    status = main(["predict", str(model), files[2], "--input", "Tendon Disp.", "--output", "Angle x,Pos x", "--out",
                   str(pred)])
    err = capsys.readouterr().err.strip()
    assert status == 2 and err.count("\n") == 0
    assert "'Angle x,Pos x' names 2 columns" in err and "identify, discover and train fit several" in err


def test_a_named_output_missing_constant_or_copied_from_the_input_is_refused(runs, tmp_path, capsys):
    run = runs[0]
    args = ["--input", "Tendon Disp.", "--model", "lag+linear", "--rate", "25", "--out", str(tmp_path / "f.json")]
    cases = [(_write(tmp_path / "a.csv", run), "Angle x,Pos q", "no column 'Pos q'"),
             (_write(tmp_path / "b.csv", run, **{"Pos x": np.full(run.n, 3.0)}), "Angle x,Pos x",
              "Output 'Pos x' is constant"),
             (_write(tmp_path / "c.csv", run, **{"Pos y": run.u}), "Angle x,Pos y", "is a copy of the input"),
             (_write(tmp_path / "d.csv", run), "Angle x,Angle x", "distinct column names"),
             (_write(tmp_path / "e.csv", run), "Angle x,time", "names the time column")]
    for file, outputs, message in cases:
        assert main(["identify", file, "--output", outputs, *args]) == 2, outputs
        err = capsys.readouterr().err.strip()
        assert message in err and err.count("\n") == 0, err


def _c_controller_tracks(fit_json, tmp_path):
    """``hyst export FIT --track "Pos y" --controller DIR``: the generated closed_loop (C99, its own step as the
    plant) tracks the tip's position; measured 0.0024 mm RMSE on a 23.5 mm sine (the angle's: 0.0098 deg on 56).
    Built at -O0: the loop's numbers are the same at any level, and -O0 builds in a third of -O1's time."""
    import re
    import shutil
    import subprocess

    if shutil.which("gcc") is None or shutil.which("make") is None:
        return  # the controller is built and run where a C toolchain is
    folder = tmp_path / "ctrl"
    assert main(["export", str(fit_json), "--out", str(tmp_path / "pos_y.casadi"), "--track", "Pos y",
                 "--controller", str(folder)]) == 0
    subprocess.run(["make", "-s", "-C", str(folder), "CFLAGS=-O0"], check=True, capture_output=True)
    loop = np.loadtxt(subprocess.run([str(folder / "closed_loop")], capture_output=True, text=True,
                                     check=True).stdout.splitlines())
    main_c = (folder / "main.c").read_text()
    low, high = (float(re.search(rf"{name} = ([-0-9.e]+)", main_c).group(1)) for name in ("y_low", "y_high"))
    t = loop[:, 0] * 0.04
    ref = low + (high - low) * 0.5 * (1 - np.cos(2 * np.pi * 0.2 * t))
    assert abs(high - low) > 10.0  # mm: a position's sine, not an angle's
    assert np.sqrt(np.mean((loop[25:, 2] - ref[25:]) ** 2)) < 0.01 * abs(high - low)
    # the same position tracked with the angle held under 50 deg: the C loop's angle, from its inputs
    from hybrid.export import export_model, load

    whole = export_model(load(str(fit_json)))
    u0 = float(re.search(r"u_prev = ([-0-9.e]+)", main_c).group(1))
    angles = {}
    for name, extra in (("free", []), ("bounded", ["--y-bounds", "Angle x:0,50"])):
        folder = tmp_path / f"ctrl_{name}"
        assert main(["export", str(fit_json), "--out", str(tmp_path / "pos_y.casadi"), "--track", "Pos y",
                     "--horizon", "10", "--controller", str(folder), *extra]) == 0
        subprocess.run(["make", "-s", "-C", str(folder), "CFLAGS=-O0"], check=True, capture_output=True)
        loop = np.loadtxt(subprocess.run([str(folder / "closed_loop")], capture_output=True, text=True,
                                         check=True).stdout.splitlines())
        angles[name] = whole.output(0).simulate(loop[:, 1], x0=whole.x0(u0))
    assert angles["free"].max() > 55 and 49.5 < angles["bounded"].max() <= 50 + 0.05, \
        (angles["free"].max(), angles["bounded"].max())


def _estimator_of_every_output(fit_json, tmp_path, capsys):
    """``hyst export FIT --track "Pos y" --estimator 20 --c-code DIR``: the estimator of every output (one state, an
    offset per output, a mask per output and sample) beside the tracked output's step and in its C library. It gives
    what ``MovingHorizonEstimator`` on the model of every output gives, with the position measured alone at some
    samples and ``Pos x`` never, and its state is the one the tracked output's step takes."""
    import casadi as ca

    from hybrid.control import MovingHorizonEstimator
    from hybrid.export import ExportedModel, export_model, load
    from hybrid.export._codegen import has_compiler, load_compiled

    step, c_dir = tmp_path / "est.casadi", tmp_path / "est_c"
    assert main(["export", str(fit_json), "--out", str(step), "--track", "Pos y", "--estimator", "20",
                 *(["--c-code", str(c_dir)] if has_compiler() else [])]) == 0
    assert "an offset per output, of all 3 outputs" in capsys.readouterr().out
    mhe = ca.Function.load(str(tmp_path / "est.mhe.casadi"))
    whole, tracked = export_model(load(str(fit_json))), ExportedModel.load(step)
    whole.dt = tracked.dt
    own = MovingHorizonEstimator(whole, window=20, compile=False).function
    assert mhe.size_in(3) == (3, 20) and mhe.size_out(2) == (tracked.n_x, 1)
    u = 3.0 + 2.0 * np.sin(np.linspace(0, 3, 20))
    y = whole.simulate(u, x0=whole.x0(1.0)).T + 0.3  # every output 0.3 off its model
    mask = np.vstack([np.arange(20) % 4 == 0, np.zeros(20), np.arange(20) % 2 == 0]).astype(float)
    call = (whole.x0(1.0), np.zeros(3), u[None], y, mask)
    for a, b in zip(mhe(*call), own(*call)):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=0, atol=1e-12)
    offsets = np.asarray(mhe(*call)[1]).ravel()  # each measured output's offset found, the unmeasured one's kept
    np.testing.assert_allclose(offsets, [0.3, 0.0, 0.3], atol=0.01)
    if has_compiler():
        native = load_compiled(c_dir / "libstep.so", "mhe")
        for a, b in zip(native(*call), own(*call)):
            np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-10, atol=1e-9)


def test_fit_writes_one_folder_of_every_output_with_intervals_per_output(runs, tmp_path, capsys):
    """``hyst fit --output A,B,C``: one physics of every output (the arc's length recovered), its card's rows per
    output beside a linear ARX of all three, intervals per output with their joint coverage, and the folder
    predicted, exported per output and refused where it models one output."""
    cath = VirtualCatheter(seed=6, tip=TipArc())
    more = [cath.run(DecayingSinusoid(frequency_hz=f, baseline=b)) for f, b in ((0.4, "zero"), (0.25, "mid"),
                                                                               (0.45, "end"))]
    train = [*runs[:2], *more]  # five runs: two held out of a fit for the intervals
    files = [_write(tmp_path / f"r{i}.csv", r) for i, r in enumerate(train)]
    test = _write(tmp_path / "test.csv", runs[2])
    out = tmp_path / "pose"
    common = ["--input", "Tendon Disp.", "--output", "Angle x,Pos x,Pos y", "--rate", "25"]
    assert main(["fit", *files, "--test", test, *common, "--physics", "backlash+boucwen+linear+arc", "--jobs", "1",
                 "--no-progress", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    card = json.loads((out / "card.json").read_text())
    physics = json.loads((out / "physics.json").read_text())
    assert card["outputs"] == ["Angle x", "Pos x", "Pos y"] and card["residual"] == "none"
    # the true chain: the physics alone beats every residual candidate held out, and the card says so
    choice = card["residual_choice"]
    assert set(choice["validation"]) == {"none", "fnn-hib", "lstm", "fnn-hib alone", "lstm alone"}
    assert min(choice["validation"], key=choice["validation"].get) == "none"
    assert "Residual network: none: the physics alone was lowest held out" in (out / "report.md").read_text()
    assert physics["parameters"]["arc.length"] == pytest.approx(75.0, rel=0.02)
    rows = [r for r in card["rows"] if r["set"] == "test"]
    assert [r["output"] for r in rows] == ["Angle x", "Pos x", "Pos y"]
    for r, noise in zip(rows, (0.15, 0.1, 0.1)):  # each output down to its sensor's noise, far below the ARX's
        assert r["model_rmse"] < 1.3 * noise and r["model_rmse"] < 0.3 * r["arx_rmse"], r
        assert 0.5 < r["coverage"] <= 1.0 and r["joint_coverage"] <= r["coverage"]
    assert "linear ARX of all outputs" in printed and "every output inside at once (joint)" in printed
    # held out of both fits, the physics beats the ARX of all outputs on each (no warning)
    assert all(s["physics"] < 0.3 * s["arx"] for s in card["held_out_rmse"].values()), card["held_out_rmse"]
    report = (out / "report.md").read_text()
    assert "| Pos y | test |" in report and "joint coverage" in report and (out / "loops.png").is_file()
    # predicted with each output's interval; its RMSE and coverage as the card's
    pred = tmp_path / "pred.csv"
    assert main(["predict", str(out), test, "--interval", "0.9", "--out", str(pred)]) == 0
    printed = capsys.readouterr().out
    assert "every output inside at once" in printed and "(the fit's)" in printed
    header = pred.read_text().splitlines()[0].split(",")
    data = np.loadtxt(pred, delimiter=",", skiprows=1)
    table = {name: data[:, i] for i, name in enumerate(header)}
    for r in rows:
        o = r["output"]
        assert np.sqrt(np.mean((table[o] - table[o + "_pred"]) ** 2)) == pytest.approx(r["model_rmse"], rel=1e-9)
        inside = (table[o] >= table[o + "_lo"]) & (table[o] <= table[o + "_hi"])
        assert np.mean(inside) == pytest.approx(r["coverage"], abs=1e-12)
    # the folder's step starts from the window as the card does: its init reads every output, fits the angle's
    from hybrid.export import ExportedModel as Step

    folder_step = Step.load(out / "step.casadi")
    assert folder_step.n_y == 3 and folder_step.meta["warmup"] == 10 and folder_step.meta["init_output"] == 0
    measured = np.column_stack([table[o] for o in card["outputs"]])
    first = np.loadtxt(test, delimiter=",", skiprows=1)
    stepped = folder_step.simulate(first[10:, 1], warmup=(first[:10, 1], first[:10, 2:5]))
    np.testing.assert_allclose(stepped, np.column_stack([table[o + "_pred"] for o in card["outputs"]]), rtol=1e-9,
                               atol=1e-9)
    assert measured.shape == stepped.shape
    # one output's step exported with its own interval beside it
    step = tmp_path / "pos_y.casadi"
    assert main(["export", str(out), "--track", "Pos y", "--out", str(step)]) == 0
    from hybrid.export import ExportedModel, load

    exported, series = ExportedModel.load(step), load(str(out))
    assert exported.n_y == 1 and exported.meta["interval_level"] == 0.9
    np.testing.assert_allclose(exported.simulate(runs[2].u), series.simulate(runs[2].u)[:, 2], rtol=1e-12, atol=1e-9)
    # the tracked position kept inside bounds tightened by its own interval (hyst mpc --tighten); one horizon's
    # samples: the bound is out of the reference's reach, so IPOPT stops at its iteration limit on most steps
    folder = tmp_path / "mpc_tight"
    assert main(["mpc", "--model", str(out), "--track", "Pos y", "--y-bounds", "50,65", "--tighten", "--duration",
                 "1", "--no-figures", "--out", str(folder)]) == 0
    summary = json.loads((folder / "summary.json").read_text())
    assert summary["track"] == "Pos y" and summary["interval"] == "offline"
    # the position tracked while the angle's own interval stays inside the angle's bounds
    folder = tmp_path / "mpc_tight_angle"
    assert main(["mpc", "--model", str(out), "--track", "Pos y", "--y-bounds", "Angle x:20,60", "--tighten",
                 "--duration", "1", "--no-figures", "--out", str(folder)]) == 0
    summary = json.loads((folder / "summary.json").read_text())
    assert summary["track"] == "Pos y" and summary["interval"] == "offline"
    assert main(["mpc", "--model", str(out), "--track", "Pos y", "--y-bounds", "Angle x:20,60", "--tighten",
                 "--measure-every", "5", "--no-figures", "--out", str(tmp_path / "no")]) == 2
    assert "leave --measure-every out" in capsys.readouterr().err
    # the C controller of the position keeps the angle's own band inside the angle's bounds (main.c's h)
    from hybrid.export._load import folder_intervals

    half = folder_intervals(out, "Angle x")[0].quantile()
    assert main(["export", str(out), "--track", "Pos y", "--y-bounds", "Angle x:20,60", "--controller",
                 str(tmp_path / "ctrl_b"), "--out", str(tmp_path / "b.casadi")]) == 0
    assert f"main.c feeds {half:.4g}, that output's interval" in capsys.readouterr().out
    assert f"half_width = {half!r};" in (tmp_path / "ctrl_b" / "main.c").read_text()
    # the angle's step with the window's init; a position's has none, and --warmup with it says so
    assert main(["export", str(out), "--track", "Angle x", "--warmup", "10", "--out", str(tmp_path / "a.casadi")]) == 0
    assert ExportedModel.load(tmp_path / "a.casadi").init is not None
    capsys.readouterr()
    assert main(["export", str(out), "--track", "Pos y", "--warmup", "10", "--out", str(step)]) == 2
    assert "fits the state on 'Angle x''s window" in capsys.readouterr().err
    # a position's step with an init on the position's window alone (a camera that sees no angle)
    assert main(["export", str(out), "--track", "Pos y", "--warmup", "10", "--measure-outputs", "Pos y", "--out",
                 str(step)]) == 0
    pos_y = ExportedModel.load(step)
    assert pos_y.init is not None and pos_y.init.size_in(1) == (1, 10)
    window = first[:10, 4]
    from_window = pos_y.simulate(first[10:, 1], warmup=(first[:10, 1], window))
    assert np.sqrt(np.mean((from_window - first[10:, 4]) ** 2)) < 1.5 * rows[-1]["model_rmse"] + 0.05
    for extra, message in ((["--measure-outputs", "Pos y"], "give --warmup too"),
                           (["--warmup", "10", "--measure-outputs", "Pos z"], "among the model's outputs")):
        assert main(["export", str(out), "--out", str(step), *extra]) == 2
        assert message in capsys.readouterr().err


def test_fit_of_several_outputs_with_a_residual_network_of_every_output(runs, tmp_path, capsys):
    """``hyst fit --output A,B,C --physics lag+linear --residual fnn-hib``: a chain that misses the catheter's
    hysteresis, and one network correcting every output. The folder's model is the hybrid: each test output's
    error below its physics' alone, intervals per output from the hybrid's held-out fit, and ``hyst predict`` and
    the exported step give the card's numbers."""
    from hybrid.export import ExportedModel

    cath = VirtualCatheter(seed=6, tip=TipArc())
    more = [cath.run(DecayingSinusoid(frequency_hz=f, baseline=b)) for f, b in ((0.4, "zero"), (0.25, "mid"),
                                                                               (0.45, "end"))]
    files = [_write(tmp_path / f"r{i}.csv", r) for i, r in enumerate([*runs[:2], *more])]  # two held out
    test = _write(tmp_path / "test.csv", runs[2])
    out = tmp_path / "hybrid"
    assert main(["fit", *files, "--test", test, "--input", "Tendon Disp.", "--output", "Angle x,Pos x,Pos y",
                 "--rate", "25", "--physics", "lag+linear", "--residual", "fnn-hib", "--jobs", "1", "--no-progress",
                 "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    card = json.loads((out / "card.json").read_text())
    assert card["residual"] == "fnn-hib" and card["model"] == "model.pt" and "residual fnn-hib of every output" in printed
    rows = [r for r in card["rows"] if r["set"] == "test"]
    for r in rows:
        assert r["model_rmse"] < 0.8 * r["physics_rmse"], r
        assert 0.5 < r["coverage"] <= 1.0, r
    report = (out / "report.md").read_text()
    assert card["intervals"] == "intervals.json" and "the hybrid's held-out fit (every third run held out" in report
    assert "# Model card: lag+maps, outputs Angle x, Pos x, Pos y (physics + fnn-hib residual)" in report
    pred = tmp_path / "pred.csv"
    assert main(["predict", str(out), test, "--out", str(pred)]) == 0
    header = pred.read_text().splitlines()[0].split(",")
    data = np.loadtxt(pred, delimiter=",", skiprows=1)
    for r in rows:
        o = r["output"]
        err = data[:, header.index(o)] - data[:, header.index(o + "_pred")]
        assert np.sqrt(np.mean(err ** 2)) == pytest.approx(r["model_rmse"], rel=1e-9)
    step = ExportedModel.load(out / "step.casadi")
    first = np.loadtxt(test, delimiter=",", skiprows=1)
    stepped = step.simulate(first[10:, 1], warmup=(first[:10, 1], first[:10, 2:5]))
    np.testing.assert_allclose(stepped, data[:, [header.index(o + "_pred") for o in card["outputs"]]], rtol=1e-6,
                               atol=1e-6)


@pytest.mark.parametrize("column,value,message", [
    ("Pos q", None, "no column 'Pos q'"), ("Pos x", "constant", "is constant"), ("Pos y", "input", "copy of the input")])
def test_fit_refuses_a_named_output_missing_constant_or_copied_from_the_input(runs, tmp_path, capsys, column, value,
                                                                             message):
    replace = {} if value is None else {column: np.full(runs[0].n, 3.0) if value == "constant" else runs[0].u}
    file = _write(tmp_path / "a.csv", runs[0], **replace)
    assert main(["fit", file, "--input", "Tendon Disp.", "--output", f"Angle x,{column}", "--rate", "25",
                 "--no-progress", "--out", str(tmp_path / "m")]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and err.count("\n") == 0, err
    assert not (tmp_path / "m").exists()
