"""Continuous mill (issue 4): cross-checks between transport paths, classification,
extreme cases and bad definitions.

Tolerances: the exact paths (triangular, block and spectral solves) agree to a few
hundred ulps of O(1) mass fractions, hence 1e-12; the discretised axial path is
checked against its own Richardson error estimate and observed order.
"""
import numpy as np
import pytest
import rtd
from hypothesis import given, settings, strategies as st

from millflow.batch import batch_grind
from millflow.breakage import b_from_B, normalized_B, power_law_rates
from millflow.errors import AccuracyWarning, InputError, SolverError
from millflow.grid import SizeGrid
from millflow.mill import Mill, steady_mill, transfer_matrix
from millflow.mill.axial import solve_axial, solve_axial_grid
from millflow.mill.segregated import segregated


def kernel(n=30, a=1.0 / 60, ratio=2**0.25, plateau=None):
    grid = SizeGrid.geometric(1e-2, ratio, n)
    S = power_law_rates(grid.x, a, 1.0, 1e-3)
    if plateau == "four":
        S[5:9] = S[5]
    elif plateau == "all":
        S[:] = a
    elif plateau == "pairs":
        S[10:12] = S[10]
        S[20:22] = S[20] * (1 + 1e-9)
    S[-1] = 0.0
    b = b_from_B(normalized_B(grid.x, 0.4, 0.8, 3.0))
    feed = np.zeros(n)
    feed[:3] = [0.2, 0.5, 0.3]
    return grid, S, b, feed


TAU = 600.0


# --------------------------------------------------------------- analytic checks
def test_perfect_mixing_is_eq3_solved_directly():
    grid, S, b, f = kernel()
    for d in (None, np.where(grid.x > 2e-3, 0.3, 1.5)):
        dd = np.ones(S.size) if d is None else d
        # eq. 3: p_i = f_i - tau (S_i/d_i) p_i + tau sum_j b_ij (S_j/d_j) p_j
        A = np.eye(S.size) + TAU * np.diag(S / dd) - TAU * b * (S / dd)[np.newaxis, :]
        direct = np.linalg.solve(A, f)
        ds = steady_mill(S, b, f, rtd.PerfectMixing(TAU), d)
        assert ds.attrs["method"] == "well_mixed"
        np.testing.assert_allclose(ds["product"], direct, rtol=0, atol=1e-14)
        np.testing.assert_allclose(ds["holdup"], TAU * direct / dd, rtol=1e-13)


def test_one_class_into_sink():
    ds = steady_mill([2.0, 0.0], [[0, 0], [1, 0]], [1.0, 0.0], rtd.PerfectMixing(3.0))
    np.testing.assert_allclose(ds["product"], [1 / 7, 6 / 7], rtol=1e-15)


def test_plug_flow_equals_batch_grind_at_tau():
    grid, S, b, f = kernel(plateau="four")
    ref = batch_grind(S, b, f, TAU)[0]
    ds = steady_mill(S, b, f, rtd.PlugFlow(TAU), positions=[0.0, 0.5, 1.0])
    assert ds.attrs["method"] == "plug_flow"
    np.testing.assert_allclose(ds["product"], ref, rtol=0, atol=1e-14)
    np.testing.assert_allclose(ds["profile_fraction"][1], batch_grind(S, b, f, TAU / 2)[0], atol=1e-14)
    P = transfer_matrix(S, b, rtd.PlugFlow(TAU))
    np.testing.assert_allclose(P @ f, ref, atol=1e-14)
    assert abs(float(ds["holdup"].sum()) - TAU) < 1e-9 * TAU


@pytest.mark.parametrize("n", [1, 3, 10])
@pytest.mark.parametrize("plateau", [None, "four", "all", "pairs"])
def test_segregated_equals_cell_network_for_tanks_in_series(n, plateau):
    _, S, b, f = kernel(plateau=plateau)
    for tau in (6.0, TAU, 6e4):
        model = rtd.TanksInSeries(tau, n)
        cells = steady_mill(S, b, f, model)
        seg = steady_mill(S, b, f, model, method="segregated")
        assert cells.attrs["method"] == "cells" and seg.attrs["method"] == "segregated"
        np.testing.assert_allclose(seg["product"], cells["product"], rtol=0, atol=1e-12)
        np.testing.assert_allclose(seg["holdup"], cells["holdup"], rtol=0, atol=1e-12 * tau)


@pytest.mark.parametrize("plateau", ["four", "all", "pairs"])
def test_contour_clusters_against_independent_paths(plateau):
    """Coinciding rates go through contour_funm; check them against paths that never
    divide by rate differences: a chained cell network and the axial finite volumes."""
    _, S, b, f = kernel(n=24, plateau=plateau)
    series = rtd.Series(rtd.PerfectMixing(200.0), rtd.PerfectMixing(400.0), rtd.PerfectMixing(50.0))
    seg = steady_mill(S, b, f, series, method="segregated")
    assert steady_mill(S, b, f, series).attrs["method"] == "composed"
    net = rtd.compose.chain_networks(series.parts)
    np.testing.assert_allclose(seg["product"], steady_mill(S, b, f, net)["product"], atol=1e-12)
    np.testing.assert_allclose(steady_mill(S, b, f, series)["product"], seg["product"], atol=1e-12)
    model = rtd.AxialDispersion(TAU, 3.0)
    ax = solve_axial(S, b, f, TAU, 3.0, tol=1e-9)
    diff = float(np.abs(steady_mill(S, b, f, model)["product"] - ax.product).max())
    assert diff < 1e-9 and diff <= ax.error_estimate


def _slow_rates(alpha, n=60):
    grid = SizeGrid.geometric(1e-2, 2**0.25, n)
    S = power_law_rates(grid.x, 1.0 / 60, alpha, 1e-3)
    S[-1] = 0.0
    b = b_from_B(normalized_B(grid.x, 0.4, 0.8, 3.0))
    return S, b, np.eye(n)[0]


def test_one_wide_cluster_is_exact():
    """alpha = 0.05: consecutive rates 0.9 % apart, one cluster of 59 classes."""
    S, b, f = _slow_rates(0.05)
    model = rtd.TanksInSeries(TAU, 3)
    seg = steady_mill(S, b, f, model, method="segregated")
    assert max(eval(seg.attrs["cluster_sizes"])) > 50
    np.testing.assert_allclose(seg["product"], steady_mill(S, b, f, model)["product"], atol=1e-13)


def test_cancelling_eigenbasis_falls_back_or_says_so():
    """alpha = 0.1, N = 100: rates 1.7 % apart over a factor 5.6 (too wide for one Taylor series,
    too close for the eigenbasis). Axial dispersion falls back to finite volumes; a
    forced segregated solve reports its large error estimate."""
    S, b, f = _slow_rates(0.1, n=100)
    ds = steady_mill(S, b, f, rtd.AxialDispersion(TAU, 5.0))
    assert ds.attrs["method"] == "axial_fv" and "fallback" in ds.attrs
    # the open vessel falls back to its own finite volumes (on the whole line), and agrees
    # with the time quadrature of its density to the FV error estimate
    open_vessel = rtd.AxialDispersion(TAU, 5.0, bc="open")
    ds_open = steady_mill(S, b, f, open_vessel)
    assert ds_open.attrs["method"] == "axial_fv" and "fallback" in ds_open.attrs
    quad = steady_mill(S, b, f, open_vessel, method="quadrature")
    assert float(np.abs(ds_open["product"] - quad["product"]).max()) <= 3 * ds_open.attrs["error_estimate"] + 1e-12
    with pytest.raises(SolverError, match="method='quadrature'"):  # the error says what to do
        steady_mill(S, b, f, rtd.TanksInSeries(TAU, 2.5))
    with pytest.warns(AccuracyWarning, match="quadrature"):
        assert "advice" in steady_mill(S, b, f, rtd.TanksInSeries(TAU, 2.5), on_inaccuracy="warn").attrs
    with pytest.raises(SolverError, match=r"segregated: .*above the tolerance 1e-08"):
        steady_mill(S, b, f, rtd.TanksInSeries(TAU, 3), method="segregated")  # never silently
    with pytest.warns(AccuracyWarning, match="error estimate"):
        forced = steady_mill(S, b, f, rtd.TanksInSeries(TAU, 3), method="segregated", on_inaccuracy="warn")
    exact = steady_mill(S, b, f, rtd.TanksInSeries(TAU, 3))
    assert float(np.abs(forced["product"] - exact["product"]).max()) <= forced.attrs["error_estimate"]


def test_parallel_and_series_composition_equal_segregated():
    _, S, b, f = kernel()
    for model in (rtd.Parallel(rtd.TanksInSeries(TAU, 3), rtd.AxialDispersion(400.0, 8.0), weights=(0.3, 0.7)),
                  rtd.Series(rtd.TanksInSeries(300.0, 2.5), rtd.AxialDispersion(200.0, 4.0, bc="open"))):
        comp = steady_mill(S, b, f, model)
        seg = steady_mill(S, b, f, model, method="segregated")
        assert comp.attrs["method"] == "composed"
        np.testing.assert_allclose(comp["product"], seg["product"], atol=1e-13)
        np.testing.assert_allclose(comp["holdup"], seg["holdup"], atol=1e-11)
        assert abs(float(comp["holdup"].sum()) - model.mean) < 1e-9 * model.mean


def test_open_vessel_segregated_equals_time_quadrature():
    _, S, b, f = kernel()
    model = rtd.AxialDispersion(TAU, 5.0, bc="open")
    seg = steady_mill(S, b, f, model)
    quad = steady_mill(S, b, f, model, method="quadrature")
    np.testing.assert_allclose(seg["product"], quad["product"], atol=1e-12)
    np.testing.assert_allclose(seg["holdup"], quad["holdup"], atol=1e-9 * TAU)
    assert abs(float(seg["holdup"].sum()) - model.mean) < 1e-9 * model.mean


def test_recirculating_cells_segregated_and_reduction():
    _, S, b, f = kernel()
    model = rtd.RecirculatingCells(TAU, 4, r=0.7, bypass=0.1)
    cells = steady_mill(S, b, f, model)
    seg = steady_mill(S, b, f, model, method="segregated")
    np.testing.assert_allclose(seg["product"], cells["product"], atol=1e-12)
    a = steady_mill(S, b, f, rtd.RecirculatingCells(TAU, 4))["product"]
    c = steady_mill(S, b, f, rtd.TanksInSeries(TAU, 4))["product"]
    np.testing.assert_allclose(a, c, atol=1e-14)


def test_classification_at_every_cell_is_rescaled_rates():
    """d* on every flow scales every transport time of class i by 1/d_i*: the product is
    segregated flow with rates S/d* (q_i = d_i* m_i satisfies the unclassified balance)."""
    grid, S, b, f = kernel()
    d = np.where(grid.x > 2e-3, 0.2, 1.3)
    for model in (rtd.TanksInSeries(TAU, 3), rtd.RecirculatingCells(TAU, 3, r=1.0)):
        cells = steady_mill(S, b, f, model, d, where="cells")
        seg = segregated(S / d, b, f, model, holdup=False)[0]
        np.testing.assert_allclose(cells["product"], seg, atol=1e-12)


def test_axial_converges_to_wehner_wilhelm_with_order_two():
    _, S, b, f = kernel(n=20)
    model = rtd.AxialDispersion(TAU, 10.0)
    ref = segregated(S, b, f, model)[0]
    errors = np.array([np.abs(solve_axial_grid(S, b, f, TAU, 10.0, m)[2] - ref).max() for m in (32, 64, 128, 256)])
    orders = np.log2(errors[:-1] / errors[1:])
    assert np.all(np.abs(orders - 2.0) < 0.05), orders
    ds = steady_mill(S, b, f, model, method="axial_fv", tol=1e-9)
    assert abs(ds.attrs["order"] - 2) < 0.05
    err = float(np.abs(ds["product"] - ref).max())
    assert err < 1e-9 and err <= ds.attrs["error_estimate"]


def test_axial_velocity_and_dispersion_scaled_equals_rescaled_rates():
    grid, S, b, f = kernel(n=20)
    d = np.where(grid.x > 2e-3, 0.4, 1.0)
    ds = steady_mill(S, b, f, rtd.AxialDispersion(TAU, 5.0), d, dispersion=d, tol=1e-10)
    ref = segregated(S / d, b, f, rtd.AxialDispersion(TAU, 5.0), holdup=False)[0]
    assert float(np.abs(ds["product"] - ref).max()) < 1e-9


# --------------------------------------------------------------- classification
def test_classification_at_declared_cells():
    from millflow.mill.cells import _solve_block, _solve_chain

    grid, S, b, f = kernel()
    d = np.where(grid.x > 1e-3, 0.3, 1.2)
    model = rtd.TanksInSeries(TAU, 3)
    at = {w: steady_mill(S, b, f, model, d, where=w)["product"].values
          for w in ("discharge", "cells", (3,), (1, 2, 3), (2,))}
    np.testing.assert_allclose(at[(3,)], at["discharge"], atol=1e-15)
    np.testing.assert_allclose(at[(1, 2, 3)], at["cells"], atol=1e-15)
    net = model.network()
    for w in ("discharge", "cells", (2,)):  # chain and block solvers agree
        np.testing.assert_allclose(_solve_block(S, b, f, net, d, w).product,
                                   _solve_chain(S, b, f, net, d, w).product, atol=1e-14)
    ds = steady_mill(S, b, f, rtd.RecirculatingCells(TAU, 4, r=2.0), d, where=[2, 4])
    assert ds.attrs["mass_balance_error"] < 1e-12
    with pytest.raises(InputError, match="not in 1..3"):
        steady_mill(S, b, f, model, d, where=(4,))


@pytest.mark.parametrize("model", [rtd.PerfectMixing(TAU), rtd.TanksInSeries(TAU, 3),
                                   rtd.RecirculatingCells(TAU, 5, r=0.5), rtd.PlugFlow(TAU),
                                   rtd.AxialDispersion(TAU, 10.0)])
def test_classification_mass_balance_and_coarse_holdup(model):
    grid, S, b, f = kernel()
    d = np.where(grid.x > 1e-3, 0.3, 1.0)  # coarse retained behind a grate
    ds = steady_mill(S, b, f, model, d)
    assert ds.attrs["mass_balance_error"] < 1e-12
    assert float(ds["product"].min()) >= 0
    coarse = grid.x > 1e-3
    assert float(ds["holdup_fraction"][coarse].sum()) > float(ds["product_fraction"][coarse].sum())
    # without classification the hold-up per feed rate is the mean residence time
    assert abs(float(steady_mill(S, b, f, model)["holdup"].sum()) - TAU) < 1e-9 * TAU


def test_transfer_matrix_columns_and_product():
    grid, S, b, f = kernel()
    d = np.where(grid.x > 1e-3, 0.5, 1.0)
    for model, dd in ((rtd.PerfectMixing(TAU), d), (rtd.TanksInSeries(TAU, 10), d),
                      (rtd.RecirculatingCells(TAU, 3, r=2.0), d), (rtd.AxialDispersion(TAU, 20.0), None),
                      (rtd.Series(rtd.PlugFlow(100.0), rtd.PerfectMixing(500.0)), None)):
        P = transfer_matrix(S, b, model, dd)
        np.testing.assert_allclose(P.sum(axis=0), 1.0, atol=1e-12)
        assert P.min() >= -1e-15
        np.testing.assert_allclose(P @ f, steady_mill(S, b, f, model, dd)["product"], atol=1e-14)


# --------------------------------------------------------------- extreme cases
def _sane(ds, feed):
    p = ds["product"].values
    assert np.all(np.isfinite(p)) and p.min() >= 0
    assert np.all(np.isfinite(ds["holdup"].values)) and ds["holdup"].values.min() >= 0
    assert abs(p.sum() - feed.sum()) < 1e-12 * max(1.0, feed.sum())


@pytest.mark.parametrize("a", [1e-8, 1e8 / TAU])
@pytest.mark.parametrize("model", [rtd.PerfectMixing(TAU), rtd.TanksInSeries(TAU, 200), rtd.PlugFlow(TAU),
                                   rtd.RecirculatingCells(TAU, 200, r=3.0), rtd.AxialDispersion(TAU, 1e-2),
                                   rtd.AxialDispersion(TAU, 1e4)])
def test_stiff_rates_stay_finite_nonnegative_conserving(a, model):
    grid, S, b, _ = kernel(n=15, a=a)
    for feed in (np.eye(15)[0], np.eye(15)[-1], np.full(15, 1 / 15)):
        _sane(steady_mill(S, b, feed, model), feed)


@pytest.mark.parametrize("model", [rtd.PerfectMixing(TAU), rtd.TanksInSeries(TAU, 200),
                                   rtd.RecirculatingCells(TAU, 50, r=1.0), rtd.PlugFlow(TAU)])
def test_extreme_classification(model):
    grid, S, b, _ = kernel(n=15, a=1e4 / TAU)
    d = np.geomspace(1e-3, 1e3, 15)
    for feed in (np.eye(15)[0], np.eye(15)[-1]):
        for where in ((None, "cells") if not isinstance(model, rtd.PlugFlow) else (None,)):
            _sane(steady_mill(S, b, feed, model, d, where=where), feed)


@pytest.mark.parametrize("pe", [1e-2, 1e4])
@pytest.mark.parametrize("a", [1e3 / TAU, 1e8 / TAU])
def test_extreme_axial_classification(pe, a):
    grid, S, b, _ = kernel(n=8, a=a, ratio=2.0)
    d = np.geomspace(1e-3, 1e3, 8)
    for feed in (np.eye(8)[0], np.eye(8)[-1]):
        _sane(steady_mill(S, b, feed, rtd.AxialDispersion(TAU, pe), d, tol=1e-6), feed)


@settings(max_examples=15, deadline=None)
@given(n=st.integers(2, 8), seed=st.integers(0, 2**31 - 1), log_tau=st.floats(-3, 6),
       kind=st.sampled_from(["pm", "tis", "cells", "plug", "axial"]))
def test_mass_conservation_random_kernels(n, seed, log_tau, kind):
    rng = np.random.default_rng(seed)
    S = np.append(10.0 ** rng.uniform(-3, 3, n - 1), 0.0)
    b = np.tril(rng.random((n, n)), -1)
    b[:, :-1] /= b[:, :-1].sum(axis=0)
    b[:, -1] = 0
    feed = rng.random(n)
    d = 10.0 ** rng.uniform(-2, 2, n)
    tau = 10.0**log_tau
    model = {"pm": rtd.PerfectMixing(tau), "tis": rtd.TanksInSeries(tau, 4),
             "cells": rtd.RecirculatingCells(tau, 3, r=0.5), "plug": rtd.PlugFlow(tau),
             "axial": rtd.AxialDispersion(tau, 3.0)}[kind]
    for dd in (None, d):
        ds = steady_mill(S, b, feed, model, dd, tol=1e-6)
        assert ds.attrs["mass_balance_error"] < 1e-12 * feed.sum() * n
        assert ds["product"].values.min() >= 0


# --------------------------------------------------------------- outputs and API
def test_dataset_layout_and_locations():
    grid, S, b, f = kernel()
    ds = steady_mill(S, b, f, rtd.TanksInSeries(TAU, 3), x=grid.x,
                     locations={"discharge": "discharge", "middle": "cell:2", "feed": "feed"})
    assert ds["product"].dims == ("size",) and ds["x"].attrs["units"] == "m"
    assert ds["cell_holdup"].dims == ("cell", "size")
    for key in ("method", "error_estimate", "runtime_s", "mass_balance_error"):
        assert key in ds.attrs
    np.testing.assert_allclose(ds["sample"].sel(location="discharge"), ds["product_fraction"])
    np.testing.assert_allclose(ds["sample"].sum("size"), 1.0)
    ax = steady_mill(S, b, f, rtd.AxialDispersion(TAU, 10.0), positions=[0, 0.5, 1], locations=["z:0.5"])
    assert ax["profile"].dims == ("position", "size")
    np.testing.assert_allclose(ax["sample"].sum("size"), 1.0)



def test_size_coordinate_means_the_same_in_every_dataset():
    # "size" is the upper class size [m] with units, as the grid's own coordinate and the
    # batch and flowsheet Datasets have it; the class number is "size_class"
    from millflow.mill import transient_mill

    grid, S, b, f = kernel()
    want = grid.size_coord()
    steady = steady_mill(S, b, f, rtd.TanksInSeries(TAU, 3), x=grid)
    moving = transient_mill(S, b, rtd.TanksInSeries(TAU, 3), np.array([0.0, TAU]), feed=f, x=grid.x)
    for ds in (steady, moving):
        np.testing.assert_array_equal(ds["size"].values, want.values)
        assert ds["size"].attrs["units"] == "m" == want.attrs["units"]
        np.testing.assert_array_equal(ds["size_class"].values, np.arange(1, grid.n + 1))
        np.testing.assert_array_equal(ds["x"].values, want.values)  # the old name, kept
        # selecting by a size in metres works as on the grid's coordinate
        assert float(ds["size"].sel(size=grid.x[2])) == grid.x[2]
    bare = steady_mill(S, b, f, rtd.TanksInSeries(TAU, 3))  # no sizes given: class numbers only
    assert "size" not in bare.coords and bare["size_class"].values[0] == 1


def test_mill_object():
    grid, S, b, f = kernel()
    mill = Mill(S, b, rtd.TanksInSeries(TAU, 3), d=np.full(S.size, 0.8))
    assert "TanksInSeries" in repr(mill) and mill.method == "cells"
    np.testing.assert_allclose(mill.product(f), mill.steady(f)["product"], atol=0)
    np.testing.assert_allclose(mill.transfer_matrix() @ f, mill.product(f), atol=1e-15)


@pytest.mark.parametrize("call, match", [
    (lambda S, b, f: steady_mill(S, b, f, rtd.PerfectMixing(TAU), np.zeros(S.size)), "d: class 1"),
    (lambda S, b, f: steady_mill(S, b, f, rtd.PerfectMixing(TAU), np.ones(3)), "d has shape"),
    (lambda S, b, f: steady_mill(S, b, f[:-1], rtd.PerfectMixing(TAU)), "feed has shape"),
    (lambda S, b, f: steady_mill(S, b[:-1], f, rtd.PerfectMixing(TAU)), "b has shape"),
    (lambda S, b, f: steady_mill(S, b, -f, rtd.PerfectMixing(TAU)), "feed: class 1"),
    (lambda S, b, f: steady_mill(S, b, f, rtd.Series(rtd.PlugFlow(1.0), rtd.PerfectMixing(2.0)),
                                 np.ones(S.size)), "cannot carry classification"),
    (lambda S, b, f: steady_mill(S, b, f, rtd.AxialDispersion(TAU, 3.0, bc="open"), np.linspace(0.5, 1, S.size),
                                 dispersion=np.ones(S.size)), "same Peclet number"),
    (lambda S, b, f: steady_mill(S, b, f, rtd.AxialDispersion(TAU, 3.0, bc="open"), discharge="mixed"),
     "expected one of 'sampled', 'flux'"),
    (lambda S, b, f: steady_mill(S, b, f, rtd.AxialDispersion(TAU, 3.0), discharge="flux"), "not the open vessel"),
    (lambda S, b, f: steady_mill(S, b, f, rtd.TanksInSeries(TAU, 2), dispersion=np.ones(S.size)),
     "no axial dispersion"),
    (lambda S, b, f: steady_mill(S, b, f, rtd.PlugFlow(TAU), np.ones(S.size), where="discharge"), "where"),
    (lambda S, b, f: steady_mill(S, b, f, rtd.PerfectMixing(TAU), method="magic"), "expected one of"),
    (lambda S, b, f: steady_mill(S, b, f, rtd.PerfectMixing(TAU), np.ones(S.size), method="segregated"),
     "does not apply"),
    (lambda S, b, f: steady_mill(S, b, f, "tanks"), "expected an rtd model"),
    (lambda S, b, f: steady_mill(S, b, f, rtd.TanksInSeries(TAU, 2), positions=[0.5]), "no axis"),
])
def test_bad_definitions(call, match):
    _, S, b, f = kernel(n=10)
    with pytest.raises(InputError, match=match):
        call(S, b, f)


def test_negative_tau_is_refused():
    with pytest.raises(ValueError, match="tau"):
        rtd.PerfectMixing(-1.0)


def test_an_rtd_fit_result_is_not_a_transport():
    """Issue 14 §2: a fit of minutes data passed as it is would be read in seconds; refused."""
    import rtd as _rtd

    t = np.linspace(0, 40, 81)
    res = _rtd.fit("tis", t, _rtd.TanksInSeries(6.0, 3.0).pdf(t))
    S, b, f = np.array([0.01, 0.0]), np.array([[0.0, 0.0], [1.0, 0.0]]), np.array([1.0, 0.0])
    with pytest.raises(InputError, match="model_in_seconds"):
        steady_mill(S, b, f, res)


@pytest.mark.parametrize("rate, n, tau", [(0.01, 2.5, 600.0), (0.05, 3.04, 600.0), (0.001, 7.3, 60.0)])
def test_segregated_real_n_equal_rates_estimate_is_honest(rate, n, tau):
    """Issue 10 §2: segregated flow with equal rates (a defective K) and a real-n tanks in
    series. Reference: P = exp(-n log(I - K tau/n)) f in 40-digit arithmetic (mpmath). The
    reported error estimate must not be below the actual error by more than a factor 3."""
    import mpmath as mp

    mp.mp.dps = 40
    N = 20
    g = SizeGrid.geometric(4e-3, 2 ** 0.5, N)
    b = b_from_B(normalized_B(g.x, 0.5, 0.8, 3.0))
    S = np.full(N, rate)
    S[-1] = 0.0
    f = np.zeros(N)
    f[:3] = [0.3, 0.4, 0.3]
    ds = steady_mill(S, b, f, rtd.TanksInSeries(tau, n), method="segregated")
    K = mp.matrix(N, N)
    for i in range(N):
        for j in range(N):
            K[i, j] = mp.mpf(b[i, j]) * mp.mpf(S[j]) - (mp.mpf(S[j]) if i == j else 0)
    P = mp.expm(-mp.mpf(n) * mp.logm(mp.eye(N) - K * mp.mpf(tau) / mp.mpf(n)))
    ref = np.array([float(v) for v in P * mp.matrix(f.tolist())])
    err = float(np.max(np.abs(ds["product"].values - ref)))
    assert err <= 3 * ds.attrs["error_estimate"] + 1e-300
    assert err < 1e-13  # and the answer is exact to rounding
