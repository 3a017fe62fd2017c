"""``millflow fit`` on a survey: a config with a [survey] table, or the survey file itself."""
import json
import shutil

import numpy as np
import pytest

from millflow.cli import main
from millflow.flowsheet import load, solve
from millflow.survey import read_survey, reconcile
from millflow.survey.fit import fit_circuit
from tests import paths

EXAMPLE = paths.REPO / "examples" / "survey"
NAMES = ["units.cyclones.d50c_um", "units.cyclones.water_to_coarse"]
BOUNDS = {NAMES[0]: (60.0, 300.0), NAMES[1]: (0.05, 0.6)}


def _config(tmp_path, extra=""):
    p = tmp_path / "fit.toml"
    p.write_text(f'[survey]\nfile = "{(EXAMPLE / "survey.toml").as_posix()}"\n'
                 '[params."units.cyclones.d50c_um"]\nmin = 60\nmax = 300\n'
                 '[params."units.cyclones.water_to_coarse"]\nmin = 0.05\nmax = 0.6\n'
                 '[optimizer]\nstarts = 1\n' + extra, encoding="utf-8")
    return p


def test_fit_config_with_a_survey_table_fits_the_circuit(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["fit", str(_config(tmp_path)), "--out", str(out), "--json", "--no-plots"]) == 0
    s = json.loads(capsys.readouterr().out)
    f = s["fit"]
    # the same fit as the library's, on the same reconciled survey
    direct = fit_circuit(reconcile(read_survey(EXAMPLE / "survey.toml")), NAMES, BOUNDS, starts=1,
                         leave_one_out=False)
    for n in NAMES:
        assert f["parameters"][n]["value"] == pytest.approx(direct.values[n], rel=1e-6), n
        lo, hi = f["parameters"][n]["ci95"]
        assert lo < f["parameters"][n]["value"] < hi
    assert f["dof"] == f["n_data"] - 2
    # leave-one-stream-out: every measured non-feed stream predicted, with a finite error
    loo = f["leave_one_stream_out"]
    assert set(loo) == {"mill_feed", "mill_discharge", "cyclone_feed", "underflow", "overflow"}
    assert all(np.isfinite(v["rms_normalised_error"]) and v["rms_normalised_error"] > 0 for v in loo.values())
    names = {p.name for p in out.iterdir()}
    assert {"fitted_circuit.toml", "fit.json", "results.nc", "summary.json", "measurements.csv"} <= names
    # millflow run reproduces the fitted circuit: the written TOML solves to the model's flows
    again = solve(load(out / "fitted_circuit.toml"))
    model = direct.model.solve([f["parameters"][n]["value"] for n in NAMES])
    np.testing.assert_allclose(again.flows, model.flows, rtol=1e-6, atol=1e-9 * model.flows.max())
    assert main(["run", str(out / "fitted_circuit.toml"), "--out", str(tmp_path / "run"), "--quiet"]) == 0


def test_the_survey_file_itself_is_a_fit_config(tmp_path, capsys):
    shutil.copy(EXAMPLE / "circuit.toml", tmp_path / "circuit.toml")
    text = (EXAMPLE / "survey.toml").read_text(encoding="utf-8")
    text = text[:text.index("[fit]")] + ('[fit]\nstarts = 1\nleave_one_out = false\n[fit.parameters]\n'
                                          '"units.cyclones.d50c_um" = {min = 60, max = 300}\n')
    (tmp_path / "survey.toml").write_text(text, encoding="utf-8")
    assert main(["fit", str(tmp_path / "survey.toml"), "--out", str(tmp_path / "a"), "--no-plots"]) == 0
    shown = capsys.readouterr().out
    assert "circuit fit: SSR" in shown and "units.cyclones.d50c_um" in shown
    # the balance route gives the same estimate
    assert main(["balance", str(tmp_path / "survey.toml"), "--out", str(tmp_path / "b"), "--no-plots"]) == 0
    a = json.loads((tmp_path / "a" / "fit.json").read_text())
    b = json.loads((tmp_path / "b" / "fit.json").read_text())
    assert a["parameters"]["units.cyclones.d50c_um"]["value"] == pytest.approx(
        b["parameters"]["units.cyclones.d50c_um"]["value"], rel=1e-9)


@pytest.mark.parametrize("extra, message", [
    ('[params."units.cyclones.nonsense"]\nmin = 1\nmax = 2\n', "nonsense"),
    ('[validation]\nhold_out = "each"\n', "hold_out"),
    ('[params."units.cyclones.bypass"]\nmin = 0.5\nmax = 0.1\n', "not below max"),
])
def test_bad_survey_fit_configs_give_one_line(tmp_path, capsys, extra, message):
    assert main(["fit", str(_config(tmp_path, extra)), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1
    assert not (tmp_path / "out").exists()


def test_survey_table_without_a_file(tmp_path, capsys):
    p = tmp_path / "fit.toml"
    p.write_text('[survey]\nfile = "missing.toml"\n', encoding="utf-8")
    assert main(["fit", str(p)]) == 2
    assert "missing.toml" in capsys.readouterr().err
