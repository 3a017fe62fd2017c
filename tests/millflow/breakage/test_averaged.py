"""Class-averaged rates and breakage (millflow.breakage.averaged): the integrals against an
independent quadrature, conservation, the discrete path, and second-order convergence of
a batch grind of the continuous model (eq. 4 with eqs. 5 and 6)."""
import numpy as np
import pytest
from scipy.integrate import quad

from millflow.batch import batch_solve
from millflow.breakage import NonNormalizedBreakage, NormalizedBreakage, PowerLawRate, TabulatedRate
from millflow.breakage.averaged import averaged_breakage, breakage_on_grid, class_average, curve_on_grid
from millflow.breakage.distributions import continuous_B
from millflow.grid import SizeGrid
from millflow.psd import from_distribution, p80, regrid, rosin_rammler

RATE = PowerLawRate(A=0.02, alpha=1.1, x0=1e-3)
BRK = NormalizedBreakage(0.4, 0.8, 3.0)


def _reference(grid, rate, brk):
    """T_ij = mean over class j (uniform in ln y) of S(y) B(x_i; y), by adaptive quadrature."""
    x = grid.x
    n = x.size
    S = np.zeros(n)
    b = np.zeros((n, n))

    def avg(f, j):
        lo, hi = np.log(x[j + 1]), np.log(x[j])
        return quad(lambda u: f(np.exp(u)), lo, hi, epsabs=0, epsrel=1e-13)[0] / (hi - lo)

    def s(y):
        return rate.A * (y / rate.x0) ** rate.alpha

    for j in range(n - 1):
        T = [avg(lambda y, xi=xi: s(y) * float(brk.cumulative(xi, y, top=x[0])), j) for xi in x[j + 1:]]
        S[j] = T[0]
        col = np.append(np.array(T[:-1]) - np.array(T[1:]), T[-1]) / T[0]
        b[j + 1:, j] = col
    return S, b


@pytest.mark.parametrize("brk", [BRK, NonNormalizedBreakage(0.3, 0.7, 3.5, theta=0.2)])
def test_averages_match_adaptive_quadrature(brk):
    grid = SizeGrid.geometric(4e-3, 2 ** 0.5, 9)
    S, b = averaged_breakage(RATE, brk, grid)
    S_ref, b_ref = _reference(grid, RATE, brk)
    # 3 Gauss points per class against adaptive quadrature to 1e-13: the integrands are
    # smooth inside a class, the quadrature error at ratio 2^(1/2) is ~1e-6 relative
    np.testing.assert_allclose(S, S_ref, rtol=2e-6)
    np.testing.assert_allclose(b, b_ref, rtol=2e-5, atol=1e-9)


def test_columns_sum_to_one_and_sink_does_not_break():
    grid = SizeGrid.geometric(8e-3, 2 ** 0.25, 60)
    S, b = averaged_breakage(RATE, BRK, grid)
    assert S[-1] == 0 and np.all(S[:-1] > 0)
    np.testing.assert_allclose(b[:, :-1].sum(axis=0), 1.0, rtol=0, atol=1e-13)  # telescoping sums: rounding only
    assert np.all(np.triu(b) == 0) and np.all(b >= 0)


def test_leaving_rate_is_below_upper_edge_rate_by_in_class_breakage():
    """Fragments coarser than the lower edge stay in the class: S_j = mean S(y) B(x_{j+1}; y)
    < mean S(y); and the class mean of S lies between its edge values (S increasing)."""
    grid = SizeGrid.geometric(4e-3, 2 ** 0.5, 6)
    S, _ = averaged_breakage(RATE, BRK, grid)
    mean_S = class_average(lambda y: RATE.A * (y / RATE.x0) ** RATE.alpha, grid)
    x = grid.x
    edge = RATE.A * (x / RATE.x0) ** RATE.alpha
    assert np.all(S[:-1] < mean_S[:-1])
    assert np.all((edge[1:] < mean_S[:-1]) & (mean_S[:-1] < edge[:-1]))


def test_discrete_models_keep_the_exact_path():
    grid = SizeGrid.geometric(4e-3, 2 ** 0.5, 5)
    table = TabulatedRate([0.5, 0.3, 0.2, 0.1])
    S, b, how = breakage_on_grid(table, BRK, grid)
    assert how == "discrete (as given)"
    np.testing.assert_array_equal(S, [0.5, 0.3, 0.2, 0.1, 0.0])
    np.testing.assert_array_equal(b, BRK.b(grid.x))
    S2, _, how2 = breakage_on_grid(RATE, BRK, grid.with_scheme("upper_edge"))
    assert how2 == "upper edge" and np.array_equal(S2, RATE(grid.x))


def test_curve_average_and_upper_edge():
    grid = SizeGrid.geometric(1e-3, 2.0, 4)
    avg = curve_on_grid(np.log, grid)
    # the mean of ln y over (x_{i+1}, x_i] uniform in ln y is the log of the geometric midpoint
    np.testing.assert_allclose(avg[:-1], 0.5 * (np.log(grid.x[:-1]) + np.log(grid.x[1:])), rtol=1e-14)
    assert avg[-1] == np.log(grid.x[-1])
    np.testing.assert_array_equal(curve_on_grid(np.log, grid.with_scheme("upper_edge")), np.log(grid.x))


def test_continuous_B_reduces_to_the_discrete_eq6():
    x = SizeGrid.geometric(4e-3, 2 ** 0.5, 6).x
    B = BRK.B(x)
    for i in range(2, 6):
        for j in range(i - 1):
            assert continuous_B(x[i - 1], x[j], 0.4, 0.8, 3.0) == pytest.approx(B[i, j], rel=1e-14)


def _batch_p80(ratio, scheme, t=60.0):
    grid = SizeGrid.between(2e-3, 2e-5, ratio).with_scheme(scheme)
    S, b, _ = breakage_on_grid(RATE, BRK, grid)
    feed = from_distribution(grid, lambda x: rosin_rammler(x, 4e-4, 1.5))  # exact class masses of one PSD
    M = batch_solve(S, b, feed, [t]).M[-1]
    return grid, M


def test_batch_grind_converges_at_second_order():
    """P80 of a batch grind of a Rosin-Rammler feed on nested grids 2^(1/2), 2^(1/4), 2^(1/8),
    2^(1/16): the class-averaged scheme's observed order is >= 1.8 (the upper-edge
    scheme's about 1); both converge to the same continuous answer."""
    out = {}
    for scheme in ("class_average", "upper_edge"):
        vals = [p80(*_batch_p80(2 ** (1 / k), scheme)) for k in (2, 4, 8, 16)]
        d = np.abs(np.diff(vals))
        out[scheme] = (vals, np.log2(d[:-1] / d[1:]))
    vals, orders = out["class_average"]
    assert np.all(orders >= 1.8), orders
    old_vals, old_orders = out["upper_edge"]
    assert np.all(old_orders < 1.3), old_orders
    # same limit: the extrapolated values agree to far less than the old scheme's error
    ext_new = vals[-1] + (vals[-1] - vals[-2]) / 3
    ext_old = old_vals[-1] + (old_vals[-1] - old_vals[-2])
    assert abs(ext_new - ext_old) < 0.1 * abs(old_vals[-1] - ext_old)


def test_refined_solution_reduces_exactly_to_the_coarse_edges():
    g1, M1 = _batch_p80(2 ** 0.25, "class_average")
    g2, M2 = _batch_p80(2 ** 0.125, "class_average")
    red = regrid(M2, g2, g1)
    assert abs(red.sum() - 1) < 1e-13
    # second order: the coarse class masses are within 1 % (absolute 1e-3) of the refined ones
    np.testing.assert_allclose(M1, red, atol=2e-3)


@pytest.mark.parametrize("scheme", ["class_average", "upper_edge"])
def test_grind_reports_a_grid_error_that_bounds_the_actual(scheme):
    """batch.grind splits its error estimate into solver and grid parts; the grid part
    (Richardson from the grid refined 2x, safety 3) is >= the actual error of the mass
    fractions against a 2^(1/64) reference and <= 10x it (measured ~3x for both schemes)."""
    from millflow.batch import grind

    def run(k, sch):
        g = SizeGrid.geometric(2e-3, 2 ** (1 / k), 7 * k + 1).with_scheme(sch)  # nested, sink edge too
        return g, grind(g, RATE, BRK, from_distribution(g, lambda x: rosin_rammler(x, 4e-4, 1.5)), [0, 60.0])

    gref, dref = run(64, "class_average")
    for k in (2, 4):
        g, ds = run(k, scheme)
        actual = np.max(np.abs(ds.mass_fraction.values[-1] - regrid(dref.mass_fraction.values[-1], gref, g)))
        est = ds.attrs["grid_error_estimate"]
        assert actual <= est <= 10 * actual, (k, est, actual)
        assert ds.attrs["error_estimate"] == ds.attrs["solver_error_estimate"] + est
        assert "Richardson" in ds.attrs["grid_error_method"]


def test_grind_of_discrete_arrays_has_no_grid_error():
    from millflow.batch import grind

    g = SizeGrid.geometric(1e-3, 2.0, 3)
    ds = grind(g, [0.1, 0.05, 0.0], [[0, 0, 0], [0.7, 0, 0], [0.3, 1, 0]], [1.0, 0, 0], [0, 10.0])
    assert ds.attrs["grid_error_estimate"] == 0.0 and ds.attrs["discretisation"] == "discrete (as given)"
