"""millflow.mill.transport: the one place a transport is dispatched. Its kinds and
predicates for every name, alias and rtd model; the cells, shape and fit parameters the
callers read; the builders; and the non-linear solve, equal to rounding to that of the solver it
chooses."""
import numpy as np
import pytest

import rtd
from millflow.breakage import b_from_B, normalized_B, power_law_rates
from millflow.grid import SizeGrid
from millflow.mill import nonlinear as nl
from millflow.mill import transport as tr
from millflow.nonlinear import Aggregation, constant_kernel, kinetics
from rtd import names

KIND = {"perfect_mixing": "perfect_mixing", "plug_flow": "plug", "tanks_in_series": "tanks",
        "recirculating_cells": "network", "axial_dispersion": "axial", "axial_dispersion_open": "axial_open"}


def test_every_name_and_alias_has_its_kind():
    assert set(tr.TRANSPORT_NAMES) == set(KIND) == set(names.TRANSPORTS)
    for name, kind in KIND.items():
        assert tr.transport_kind(name) == kind
    for alias, name in names.ALIASES.items():
        assert tr.transport_kind(alias) == KIND[name]
    assert tr.transport_kind("well_mixed") == "perfect_mixing" and tr.canonical_transport("cstr") == "perfect_mixing"
    assert tr.transport_kind("series") == "series"
    with pytest.raises(ValueError, match="unknown"):
        tr.transport_kind("no_such_transport")


def test_models_have_the_kind_of_their_names():
    for name, entry in names.TRANSPORTS.items():
        params = {k: 4.0 for k in entry.required}
        assert tr.transport_kind(names.build(name, 600.0, **params)) == KIND[name]
    assert tr.transport_kind(rtd.TanksInSeries(600.0, 2.5)) == "tanks"  # also without whole cells
    assert tr.transport_kind(rtd.Series(rtd.PlugFlow(1.0), rtd.PerfectMixing(2.0))) == "series"
    assert tr.transport_kind(rtd.RecirculatingCells(600.0, 3).network()) == "network"


def test_predicates():
    assert [n for n in KIND if tr.is_cells(n)] == ["perfect_mixing", "tanks_in_series", "recirculating_cells"]
    assert [n for n in KIND if tr.is_axial(n)] == ["plug_flow", "axial_dispersion", "axial_dispersion_open"]
    assert [n for n in KIND if tr.is_axial(n, open_vessel=False)] == ["plug_flow", "axial_dispersion"]
    assert [n for n in KIND if tr.is_axial_dispersion(n)] == ["axial_dispersion", "axial_dispersion_open"]
    assert [n for n in KIND if tr.is_axial_dispersion(n, open_vessel=True)] == ["axial_dispersion_open"]
    assert [n for n in KIND if tr.is_axial_dispersion(n, open_vessel=False)] == ["axial_dispersion"]
    assert [n for n in KIND if tr.is_tanks(n)] == ["tanks_in_series"]
    assert [n for n in KIND if tr.is_network(n)] == ["recirculating_cells"]
    assert [n for n in KIND if tr.is_plug(n)] == ["plug_flow"]
    # no transport (a fit mode without one), a flowsheet's series: none of them
    for t in (None, "series"):
        assert not any(f(t) for f in (tr.is_cells, tr.is_tanks, tr.is_network, tr.is_plug, tr.is_axial,
                                      tr.is_axial_dispersion))
    assert tr.equal_cells(None, {}) is None and tr.cell_count(None, {}) is None and tr.fit_parameters(None) == ()


def test_cells_and_parameters():
    assert tr.equal_cells("perfect_mixing", {}) == 1
    assert tr.equal_cells("tanks_in_series", {"n": 4.0}) == 4
    assert tr.equal_cells("tanks_in_series", (("n", 3),)) == 3  # a fit's sorted pairs
    for params in ({"n": 2.5}, {"n": 0}, {"n": 3, "r": 1.0}):
        assert tr.equal_cells("tanks_in_series", params) is None
    assert tr.equal_cells("recirculating_cells", {"n": 3}) is None
    assert tr.cell_count("perfect_mixing", {}) == 1 and tr.cell_count("recirculating_cells", {"n": 5}) == 5
    assert tr.cell_count("plug_flow", {}) is None
    assert {n: tr.shape_parameter(n) for n in KIND} == {
        "perfect_mixing": None, "plug_flow": None, "tanks_in_series": "n", "recirculating_cells": "n",
        "axial_dispersion": "pe", "axial_dispersion_open": "pe"}
    assert tr.fit_parameters("axial_dispersion") == ("tau", "pe")
    assert tr.fit_parameters("cells") == ("tau", "r") and tr.fit_parameters("plug_flow") == ("tau",)


def test_old_names_are_the_table():
    from millflow.fitting.spec import TRANSPORT_FIT
    from millflow.flowsheet import units

    assert TRANSPORT_FIT is tr.TRANSPORT_FIT
    assert units.TRANSPORTS is tr.BUILDERS and units.build_transport is tr.build_transport


def test_builders():
    m = tr.build_transport("axial_dispersion_open", 600.0, {"pe": 8.0, "discharge": "flux"})
    assert isinstance(m, rtd.AxialDispersion) and m.bc == "open" and m.pe == 8.0
    s = tr.build_transport("series", 600.0, {"parts": [("plug_flow", {}, 0.25), ("tanks_in_series", {"n": 2}, 0.75)]})
    assert isinstance(s, rtd.Series) and s.mean == pytest.approx(600.0)


def _kin(n=12):
    grid = SizeGrid.geometric(1e-2, 2 ** 0.5, n)
    S = power_law_rates(grid.x, 0.05, 1.0, grid.x[0])
    S[-1] = 0.0
    b = b_from_B(normalized_B(grid.x, 0.4, 0.8, 3.0))
    feed = np.zeros(n)
    feed[:3] = [0.2, 0.5, 0.3]
    return kinetics(S, b, aggregation=Aggregation(constant_kernel(0.02), grid.x[-1]), grid=grid), feed


@pytest.mark.parametrize("name", ["well_mixed", "perfect_mixing", "tanks_in_series", "plug_flow",
                                  "axial_dispersion"])
def test_the_nonlinear_solve_is_the_solver_it_chooses(name):
    kin, feed = _kin()
    tau, kw = 600.0, dict(rtol=1e-8, atol=1e-12, tol=1e-8, m_cells=64)
    n = 3 if name == "tanks_in_series" else 1
    got = tr.solve_nonlinear(kin, feed, tau, name, n_tanks=n, pe=8.0, **kw)
    want = {"well_mixed": lambda: nl.well_mixed(kin, feed, tau),
            "perfect_mixing": lambda: nl.well_mixed(kin, feed, tau),
            "tanks_in_series": lambda: nl.tanks_in_series(kin, feed, tau, 3),
            "plug_flow": lambda: nl.plug_flow(kin, feed, tau, rtol=1e-8, atol=1e-12, holdup=False),
            "axial_dispersion": lambda: nl.axial_dispersion(kin, feed, tau, 8.0, m_cells=64)}[name]()
    # the same solver and arithmetic: equal to rounding (1e-14 of the unit feed)
    np.testing.assert_allclose(got.product, want.product, rtol=0, atol=1e-14)


def test_the_nonlinear_solve_of_a_network_or_another_model():
    kin, feed = _kin()
    net = rtd.RecirculatingCells(600.0, 3, r=1.0)
    got = tr.solve_nonlinear(kin, feed, 600.0, "recirculating_cells", network=net, rtol=1e-8, atol=1e-12, tol=1e-8)
    np.testing.assert_allclose(got.product, nl.cells(kin, feed, net).product, rtol=0, atol=1e-14)
    model = rtd.AxialDispersion(600.0, 8.0, bc="open")
    got = tr.solve_nonlinear(kin, feed, 600.0, "axial_dispersion_open", model=model, rtol=1e-8, atol=1e-12,
                             tol=1e-8, m_cells=64)
    want = nl.solve_transport(kin, feed, model, tol=1e-8, holdup=False, m_cells=64)
    np.testing.assert_allclose(got.product, want.product, rtol=0, atol=1e-14)
