"""Flowsheet files: unit conversion at the edge and errors that name the key or stream."""

import numpy as np
import pytest

from millflow.errors import GridError, InputError
from millflow.flowsheet import loads, solve
from tests.closed_circuit import per_time_text

CLOSED = per_time_text()  # the example in its per-time form (rates in 1/s, tau_min = 3.5)


def edit(old, new, text=CLOSED):
    assert old in text, old
    return text.replace(old, new, 1)


def test_units_are_converted():
    a = solve(loads(CLOSED))
    b = solve(loads(edit("tau_min = 3.5", "tau_s = 210").replace("solids_tph = 250", f"solids_kg_s = {250 / 3.6!r}")
                    .replace("d50c_um = 140", "d50c_mm = 0.14")))
    np.testing.assert_allclose(a.flows, b.flows, rtol=1e-12, atol=1e-15)
    fs = loads(CLOSED)
    assert fs.units["ball_mill"].tau == 210.0
    assert fs.units["fresh_feed"].solids == pytest.approx(250 / 3.6)
    assert fs.units["cyclones"].params["d50c"] == pytest.approx(140e-6)
    assert fs.units["ball_mill"].power == 3.8e6


@pytest.mark.parametrize("old,new,match", [
    ('type = "hydrocyclone"', 'type = "cyclone"', r"units\.cyclones\.type = 'cyclone': unknown unit type; valid: .*hydrocyclone"),
    ("tau_min = 3.5", "tau = 3.5", r"units\.ball_mill\.tau: units of measure missing.*_min"),
    ("d50c_um = 140", "d50c = 140", r"units\.cyclones\.d50c: units of measure missing.*_um"),
    ("solids_tph = 250", "solids_tpd = 250", r"units\.fresh_feed\.solids_tpd: unknown unit 'tpd'.*_tph"),
    ("d50c_um = 140", "d50c_um = -140", r"units\.cyclones\.d50c_um = -140"),
    ("tau_min = 3.5", "tau_min = -3.5", r"units\.ball_mill\.tau_min = -3\.5"),
    ("alpha = 3.0", "", r"units\.cyclones: missing parameter 'alpha'"),
    ("tau_min = 3.5", "", r"units\.ball_mill: missing parameter tau_<unit>"),
    ("d50c_um = 140", "d50c_um = 140\nsharpness = 2", r"units\.cyclones\.sharpness: unknown key; valid keys"),
    ("bypass = 0.30", "bypass = -0.3", r"units\.cyclones\.bypass = -0\.3"),
    ('model = "tanks_in_series"', 'model = "tanks"', r"units\.ball_mill\.transport\.model = 'tanks'.*tanks_in_series"),
    ('to = "overflow_product"}', 'to = "final_product"}', r"streams\.overflow\.to: unknown unit 'final_product'"),
    ('from = "cyclones.underflow"', 'from = "cyclones.spigot"', r"streams\.underflow\.from: unit 'cyclones' has no outlet 'spigot'"),
    ('from = "cyclones.underflow"', 'from = "cyclones.overflow"', r"streams\.(overflow|underflow): outlet cyclones\.overflow is doubly connected"),
    ('underflow = {from = "cyclones.underflow", to = "chute"}\n', "", r"units\.cyclones: outlet cyclones\.underflow is dangling"),
    ('mill_feed = {from = "chute", to = "ball_mill"}\n', "", r"units\.chute: outlet chute\.out is dangling"),
    ('from = "cyclones.underflow", to = "chute"', 'from = "cyclones.underflow", to = "fresh_feed"', r"units\.fresh_feed: a feed takes no inlet"),
    ("top_um = 8000", "top_um = 5000", r"units\.fresh_feed\.psd: the size grid does not cover the feed"),
    ("passing_pct = [100,", "passing = [1.0,", r"psd\.passing: units of measure missing"),
    ('material = "ore"', 'material = "clinker"', r"units\.ball_mill\.material = 'clinker': unknown material; defined: ore"),
    ("alpha = 1.0, x0_um", "alpha = 1.0, x0 = 1000, x0_um", r"materials\.ore\.rate\.x0: units of measure missing"),
])
def test_bad_files_name_the_key(old, new, match):
    with pytest.raises((InputError, GridError), match=match):
        loads(edit(old, new), source="bad.toml")


def test_not_toml_and_missing_file(tmp_path):
    with pytest.raises(InputError, match="not valid TOML"):
        loads("x = {a = 1,\n b = 2}")
    from millflow.flowsheet import load

    with pytest.raises(InputError, match="not found"):
        load(tmp_path / "nope.toml")


def test_tear_method_registry():
    with pytest.raises(InputError, match="valid names: newton, substitution, wegstein"):
        solve(loads(CLOSED), method="broyden")
