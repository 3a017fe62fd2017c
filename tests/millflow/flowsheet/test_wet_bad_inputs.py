"""Bad input to the wet-circuit keys (issue 14 bad input, issue 10 §4): one line, exit 2
for bad input and 1 for a failed solve, never a traceback."""
import pytest

from millflow.cli import main
from tests.paths import FLOWSHEETS

BASE = (FLOWSHEETS / "closed_circuit_wet_cyclones.toml").read_text()

CASES = [
    (("cyclones = 2 ", 'cyclones = "six" '), 2, "expected a number"),
    (("cyclones = 2 ", "cyclones = 0 "), 2, "whole number >= 1"),
    (("apex_mm = 150", "apex_mm = 300"), 2, "apex"),
    (("apex_mm = 150", "apex_mm = 1e300"), 2, "apex"),
    (("add_water_tph = 250", "add_water_tph = -5"), 2, ">= 0"),
    (("add_water_tph = 250", "add_water_tph = [1, 2]"), 2, "expected a number"),
    (("add_water_tph = 250", "add_water_tph = 1e300"), 1, "overflow"),
    (("solids_content_pct = 95", "solids_content_pct = 120"), 2, "(0, 100]"),
    (("solids_density_t_m3 = 2.8", "solids_density_t_m3 = 0.5"), 2, "denser than the liquid"),
    (("solids_density_t_m3 = 2.8", "solids_density_t_m3 = 1e300"), 2, "check the unit"),
    (('model = "plitt"', 'model = "krebs"'), 2, "unknown hydrocyclone model"),
    (('model = "plitt"', 'model = "plitt"\nF1 = 0'), 2, "F1"),
    (("cone_angle_deg = 20", "cone_angle_deg = 200"), 2, "cone angle"),
    (("solids_tph = 250", "solids_tph = 1e9"), 1, "units.cyclones"),
    (('transport = {model = "tanks_in_series", n = 3}', 'transport = {rtd_fit = "missing.json"}'), 2, "not found"),
    (('transport = {model = "tanks_in_series", n = 3}', 'transport = {model = "series", parts = [1, 2]}'), 2,
     "parts"),
    (('psd = {form = "rosin_rammler", x63_um = 800, n = 1.0}', 'psd = {form = "csv", file = "missing.csv"}'), 2,
     "not found"),
    (('material = "ore"', 'material = "ore"\nclassification = {curve = "screen", d50_um = 3000, where = [0]}'), 2,
     "cell numbers"),
]


@pytest.mark.parametrize("edit, code, match", CASES, ids=[c[0][1][:30] for c in CASES])
def test_bad_wet_input_is_one_line(tmp_path, capsys, edit, code, match):
    assert edit[0] in BASE
    path = tmp_path / "bad.toml"
    path.write_text(BASE.replace(*edit, 1))
    rc = main(["run", str(path), "--out", str(tmp_path / "out"), "--no-plots", "--quiet", "--no-grid-check"])
    err = capsys.readouterr().err.strip()
    assert rc == code, err
    assert "Traceback" not in err and "internal error" not in err
    assert len(err.splitlines()) == 1 and match in err
    assert not (tmp_path / "out").exists()  # nothing written for a failed run
