"""``millflow scaleup``: the worked example's inputs end to end, and bad input (exit 2,
one line naming the key and value)."""
import json
import os
import sys

import numpy as np
import pytest

from millflow.cli import main
from tests import paths

REPO = str(paths.REPO)
EXAMPLE = os.path.join(REPO, "examples", "scaleup")


@pytest.fixture(scope="module")
def fit_json(tmp_path_factory):
    """A local eq. 9 fit of the example's synthetic lab data (noise-free here: the test
    is about the pipeline, not about the estimate), written as 'millflow fit --json' does."""
    sys.path.insert(0, EXAMPLE)
    try:
        import make_lab_data as mk
    finally:
        sys.path.pop(0)
    from millflow.fitting.data import psd_data_from_frames
    from millflow.fitting.estimate import fit
    from millflow.fitting.models import ForwardModel, ModelSpec, default_parameters
    from millflow.grid import SizeGrid

    psd, proc = mk.tables(np.random.default_rng(5))
    spec = ModelSpec(mode="batch", breakage="normalized", rate_process=("speed",))
    grid = SizeGrid.between(4e-3, 4e-3 / 2 ** 7.5, 2 ** 0.25)
    model = ForwardModel(spec, psd_data_from_frames(psd, proc, strict=False), grid)
    params = default_parameters(spec, {n: {"value": v} for n, v in mk.TRUTH.items()})
    res = fit(model, params, global_search=False, starts=1, grid_check=False)
    d = tmp_path_factory.mktemp("fit")
    p = d / "fit.json"
    p.write_text(json.dumps(res.to_dict(), default=float))
    return p


def _plant(tmp_path, edit=None):
    text = open(os.path.join(EXAMPLE, "plant.toml")).read()
    if edit:
        old, new = edit
        assert old in text
        text = text.replace(old, new)
    p = tmp_path / "plant.toml"
    p.write_text(text)
    return p


def test_example_end_to_end_json_and_files(tmp_path, fit_json, capsys):
    plant = _plant(tmp_path)
    rc = main(["scaleup", str(fit_json), "--to", str(plant), "--target-p80-um", "150", "--json", "--draws", "200",
               "--out", str(tmp_path / "out")])
    assert rc == 0
    s = json.loads(capsys.readouterr().out)
    for f in ("scaleup.nc", "scaleup_psd.csv", "scaleup.json", "scaleup.png"):
        assert (tmp_path / "out" / f).is_file()
    b = s["bands"]["p80_um"]
    assert b["delta"]["lo"] < s["p80_um"] < b["delta"]["hi"]
    assert b["mc"]["lo"] < s["p80_um"] < b["mc"]["hi"]
    assert s["throughput_residual_rel"] < 1e-10  # Brent on ln(mill flow) to 1e-13
    assert s["mass_balance"] < 1e-12
    assert s["power_gross_kW"] == pytest.approx(s["power_net_kW"] / 0.93, rel=1e-12)
    lo, hi = s["bands"]["throughput_tph"]["delta"].values()
    assert lo < s["throughput_tph"] < hi
    assert s["specific_energy_at_target_kWh_per_t"] == pytest.approx(s["power_net_kW"] / s["throughput_tph"], rel=1e-12)


@pytest.mark.parametrize("edit,match", [
    (("critical_speed_fraction = 0.75", "critical_speed_fraction = 1.05"), "mill.critical_speed_fraction = 1.05"),
    (("critical_speed_fraction = 0.75", "critical_speed_fraction = 0.0"), "mill.critical_speed_fraction = 0.0"),
    (("ball_filling = 0.35\ncritical_speed_fraction = 0.75", "ball_filling = 0.7\ncritical_speed_fraction = 0.75"),
     "mill.ball_filling = 0.7"),
    (("diameter_m = 4.0", "diameter = 4.0"), "mill.diameter: units of measure missing; write diameter_<unit>"),
    (("diameter_m = 4.0", "diameter_furlong = 4.0"), "mill.diameter_furlong: unknown unit 'furlong'"),
    (("d50c_um = 200", "d50c = 200"), "classifier.d50c: units of measure missing; write d50c_<unit>"),
    (("d50c_um = 200", "d50c_um = 200\nd50c_mm = 0.2"), "d50c_um, d50c_mm give 'd50c' twice"),
    (("feed_tph = 100", "feed = 100"), "feed.feed: units of measure missing; write feed_<unit>"),
    (("top_um = 4000", "top = 4000"), "grid.top: units of measure missing"),
    (("ball_size_mm = 50", "ball_size_mm = 50\nball_sise_mm = 50"), "mill.ball_sise_mm: unknown key"),
    (("speed = 0.80", "sped = 0.80"), r"lab.process: missing process values \['speed'\]"),
    (("top_um = 4000", "top_um = 2000"), "feed:.*give a \\[grid\\] with top_um"),
])
def test_bad_plant_input_exit_2(tmp_path, fit_json, capsys, edit, match):
    plant = _plant(tmp_path, edit)
    assert main(["scaleup", str(fit_json), "--to", str(plant), "--band-method", "delta"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    import re
    assert re.search(match, err), err


def test_fit_without_covariance_or_other_family_exit_2(tmp_path, fit_json, capsys):
    plant = _plant(tmp_path)
    d = json.loads(fit_json.read_text())
    d.pop("covariance")
    (tmp_path / "old.json").write_text(json.dumps(d))
    assert main(["scaleup", str(tmp_path / "old.json"), "--to", str(plant)]) == 2
    assert "has no 'covariance'" in capsys.readouterr().err
    d = json.loads(fit_json.read_text())
    d["model_spec"]["classification"] = "screen"
    (tmp_path / "screen.json").write_text(json.dumps(d))
    assert main(["scaleup", str(tmp_path / "screen.json"), "--to", str(plant)]) == 2
    assert "classification = 'screen'" in capsys.readouterr().err
    d = json.loads(fit_json.read_text())
    d["model_spec"]["mode"] = "well_mixed"
    (tmp_path / "wm.json").write_text(json.dumps(d))
    assert main(["scaleup", str(tmp_path / "wm.json"), "--to", str(plant)]) == 2
    assert "without tau_column" in capsys.readouterr().err


def test_unreachable_target_exit_2(tmp_path, fit_json, capsys):
    plant = _plant(tmp_path)
    assert main(["scaleup", str(fit_json), "--to", str(plant), "--target-p80-um", "12", "--band-method", "delta",
                 "--out", str(tmp_path / "o")]) == 2
    assert "not reachable" in capsys.readouterr().err


def test_rtd_fit_json_gives_the_transport_shape(tmp_path, fit_json, capsys):
    (tmp_path / "tracer.json").write_text(json.dumps({"model": "tis", "params": {"tau": {"value": 240.0, "se": 5.0},
                                                                                  "n": {"value": 2.5, "se": 0.2}}}))
    plant = _plant(tmp_path, ('model = "tanks_in_series"\nn = 3', 'rtd_fit = "tracer.json"'))
    assert main(["scaleup", str(fit_json), "--to", str(plant), "--band-method", "delta", "--json",
                 "--out", str(tmp_path / "o")]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["transport"] == "tanks_in_series" and s["transport_params"] == {"n": 2.5}
    assert "shape only" in s["transport_source"]


def test_fit_json_carries_eq9_covariance(fit_json):
    d = json.loads(fit_json.read_text())
    C = np.array(d["covariance"]["matrix"])
    names = d["covariance"]["names"]
    se = np.array([d["params"][n]["se"] for n in names])
    np.testing.assert_allclose(np.sqrt(np.diag(C)), se, rtol=1e-12)  # same eq. 9 numbers, JSON round trip
    assert d["model_spec"]["param_names"][0] == "ln_A0" and d["model_spec"]["process_ref"]["speed"] > 0


def test_austin_scaling_from_the_plant_file(tmp_path, fit_json, capsys):
    from millflow.scaleup import austin_factors
    plant = _plant(tmp_path, ('scaling = "herbst_fuerstenau"', 'scaling = "austin"'))
    assert main(["scaleup", str(fit_json), "--to", str(plant), "--band-method", "delta", "--json",
                 "--out", str(tmp_path / "o")]) == 0
    s = json.loads(capsys.readouterr().out)
    lab = dict(diameter_m=0.2, ball_size_mm=25, ball_filling=0.35, critical_speed_fraction=0.80, powder_filling=1.0)
    pl = dict(diameter_m=4.0, ball_size_mm=50, ball_filling=0.35, critical_speed_fraction=0.75, powder_filling=1.0)
    assert s["A_factor"] == pytest.approx(austin_factors(lab, pl)["A"], rel=1e-14)


def test_transport_shape_from_a_stated_aspect_ratio_correlation(fit_json, tmp_path, capsys):
    # Pe = 2.5 (L/D)^1.0 on the example's 4.0 m x 6.0 m mill: L/D = 1.5, so Pe = 3.75 exactly
    corr = ('model = "axial_dispersion"\n[transport.from_aspect_ratio]\nparameter = "pe"\ncoefficient = 2.5\n'
            'exponent = 1.0\nsource = "stated for this test"')
    plant = _plant(tmp_path, ('model = "tanks_in_series"\nn = 3', corr))
    assert main(["scaleup", str(fit_json), "--to", str(plant), "--band-method", "delta", "--json",
                 "--out", str(tmp_path / "o")]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["transport"] == "axial_dispersion"
    assert s["transport_params"]["pe"] == pytest.approx(3.75, rel=1e-15)  # one product and one power of 1.5
    assert "L/D = 1.5" in s["transport_source"]


def test_aspect_ratio_correlation_needs_its_source(fit_json, tmp_path, capsys):
    corr = ('model = "axial_dispersion"\n[transport.from_aspect_ratio]\n'
            'parameter = "pe"\ncoefficient = 2.5\nexponent = 1.0')
    plant = _plant(tmp_path, ('model = "tanks_in_series"\nn = 3', corr))
    assert main(["scaleup", str(fit_json), "--to", str(plant), "--out", str(tmp_path / "o")]) == 2
    assert "source" in capsys.readouterr().err


@pytest.mark.parametrize("edit", [
    ("diameter_m = 4.0", "diameter_mm = 4000"),
    ("diameter_m = 4.0", f"diameter_ft = {4.0 / 0.3048!r}"),
    ("ball_size_mm = 50", f"ball_size_in = {50 / 25.4!r}"),
    ("d50c_um = 200", "d50c_mm = 0.2"),
    ("feed_tph = 100", f"feed_kg_s = {100 / 3.6!r}"),
    ("top_um = 4000", "top_mm = 4.0"),
    ("solids_density_kg_m3 = 2700\npower_model", "solids_density_t_m3 = 2.7\npower_model"),
    ("solids_density_kg_m3 = 2700\npower_model", "solid_density_kg_m3 = 2700\npower_model"),  # earlier spelling
])
def test_plant_file_reads_any_known_unit(tmp_path, fit_json, edit):
    """Every dimensional key of the plant file is read through millflow.inputs: another unit of
    the same dimension gives the same plant (SI inside), so the same prediction to rounding
    (the unit conversions are exact to a few eps; the roots converge to 1e-13)."""
    from millflow.scaleup.fitted import load_fit
    from millflow.scaleup.plantfile import load_plant

    fit = load_fit(fit_json)
    base, _ = load_plant(_plant(tmp_path), fit)
    (tmp_path / "b").mkdir()
    other, _ = load_plant(_plant(tmp_path / "b", edit), fit)
    assert other.circuit.mill.diameter_m == pytest.approx(base.circuit.mill.diameter_m, rel=1e-14)
    assert other.circuit.mill.ball_size_mm == pytest.approx(base.circuit.mill.ball_size_mm, rel=1e-14)
    assert other.circuit.classifier["d50c"] == pytest.approx(base.circuit.classifier["d50c"], rel=1e-14)
    assert other.feed_tph == pytest.approx(base.feed_tph, rel=1e-14)
    a = base.throughput_for_p80(fit.theta, 150e-6)["feed_tph"]
    b = other.throughput_for_p80(fit.theta, 150e-6)["feed_tph"]
    assert b == pytest.approx(a, rel=1e-10)


@pytest.mark.parametrize("content, match", [
    ({"model": "tanks_in_series", "params": {"n": 3, "tau": 100}}, "params.n = 3: expected a table with 'value'"),
    ({"model": "tanks_in_series", "params": [3, 100]}, "not a 'millflow fit-rtd --json' result"),
    ([1, 2], "not a 'millflow fit-rtd --json' result"),
    ({"model": "tanks_in_series", "params": {"n": {"value": "3"}}}, "params.n.value = '3': expected a finite number"),
    ({"model": "tanks_in_series", "params": {"tau": {"value": 3.0}}}, r"params \['n'\] missing"),
    ({"model": "nonsense", "params": {}}, "model"),
])
def test_malformed_rtd_fit_is_one_line_exit_2(tmp_path, fit_json, capsys, content, match):
    (tmp_path / "tracer.json").write_text(json.dumps(content))
    plant = _plant(tmp_path, ('model = "tanks_in_series"\nn = 3', 'rtd_fit = "tracer.json"'))
    assert main(["scaleup", str(fit_json), "--to", str(plant), "--band-method", "delta"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err and "internal error" not in err
    import re
    assert re.search(match, err), err


def test_negative_variance_is_refused_naming_the_parameter(tmp_path, fit_json, capsys):
    d = json.loads(fit_json.read_text())
    names = d["covariance"]["names"]
    d["covariance"]["matrix"][1][1] = -abs(d["covariance"]["matrix"][1][1])
    (tmp_path / "bad.json").write_text(json.dumps(d))
    assert main(["scaleup", str(tmp_path / "bad.json"), "--to", str(_plant(tmp_path))]) == 2
    err = capsys.readouterr().err
    assert f"the variance of {names[1]} is -" in err and err.count("\n") == 1


def test_plant_energy_outside_the_lab_range_is_said(tmp_path, fit_json, capsys):
    """The lab tests cover P_lab t / H_lab over their grinding times; a plant specific energy
    outside that range is an extrapolation of the breakage model in energy: said in the
    summary (and as a warning), with the range."""
    plant = _plant(tmp_path)
    assert main(["scaleup", str(fit_json), "--to", str(plant), "--target-p80-um", "50", "--json",
                 "--band-method", "delta", "--out", str(tmp_path / "o"), "--no-plots"]) == 0
    s = json.loads(capsys.readouterr().out)
    lo, hi = s["lab_specific_energy_kWh_t"]
    assert 0 < lo < hi < s["specific_energy_at_target_kWh_per_t"]
    assert any("at the target P80 50 um is above the lab tests' range" in n for n in s["extrapolation"])
