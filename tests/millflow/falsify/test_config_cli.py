"""`millflow falsify`: config validation (named one-line errors, exit 2) and the output folder."""
import json

import pytest

from millflow.cli import main
from millflow.errors import InputError
from millflow.falsify.config import parse_config

BASE = """
replicates = 2
drift_replicates = 0
seed = 1
[truth]
type = "tanks_in_series"
strengths = [1, 3]
[assumed]
mode = "well_mixed"
breakage = "single"
[design]
tau_s = [30, 120, 480]
n_sieves = 8
[noise]
kind = "gaussian"
sigma = 0.01
[fit]
starts = 2
popsize = 6
maxiter = 30
"""


def _cfg(tmp_path, text=BASE, name="c.toml"):
    p = tmp_path / name
    p.write_text(text)
    return p


@pytest.mark.parametrize("edit, match", [
    (("replicates = 2", "replicates = 2\ncolour = 1"), "unknown key colour"),
    (("sigma = 0.01", "sigma = \"0.01\""), r"noise.sigma = '0.01': expected int or float"),
    (("type = \"tanks_in_series\"", "type = \"coagulation\""), "truth.type = 'coagulation'"),
    (("strengths = [1, 3]", "strengths = [1, 2.5]"), "integer >= 1"),
    (("strengths = [1, 3]", "strength = 1\nstrengths = [1, 3]"), "not both"),
    (("tau_s = [30, 120, 480]", "times_s = [30, 120, 480]"), "assumed.mode = 'well_mixed' needs design.tau_s"),
    (("mode = \"well_mixed\"", "mode = \"well_mixed\"\nspeed = 3"), "unknown key assumed.speed"),
    (("n_sieves = 8", "n_sieves = 8.0"), "design.n_sieves = 8.0: expected int"),
    (("kind = \"gaussian\"", "kind = \"pink\""), "noise.kind = 'pink'"),
    (("strengths = [1, 3]", "strengths = [1, 3]\n[truth.params]\nalfa = 1.0"), "truth.params.alfa"),
    (("starts = 2", "starts = 0"), "fit.starts = 0"),
    (("replicates = 2", "replicates = 1"), "replicates = 1"),
    (("kind = \"gaussian\"", "kind = \"gaussian\"\nrho = 0.3"), "noise.rho is only for kind = 'ar1'"),
    (("breakage = \"single\"", "breakage = \"single\"\n[assumed.params.ln_B]\nmin = 0"), "ln_B"),
    (("seed = 1", "seed = -1"), r"seed = -1: expected a whole number 0 \.\. 2\*\*31 - 1"),
    (("seed = 1", "seed = 9223372036854775807"), r"2\*\*31 - 1"),
    (("seed = 1", "seed = 2147483647"), None),
])
def test_config_errors_are_named(edit, match):
    import tomllib
    text = BASE.replace(*edit)
    if match is None:
        assert parse_config(tomllib.loads(text), "c.toml").seed == tomllib.loads(text)["seed"]
        return
    with pytest.raises(InputError, match=match):
        parse_config(tomllib.loads(text), "c.toml")


def test_missing_table():
    import tomllib
    raw = tomllib.loads(BASE)
    del raw["noise"]
    with pytest.raises(InputError, match=r"missing table \[noise\]"):
        parse_config(raw, "c.toml")


def test_cli_bad_config_exit_2_one_line(tmp_path, capsys):
    p = _cfg(tmp_path, BASE.replace("sigma = 0.01", "sigma = -1.0"))
    assert main(["falsify", str(p), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "noise.sigma = -1.0" in err and "Traceback" not in err


def test_cli_writes_the_folder_and_refuses_to_overwrite(tmp_path, capsys):
    p = _cfg(tmp_path)
    out = tmp_path / "res"
    assert main(["falsify", str(p), "--json", "--quiet", "--out", str(out)]) == 0
    js = json.loads(capsys.readouterr().out)
    assert sorted(f.name for f in out.iterdir()) == sorted(js["files"] + [".millflow-manifest.json"])
    assert {"results.nc", "summary.json", "summary.csv", "bias_coverage.png"} <= set(js["files"])
    assert [r["strength"] for r in js["strengths"]] == [1.0, 3.0]
    assert not [f for f in tmp_path.iterdir() if f.name.startswith(".res.")]  # temp folder renamed away
    import xarray as xr
    with xr.open_dataset(out / "results.nc") as ds:
        assert dict(ds.sizes) == {"strength": 2, "parameter": 3, "replicate": 2}
    (out / "notes.txt").write_text("mine")  # a file millflow did not write: the folder is refused
    assert main(["falsify", str(p), "--quiet", "--out", str(out)]) == 2
    assert "did not write (notes.txt)" in capsys.readouterr().err
    assert (out / "notes.txt").read_text() == "mine"
    assert main(["falsify", str(p), "--quiet", "--no-plots", "--out", str(out), "--overwrite"]) == 0
    assert "bias_coverage.png" not in {f.name for f in out.iterdir()}
    assert main(["falsify", str(p), "--quiet", "--out", str(out)]) == 0  # its own folder: replaced


@pytest.mark.parametrize("name", ["tanks.toml", "slowing.toml", "aggregation.toml", "population.toml"])
def test_the_documented_configs_parse(name):
    from pathlib import Path

    from millflow.falsify.config import load_config
    path = Path(__file__).resolve().parents[3] / "docs" / "examples" / "falsify" / name
    cfg = load_config(path)
    assert cfg.replicates == 50 and len(cfg.strengths) >= 5


def test_assumed_kinetics_fits_the_non_linear_model():
    """[assumed] kinetics: the documented worked study 5 parses into a six-parameter
    slowing-down fit, and the truth's s is the reference of the fitted s_slow."""
    from pathlib import Path

    from millflow.falsify.config import load_config
    path = Path(__file__).resolve().parents[3] / "docs" / "examples" / "falsify" / "slowing_fitted.toml"
    cfg = load_config(path)
    assert cfg.assumed.kinetics == ("slowing_down",) and "s_slow" in cfg.params
    assert cfg.truth(1.0).kinetic_truth == {"s_slow": 1.0}


def test_assumed_kinetics_params_need_units(tmp_path):
    from millflow.errors import InputError
    from millflow.falsify.config import parse_config
    raw = {"truth": {"type": "aggregation", "strength": 0.01}, "design": {"times_s": [30, 60, 120]},
           "noise": {"sigma": 0.01},
           "assumed": {"mode": "batch", "kinetics": "aggregation", "kinetics_params": {"x_ref": 22}}}
    with pytest.raises(InputError, match="x_ref: units of measure missing"):
        parse_config(raw)


def _parsed(text):
    import tomllib
    return parse_config(tomllib.loads(text), "c.toml")


@pytest.mark.parametrize("edit", [
    ("tau_s = [30, 120, 480]", "tau_min = [0.5, 2, 8]"),
    ("tau_s = [30, 120, 480]", "tau_h = [0.008333333333333333, 0.03333333333333333, 0.13333333333333333]"),
])
def test_design_times_in_any_unit_are_the_same_design(edit):
    """tau_min and tau_h read through millflow.inputs: the same residence times in s as tau_s
    (rtol 1e-12: the unit factors are exact, the decimal hours are rounded to 16 digits)."""
    import numpy as np
    ref = dict(_parsed(BASE).design.process)["tau_s"]
    got = dict(_parsed(BASE.replace(*edit)).design.process)["tau_s"]
    np.testing.assert_allclose(got, ref, rtol=1e-12)
    assert ref == (30.0, 120.0, 480.0)


def test_top_size_in_any_length_unit():
    """top_size_mm = 2 and top_size_um = 2000 give the same sieve stack (the top sieve 2 mm)."""
    import numpy as np
    a = _parsed(BASE.replace("n_sieves = 8", "n_sieves = 8\ntop_size_mm = 2")).design
    b = _parsed(BASE.replace("n_sieves = 8", "n_sieves = 8\ntop_size_um = 2000")).design
    np.testing.assert_allclose(a.sieves_m, b.sieves_m, rtol=1e-12)
    assert abs(a.sieves_m[0] - 2e-3) < 1e-15


def test_batch_times_in_minutes():
    text = BASE.replace("tau_s = [30, 120, 480]", "times_min = [0.5, 2, 8]").replace(
        "mode = \"well_mixed\"", "mode = \"batch\"").replace("type = \"tanks_in_series\"", "type = \"slowing_down\"")
    assert _parsed(text).design.times_s == (30.0, 120.0, 480.0)


@pytest.mark.parametrize("edit, match", [
    (("tau_s = [30, 120, 480]", "tau = [30, 120, 480]"), r"c\.toml: design\.tau: units of measure missing; write "
                                                           r"tau_<unit> with one of _s, _min, _h"),
    (("tau_s = [30, 120, 480]", "tau_fortnight = [1, 2]"), r"design\.tau_fortnight: unknown unit 'fortnight' for "
                                                            r"tau \(time\)"),
    (("n_sieves = 8", "n_sieves = 8\ntop_size = 4"), r"design\.top_size: units of measure missing"),
    (("n_sieves = 8", "n_sieves = 8\ntop_size_cm = 4"), r"design\.top_size_cm: unknown unit 'cm'"),
    (("n_sieves = 8", "n_sieves = 8\ntop_size_mm = -4"), r"design\.top_size_mm = -4: expected a value > 0"),
    (("tau_s = [30, 120, 480]", "tau_s = [30, 120, 480]\ntau_min = [1]"), r"tau_s, tau_min give 'tau' twice"),
    (("tau_s = [30, 120, 480]", "tau_s = []"), r"design\.tau_s = \[\]: expected a non-empty list"),
    (("tau_s = [30, 120, 480]", "tau_s = 30"), r"design\.tau_s = 30: expected a non-empty list"),
    (("tau_s = [30, 120, 480]", "tau_s = [30, 0]"), r"design\.tau_s = \[30, 0\]: expected a value > 0"),
    (("tau_s = [30, 120, 480]", "times_s = [30]\ntau_s = [30]"), r"exactly one of times_<unit>"),
    (("type = \"tanks_in_series\"", "type = \"tanks_in_series\"\nx_ref = 22"), r"truth\.x_ref: units of measure"),
    (("type = \"tanks_in_series\"", "type = \"tanks_in_series\"\nfines_mm = 0.2"),
     r"truth\.fines_mm is only for truth\.type = 'population'"),
])
def test_unit_keys_are_read_through_inputs(edit, match):
    """A dimensional key without its unit, with an unknown unit, or twice: one line naming it."""
    with pytest.raises(InputError, match=match) as err:
        _parsed(BASE.replace(*edit))
    assert "\n" not in str(err.value)


def test_population_fines_in_mm_is_the_fines_size_in_m():
    import tomllib
    raw = tomllib.loads(BASE)
    raw["truth"] = {"type": "population", "strengths": [0, 1], "fines_mm": 0.25}
    raw["assumed"]["mode"] = "well_mixed"
    cfg = parse_config(raw, "c.toml")
    assert abs(cfg.truth(1.0).fines_m - 2.5e-4) < 1e-18
