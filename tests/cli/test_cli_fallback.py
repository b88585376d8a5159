"""``hyst fit --physics SPEC`` that cannot be fitted falls back, and says so: a warning line on stderr
naming the spec asked for, why it failed and the spec used instead, and the same on the model card."""

import pytest

from hybrid.cli._main import main

from _synthetic import NOISE_DEG, make_runs, truth_model, write_csv


@pytest.fixture(scope="module")
def csvs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("fallback")
    runs = make_runs(truth_model("backlash+linear"), NOISE_DEG, seed=3)
    return [write_csv(folder / f"run{i}.csv", r) for i, r in enumerate(runs[:2])]


def _fit(csvs, spec, out, capsys):
    assert main(["fit", *csvs, "--physics", spec, "--residual", "none", "--no-progress", "--out", str(out)]) == 0
    captured = capsys.readouterr()
    warnings = [line for line in captured.err.splitlines() if line.startswith("warning: --physics")]
    return captured.out, warnings, (out / "report.md").read_text()


def test_a_spec_without_an_output_map_falls_back_with_a_warning(csvs, tmp_path, capsys):
    out, warnings, card = _fit(csvs, "lag", tmp_path / "m", capsys)
    assert "physics 'backlash+linear'" in out  # the fallback stays
    assert len(warnings) == 1, warnings
    line = warnings[0]
    assert line.startswith("warning: --physics 'lag' could not be fitted (") and \
        line.endswith("; used 'backlash+linear' instead"), line
    assert "no output map" in line and "'lag+linear'" in line, line  # why, and how to fix it
    assert f"**Warning: {line.removeprefix('warning: ')}.**" in card


def test_a_spec_whose_solver_fails_names_both_specs(csvs, tmp_path, capsys, monkeypatch):
    import identification._identify as ident
    from identification import IdentificationError

    real = ident.identify

    def failing(model, *args, **kwargs):  # IPOPT stopping as it did on a real loop
        if model.spec == "gpi+linear":
            raise IdentificationError("IPOPT did not converge for 'gpi+linear': status Error_In_Step_Computation "
                                      "after 14 iterations (best of 1 start(s)). Try more starts.")
        return real(model, *args, **kwargs)

    monkeypatch.setattr(ident, "identify", failing)
    _, warnings, card = _fit(csvs, "gpi+linear", tmp_path / "m", capsys)
    assert warnings == ["warning: --physics 'gpi+linear' could not be fitted (IPOPT did not converge for "
                        "'gpi+linear': status Error_In_Step_Computation after 14 iterations (best of 1 start(s))); "
                        "used 'backlash+linear' instead"]
    assert "**Warning: --physics 'gpi+linear' could not be fitted" in card


def test_a_spec_that_fits_prints_no_warning(csvs, tmp_path, capsys):
    out, warnings, card = _fit(csvs, "backlash+linear", tmp_path / "m", capsys)
    assert "physics 'backlash+linear'" in out and warnings == [] and "**Warning" not in card
