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
