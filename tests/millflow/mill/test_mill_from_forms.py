"""Mill.from_forms: continuous forms on a grid by class averages, with the grid error of the
steady solve estimated by a refined solve (docs/mill.md's recipe)."""
import numpy as np
import pytest

import rtd
import millflow as mf
from millflow.mill import Mill
from millflow.psd import from_distribution, percentile_size

RATE = mf.PowerLawRate(A=0.02, alpha=1.0, x0=1e-3)
BRK = mf.NormalizedBreakage(0.5, 0.8, 3.0)


def _feed(grid):
    """One continuous feed (P = (x / 2 mm)^1.5) put on each grid: the same problem on every grid."""
    return from_distribution(grid, lambda x: np.clip((x / 2e-3) ** 1.5, 0.0, 1.0))


def _p80(m, scheme="class_average"):
    grid = mf.SizeGrid.between(2e-3, 2e-3 / 2 ** 12, 2 ** (1 / m)).with_scheme(scheme)
    ds = Mill.from_forms(RATE, BRK, rtd.TanksInSeries(600.0, 3), grid).steady(_feed(grid))
    return percentile_size(grid, ds["product_fraction"].values, 80.0), ds


def test_class_averages_converge_at_second_order_and_the_estimate_bounds_the_error():
    """P80 on ratios 2^(1/4) ... 2^(1/32): the observed order of the successive changes is
    >= 1.8 (class averages are second order), and at 2^(1/4) the reported relative grid error
    of P80 is at least the actual one (against the 2^(1/32) and 2^(1/64) values extrapolated
    at order 2) and at most 10 x it."""
    vals = {m: _p80(m) for m in (4, 8, 16, 32, 64)}
    p = {m: v[0] for m, v in vals.items()}
    orders = [np.log2(abs(p[a] - p[b]) / abs(p[b] - p[c])) for a, b, c in ((4, 8, 16), (8, 16, 32))]
    assert min(orders) >= 1.8, orders
    ref = p[64] + (p[64] - p[32]) / 3.0
    actual = abs(p[4] / ref - 1.0)
    est = vals[4][1].attrs["p80_grid_error"]
    assert actual <= est <= 10 * actual, (actual, est)
    ds = vals[4][1]
    assert ds.attrs["error_estimate"] == pytest.approx(ds.attrs["solver_error_estimate"]
                                                       + ds.attrs["grid_error_estimate"], rel=1e-12)


def test_upper_edges_are_first_order_and_their_error_is_reported_too():
    """Austin's upper-edge values (scheme "upper_edge"): P80 some 18 % low at 2^(1/4); the
    reported grid error (first order, safety factor 3) covers it."""
    p4, ds = _p80(4, "upper_edge")
    p_ref = _p80(64)[0]
    actual = abs(p4 / p_ref - 1.0)
    assert actual > 0.1 and actual <= ds.attrs["p80_grid_error"] <= 10 * actual


def test_a_mill_of_arrays_is_the_discrete_model_without_grid_error():
    grid = mf.SizeGrid.geometric(2e-3, 2 ** 0.25, 30)
    S, b = RATE(grid.x), BRK.b(grid.x)
    S[-1] = 0.0
    ds = Mill(S, b, rtd.TanksInSeries(600.0, 3), x=grid.x).steady(_feed(grid))
    assert ds.attrs["grid_error_estimate"] == 0.0 and "discrete model itself" in ds.attrs["grid_error_method"]
