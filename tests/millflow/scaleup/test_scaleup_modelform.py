"""The scale-up band's model-form contributions (millflow.scaleup.modelform), the power-model
family shared by lab and plant, and the progress of ``millflow scaleup``."""
import dataclasses
import json
import math

import numpy as np
import pytest

from millflow.cli import main
from millflow.scaleup import Circuit, ScaleUp
from millflow.scaleup.modelform import contributions, quantity
from millflow.scaleup.plantfile import _power_models
from tests.millflow.scaleup.test_scaleup import CYCLONE, FEED, LAB, PLANT, make_fit
from tests.millflow.scaleup.test_scaleup_cli import _plant, fit_json  # noqa: F401 (a fixture)

SU = ScaleUp(make_fit(), LAB, {}, Circuit(PLANT, "tis", {"n": 3}, CYCLONE), FEED, 100.0)


def _with_family(su, model):
    return dataclasses.replace(su, lab=dataclasses.replace(su.lab, power_model=model),
                               circuit=dataclasses.replace(su.circuit,
                                                           mill=dataclasses.replace(su.circuit.mill,
                                                                                    power_model=model)))


def test_each_contribution_is_the_prediction_under_its_alternative():
    band = {"lo": 140.0, "hi": 163.0}
    out = contributions(SU, None, band)
    q0 = quantity(SU)
    assert out["value"] == q0 and out["quantity"] == "p80_um"
    rows = out["contributions"]
    # power model: each family for both mills, recomputed independently
    for m in ("bond", "austin", "hogg_fuerstenau"):
        assert rows["power_model"]["alternatives"][m] == pytest.approx(quantity(_with_family(SU, m)), rel=1e-12)
    assert rows["power_model"]["alternatives"]["austin"] == q0  # the base family (default austin for both)
    other = quantity(dataclasses.replace(SU, scaling="austin"))
    assert rows["scaling_rule"]["half_width"] == pytest.approx(abs(other - q0), rel=1e-12)
    assert rows["parameters"]["half_width"] == pytest.approx(max(163.0 - q0, q0 - 140.0), rel=1e-14)
    # the total is formed as stated: the log factors added, q0 x/÷ exp(L)
    L = sum(r["log_factor"] for r in rows.values())
    assert out["total"]["lo"] == pytest.approx(q0 * math.exp(-L), rel=1e-14)
    assert out["total"]["hi"] == pytest.approx(q0 * math.exp(L), rel=1e-14)
    assert rows["scaling_rule"]["log_factor"] == pytest.approx(abs(math.log(other / q0)), rel=1e-14)
    # every contribution lies inside the total band
    for r in rows.values():
        for v in r["alternatives"].values():
            assert out["total"]["lo"] <= v <= out["total"]["hi"]


def test_herbst_fuerstenau_with_one_family_is_power_model_sensitive_only_through_p_over_h():
    # HF: S_plant = S_lab (P/H)_plant / (P/H)_lab; with one family the ratio of two powers of
    # the same model: the A factor is the same for bond and austin (Austin's is Bond's per mill)
    fa = _with_family(SU, "austin").factors()["A"]
    fb = _with_family(SU, "bond").factors()["A"]
    assert fa == pytest.approx(fb, rel=0.02)  # 0.4 % below D = 3.3 m, Bond's ball-size term above


def test_grid_contribution_is_twice_the_change_on_halving():
    fine = dataclasses.replace(SU, x=np.r_[SU.x], feed=SU.feed)  # same grid: no change
    out = contributions(SU, None, None, refined=fine)
    assert out["contributions"]["size_grid"]["half_width"] == 0.0 and "parameters" not in out["contributions"]


def test_power_models_are_one_family_unless_both_are_stated():
    d = {"lab": {}, "mill": {"power_model": "bond"}}
    assert _power_models(d) == {"lab": "bond", "plant": "bond", "mixed": False} and d["lab"]["power_model"] == "bond"
    assert _power_models({"lab": {"power_model": "hogg_fuerstenau"}, "mill": {"power_model": "austin"}})["mixed"]
    assert not _power_models({"lab": {"power_kW": 1.0}, "mill": {}})["mixed"]  # a measured power is no family


def test_cli_prints_each_contribution_the_total_and_the_draws(tmp_path, fit_json, capsys):  # noqa: F811
    plant = _plant(tmp_path)
    assert main(["scaleup", str(fit_json), "--to", str(plant), "--target-p80-um", "150", "--draws", "50",
                 "--out", str(tmp_path / "o")]) == 0
    out = capsys.readouterr().out
    for name in ("parameters", "power_model", "scaling_rule", "size_grid", "total"):
        assert f"  {name}" in out
    assert "Monte Carlo: 50 draws" in out and "mixed power models" not in out
    s = json.loads((tmp_path / "o" / "scaleup.json").read_text())
    assert s["power_models"] == {"lab": "austin", "plant": "austin", "mixed": False}
    assert (tmp_path / "o" / "scaleup_contributions.csv").is_file()
    assert (tmp_path / "o" / "scaleup_contributions.png").is_file()
    mixed = _plant(tmp_path, ("# power_model: the plant's", 'power_model = "hogg_fuerstenau"\n#'))
    assert main(["scaleup", str(fit_json), "--to", str(mixed), "--draws", "20", "--method", "mc", "--out",
                 str(tmp_path / "m")]) == 0
    assert "note: mixed power models: lab hogg_fuerstenau, plant austin" in capsys.readouterr().out
