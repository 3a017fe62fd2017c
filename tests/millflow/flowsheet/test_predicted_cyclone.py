"""A hydrocyclone cluster predicted from its geometry inside a wet circuit (issue 14 §1).

The cyclone is torn on its solids, water and (Plitt) corrected recovery C; at the converged
point its reported cut size, pressure and water split must be the model's at the flows the
circuit sends it (tear tolerance 1e-13: agreement to 1e-9 leaves room for the loop gain).
"""
import re

import numpy as np
import pytest

from millflow import cyclones as cy
from millflow.errors import InputError, SolverError
from millflow.flowsheet import loads, solve
from tests.paths import FLOWSHEETS

FILE = FLOWSHEETS / "closed_circuit_wet_cyclones.toml"


def text(**edits):
    s = re.sub(r"(?m)^ratio = .*$", "ratio = 1.189207115", FILE.read_text())  # coarse grid: fast tests
    for old, new in edits.values():
        s = s.replace(old, new)
    return s


@pytest.mark.parametrize("model", ["plitt", "nageswararao"])
def test_prediction_is_the_models_at_the_converged_flows(model):
    sol = solve(loads(text(m=('model = "plitt"', f'model = "{model}"'))))
    rep = sol.units["cyclones"]
    S, W = sol.flow("cyclone_feed").sum(), sol.water_flow("cyclone_feed")
    feed = cy.CycloneFeed.from_flows(W, S, 2800.0)
    geom = sol.flowsheet.units["cyclones"].geometry
    q = cy.slurry_flow(W, S, 2800.0) / sol.flowsheet.units["cyclones"].cyclones
    if model == "plitt":
        assert rep["d50c_m"] == pytest.approx(cy.plitt_d50c(geom, feed, q), rel=1e-9)
        assert rep["pressure_Pa"] == pytest.approx(cy.plitt_pressure(geom, feed, q), rel=1e-9)
    else:
        pred = cy.nageswararao_cyclone(geom, feed, flow_m3_s=q)
        assert rep["d50c_m"] == pytest.approx(pred.d50c_m, rel=1e-9)
        assert rep["water_split"] == pytest.approx(pred.water_split, rel=1e-9)
    # the water balance uses the model's water split
    assert sol.water_flow("underflow") / W == pytest.approx(rep["water_split"], rel=1e-9)
    assert max(r["mass_balance_error"] for r in sol.units.values()) < 1e-12
    assert max(r["water_balance_error"] for r in sol.units.values()) < 1e-12


def test_plitt_water_split_closes_the_volume_balance():
    """R_v = (1 - phi) R_f + phi R_s (Plitt's volume split and the solids recovery the circuit sees)."""
    sol = solve(loads(text()))
    rep = sol.units["cyclones"]
    Rs = sol.flow("underflow").sum() / sol.flow("cyclone_feed").sum()
    phi = rep["solids_volume_fraction"]
    Rv = rep["volume_split"] / (1 + rep["volume_split"])
    assert (1 - phi) * rep["water_split"] + phi * Rs == pytest.approx(Rv, rel=1e-9)


def test_more_dilution_water_lowers_the_cut_size():
    lean = solve(loads(text(w=("add_water_tph = 250", "add_water_tph = 600")))).units["cyclones"]["d50c_m"]
    dense = solve(loads(text())).units["cyclones"]["d50c_m"]
    assert lean < dense  # Plitt: d50c grows as exp(0.063 phi)


@pytest.mark.parametrize("edit, error, match", [
    (("apex_mm = 150", "apex_mm = 300"), InputError, "apex"),
    (('model = "plitt"', 'model = "krebs"'), InputError, "unknown hydrocyclone model"),
    (("cyclones = 2 ", "cyclones = 2.5 "), InputError, "whole number"),
    (("diameter_mm = 660", "diameter = 660"), InputError, "units of measure missing"),
    (("[slurry]\nsolids_density_t_m3 = 2.8", ""), InputError, "solids density"),
])
def test_bad_cyclone_input_is_named(edit, error, match):
    with pytest.raises(error, match=match):
        loads(text(e=edit))


def test_dry_feed_to_a_predicted_cyclone_is_a_failed_solve():
    s = text(a=("solids_content_pct = 95     # or water_tph = ...", ""), b=("add_water_tph = 50", ""),
             c=("add_water_tph = 250", ""), d=("slurry_volume_m3 = 40", "tau_min = 4"))
    with pytest.raises(SolverError, match="units.cyclones: .*needs both"):
        solve(loads(s))


def test_example_file_runs_on_its_own_grid():
    from millflow.flowsheet import load

    sol = solve(load(FILE))
    assert np.isfinite(sol.flows).all() and sol.solver["tear"]["converged"]
