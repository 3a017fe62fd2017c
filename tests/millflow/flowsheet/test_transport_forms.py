"""Any rtd model in a flowsheet mill (issue 14 §2): series compositions, and classification
placed where the library allows it (discharge, every cell, listed cells, along the axis)."""
import numpy as np
import pytest
import rtd

from millflow.breakage import NormalizedBreakage, PowerLawRate
from millflow.breakage.averaged import breakage_on_grid, curve_on_grid
from millflow.classifiers import mill_discharge_rates, screen_efficiency
from millflow.errors import InputError
from millflow.flowsheet import loads, solve
from millflow.mill import transfer_matrix

BASE = """
[grid]
top_um = 4000
bottom_um = 40
n = 14
[units.f]
type = "feed"
solids_tph = 36
psd = {form = "ggs", xmax_um = 4000, m = 0.8}
[units.mill]
type = "mill"
tau_min = 5
rate = {form = "power", A_per_min = 0.6, alpha = 1.1}
breakage = {form = "normalized", phi = 0.5, gamma = 0.8, beta = 3.0}
TRANSPORT
CLASSIFICATION
[units.p]
type = "product"
[streams]
s1 = {from = "f", to = "mill"}
s2 = {from = "mill", to = "p"}
"""


def run(transport, classification=""):
    sol = solve(loads(BASE.replace("TRANSPORT", transport).replace("CLASSIFICATION", classification)))
    fs = sol.flowsheet
    feed = fs.units["f"].source()["out"]
    # the continuous forms put on the grid as the flowsheet does (class averages)
    S, b, _ = breakage_on_grid(PowerLawRate(0.01, 1.1, 1e-3), NormalizedBreakage(0.5, 0.8, 3.0), fs.grid)
    return sol, feed, S, b, fs.grid


def _screen(grid):
    return mill_discharge_rates(curve_on_grid(lambda x: screen_efficiency(x, 1.5e-3, 4.0), grid))


def test_series_composition_is_rtd_series_of_its_parts():
    sol, feed, S, b, _ = run('transport = {model = "series", parts = [{model = "plug_flow", tau_fraction = 0.25}, '
                             '{model = "tanks_in_series", n = 2, tau_fraction = 0.75}]}')
    ref = transfer_matrix(S, b, rtd.Series(rtd.PlugFlow(75.0), rtd.TanksInSeries(225.0, 2))) @ feed
    np.testing.assert_allclose(sol.flow("s2"), ref, rtol=1e-12, atol=1e-14 * feed.sum())


@pytest.mark.parametrize("where", ['"cells"', "[1, 3]", '"discharge"'])
def test_classification_where_in_cells(where):
    sol, feed, S, b, grid = run('transport = {model = "tanks_in_series", n = 3}',
                                f'classification = {{curve = "screen", d50_um = 1500, m = 4, where = {where}}}')
    d = _screen(grid)
    w = eval(where.replace('"', "'"))  # noqa: S307 - a literal from the parametrisation
    ref = transfer_matrix(S, b, rtd.TanksInSeries(300.0, 3), d, where=tuple(w) if isinstance(w, list) else w) @ feed
    np.testing.assert_allclose(sol.flow("s2"), ref, rtol=1e-12, atol=1e-14 * feed.sum())
    assert max(r["mass_balance_error"] for r in sol.units.values()) < 1e-12


def test_series_fractions_must_sum_to_one():
    with pytest.raises(InputError, match="sum to 0.9"):
        run('transport = {model = "series", parts = [{model = "plug_flow", tau_fraction = 0.2}, '
            '{model = "perfect_mixing", tau_fraction = 0.7}]}')


def test_where_the_transport_does_not_allow_is_named():
    with pytest.raises(InputError, match="where"):
        run('transport = {model = "plug_flow"}', 'classification = {curve = "screen", d50_um = 1500, where = "cells"}')


@pytest.mark.parametrize("discharge", [None, "flux"])
def test_open_vessel_classified_along_the_axis(discharge):
    """The open-vessel axial-dispersion mill carries classification along the axis (issue 14 §2):
    the flowsheet runs the library's open-vessel finite volumes, and the unit closes its mass
    balance to rounding (1e-12: the sampled discharge keeps sum v c = feed exactly when the
    Peclet numbers are equal, the flux discharge by construction)."""
    key = "" if discharge is None else f', discharge = "{discharge}"'
    sol, feed, S, b, grid = run(f'transport = {{model = "axial_dispersion_open", pe = 4{key}}}',
                                'classification = {curve = "screen", d50_um = 1500, m = 4, where = "axis"}')
    d = _screen(grid)
    ref = transfer_matrix(S, b, rtd.AxialDispersion(300.0, 4.0, bc="open"), d, discharge=discharge) @ feed
    np.testing.assert_allclose(sol.flow("s2"), ref, rtol=1e-12, atol=1e-14 * feed.sum())
    assert max(r["mass_balance_error"] for r in sol.units.values()) < 1e-12
    assert "discharge" in sol.units["mill"]["method"] or discharge is None


def test_open_vessel_discharge_is_checked():
    with pytest.raises(InputError, match=r"transport.discharge = 'exit'.*'sampled', 'flux'"):
        run('transport = {model = "axial_dispersion_open", pe = 4, discharge = "exit"}')
    with pytest.raises(InputError, match="discharge"):
        run('transport = {model = "axial_dispersion", pe = 4, discharge = "flux"}')
    with pytest.raises(InputError, match="a flux discharge needs the open vessel as the whole mill"):
        run('transport = {model = "series", parts = [{model = "plug_flow", tau_fraction = 0.5}, '
            '{model = "axial_dispersion_open", pe = 4, discharge = "flux", tau_fraction = 0.5}]}')
