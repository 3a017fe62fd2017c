"""Kernels, the fixed-pivot operator and the non-linear kinetics: conservation, analytic
Jacobians against finite differences, linear limits, slowing-down, bad input."""
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp

from millflow.batch import batch_solve
from millflow.breakage import b_from_B, normalized_B, power_law_rates
from millflow.errors import InputError, MillflowError
from millflow.grid import SizeGrid
from millflow.nonlinear import (Aggregation, AggregationOperator, KernelError, batch_nonlinear, constant_kernel,
                                kinetics, product_kernel, shear_kernel, slowing_down, sum_kernel, theta_of,
                                user_kernel)
from millflow.nonlinear.aggregation import pivot_volumes

XREF = 1e-4


def _linear(n=30):
    grid = SizeGrid.geometric(4e-3, 2 ** 0.25, n)
    S = power_law_rates(grid.x, 0.02, 1.0, 1e-3)
    S[-1] = 0.0
    b = b_from_B(normalized_B(grid.x, 0.4, 0.8, 3.5))
    feed = np.zeros(n)
    feed[:3] = [0.3, 0.5, 0.2]
    return grid, S, b, feed


def _fd_jacobian(f, y, h=1e-7):
    J = np.empty((f(y).size, y.size))
    for m in range(y.size):
        e = np.zeros_like(y)
        e[m] = h * max(1.0, abs(y[m]))
        J[:, m] = (f(y + e) - f(y - e)) / (2 * e[m])
    return J


# --------------------------------------------------------------------- kernels
@pytest.mark.parametrize("func, msg", [
    (lambda u, v: u - v - 10.0, "< 0"),
    (lambda u, v: 1.0 + u * u * v, "symmetric"),
    (lambda u, v: np.full(np.broadcast(u, v).shape, -np.inf), "finite"),  # a kernel that returns -inf
])
def test_bad_user_kernels_are_refused_in_one_line(func, msg):
    with pytest.raises(KernelError, match=msg) as exc:
        user_kernel(func).matrix(np.array([3.0, 2.0, 1.0]))
    assert "\n" not in str(exc.value) and isinstance(exc.value, MillflowError)


def test_named_kernels_and_negative_beta0():
    v = np.array([8.0, 1.0])
    assert np.allclose(constant_kernel(2.0).matrix(v), 2.0)
    assert np.allclose(sum_kernel(1.0).matrix(v), [[16, 9], [9, 2]])
    assert np.allclose(product_kernel(1.0).matrix(v), [[64, 8], [8, 1]])
    assert np.allclose(shear_kernel(1.0).matrix(v), [[64, 27], [27, 8]])
    with pytest.raises(KernelError, match="beta0"):
        constant_kernel(-1.0)


# ------------------------------------------------------------- fixed pivots
grids = st.lists(st.floats(1.05, 2.0), min_size=3, max_size=25).map(
    lambda r: SizeGrid(1e-3 / np.cumprod(np.r_[1.0, r])))  # any (non-geometric) grid
kernel_st = st.sampled_from([constant_kernel(0.3), sum_kernel(0.1), product_kernel(0.01), shear_kernel(0.05)])


@settings(max_examples=40, deadline=None)
@given(grids, kernel_st, st.integers(0, 2 ** 32 - 1))
def test_fixed_pivot_conserves_mass_on_any_grid(grid, kernel, seed):
    M = np.random.default_rng(seed).random(grid.n)
    op = Aggregation(kernel, XREF).on(grid)
    r = op.rate(M)
    # classes + overflow: every pair's births add up to its losses; rounding of O(N^2)
    # terms, relative to the gross aggregation flux (the total mass lost by the pairs)
    gross = float(np.sum(M * (op.beta @ (M / op.v))))
    assert abs(r.sum()) <= 1e-14 * gross * grid.n ** 2
    # the Jacobian's columns too (mass conservation for every perturbation); a diagonal
    # entry is a birth minus a death of similar size, so rounding is relative to the gross terms
    J = op.jacobian(M)
    gross_cols = np.abs(2.0 * (op.G @ (M / op.v)).reshape(grid.n + 1, grid.n) / op.v).sum() + np.abs(J).sum()
    assert np.abs(J.sum(axis=0)).max() <= 1e-14 * gross_cols * grid.n


def test_overflow_is_explicit_and_mass_is_kept():
    grid = SizeGrid.geometric(1e-3, 2 ** (1 / 3), 12)
    feed = np.zeros(12)
    feed[0] = 1.0  # everything in the top class: any aggregate leaves the top
    kin = kinetics(np.zeros(12), None, aggregation=Aggregation(constant_kernel(1.0), 1e-3), grid=grid)
    res = batch_nonlinear(kin, feed, [0.5, 2.0])
    assert res.overflow_mass[-1] > 0.3  # coarse aggregates went above the grid ...
    assert np.allclose(res.M.sum(axis=1) + res.overflow_mass, 1.0, atol=1e-12)  # ... and are accounted for
    assert res.info["max_overflow"] == pytest.approx(res.overflow_mass.max())


def test_pivots_need_a_reference_size():
    with pytest.raises(InputError, match="x_ref_m"):
        pivot_volumes(SizeGrid.geometric(1e-3, 2.0, 4), 0.0)


# ------------------------------------------------------------- kinetics
def test_jacobian_matches_finite_differences():
    grid, S, b, feed = _linear(20)
    rng = np.random.default_rng(1)
    w = 2.0 * rng.random((20, 20))
    kin = kinetics(S, b, w=w, lam=-0.7, aggregation=Aggregation(sum_kernel(0.02), XREF), grid=grid)
    y = np.append(rng.random(20) / 10, 0.01)
    J, Jfd = kin.jacobian(y), _fd_jacobian(kin.rate, y)
    # central differences with h ~ 1e-7: truncation ~ h^2 |R'''| and rounding ~ eps/h ~ 1e-9
    assert np.abs(J - Jfd).max() <= 1e-6 * np.abs(J).max()


@pytest.mark.parametrize("w_scale, lam", [(0.0, -0.8), (3.0, 0.0)])
def test_population_rates_reduce_to_linear_exactly(w_scale, lam):
    grid, S, b, feed = _linear()
    kin = kinetics(S, b, w=w_scale * np.ones((S.size, S.size)), lam=lam)
    y = np.append(feed, 0.0)
    assert np.array_equal(kin.rates(feed), S)  # Phi = 1^lam or base^0: exactly 1
    K = (b - np.eye(S.size)) * S
    assert np.allclose(kin.rate(y)[:-1], K @ feed, rtol=0, atol=1e-16)
    res = batch_nonlinear(kin, feed, [60.0, 600.0], rtol=1e-10, atol=1e-14)
    exact = batch_solve(S, b, feed, [60.0, 600.0]).M
    assert np.abs(res.M - exact).max() < 10 * res.error_estimate + 1e-12  # within its own estimate


def test_linear_kinetics_take_the_exact_path():
    grid, S, b, feed = _linear()
    res = batch_nonlinear(kinetics(S, b), feed, [10.0, 100.0])
    assert res.method == "exact" and res.info["kinetics"] == "linear"
    assert np.allclose(res.M, batch_solve(S, b, feed, [10.0, 100.0]).M, rtol=0, atol=0)


def test_cushioning_slows_breakage_and_error_estimate_is_honest():
    grid, S, b, feed = _linear()
    w = np.zeros((S.size, S.size))
    w[:, S.size // 2:] = 5.0  # fines (the finer half) cushion every class
    kin = kinetics(S, b, w=w, lam=-1.0)
    t = [60.0, 600.0]
    res = batch_nonlinear(kin, feed, t, rtol=1e-6, atol=1e-10)
    lin = batch_solve(S, b, feed, t).M
    assert res.M[-1, 0] > lin[-1, 0]  # more top-size left than first order would leave
    ref = batch_nonlinear(kin, feed, t, method="Radau", rtol=1e-11, atol=1e-15, error_estimate=False)
    # the estimate (difference of two tolerances) bounds the true error of the returned solve
    assert np.abs(res.M - ref.M).max() <= res.error_estimate
    assert res.mass_balance_error < 1e-12


def test_slowing_down_is_the_linear_solution_at_theta():
    grid, S, b, feed = _linear()
    s = 2.0 / 600.0
    kappa = lambda t: 1.0 / (1.0 + s * t)  # noqa: E731
    t = np.array([30.0, 300.0, 600.0])
    assert np.allclose(theta_of(t, kappa), np.log1p(s * t) / s, rtol=1e-12)
    res = slowing_down(S, b, feed, t, kappa)
    K = (b - np.eye(S.size)) * S
    ode = solve_ivp(lambda tt, y: kappa(tt) * (K @ y), (0, 600.0), feed, method="Radau", t_eval=t,
                    rtol=1e-12, atol=1e-15, jac=lambda tt, y: kappa(tt) * K)
    # an independent ODE solve of dM/dt = kappa(t) K M to rtol 1e-12
    assert np.abs(res.M - ode.y.T).max() < 1e-9


@pytest.mark.parametrize("kw, msg", [
    ({"w": np.ones((3, 3)), "lam": 1.0}, r"w has shape \(3, 3\)"),
    ({"w": np.ones((30, 30)), "lam": math.nan}, "lambda"),
    ({"lam": 0.5}, "without w"),
])
def test_bad_population_input(kw, msg):
    grid, S, b, feed = _linear()
    with pytest.raises(InputError, match=msg):
        kinetics(S, b, **kw)


def test_operator_size_must_match():
    grid, S, b, feed = _linear()
    op = AggregationOperator.build(np.array([4.0, 2.0, 1.0]), constant_kernel(1.0))
    with pytest.raises(InputError, match="3 classes"):
        kinetics(S, b, aggregation=op)


# ------------------------------------------------------- slowing-down by the fines
def _fines_kinetics(S, b, x, c, **extra):
    mask = (x <= x[S.size // 2]).astype(float)
    return kinetics(S, b, fines_mask=mask, kappa=lambda F: 1.0 / (1.0 + c * F),
                    dkappa=lambda F: -c / (1.0 + c * F) ** 2, **extra), mask


def test_fines_slowing_jacobian_with_every_term():
    grid, S, b, feed = _linear(20)
    rng = np.random.default_rng(3)
    kin, _ = _fines_kinetics(S, b, grid.x, 4.0, w=rng.random((20, 20)), lam=0.6,
                             aggregation=Aggregation(shear_kernel(0.01), XREF), grid=grid)
    y = np.append(rng.random(20) / 10, 0.0)
    J, Jfd = kin.jacobian(y), _fd_jacobian(kin.rate, y)
    # central differences, h ~ 1e-7 (as above)
    assert np.abs(J - Jfd).max() <= 1e-6 * np.abs(J).max()
    assert "kappa(fines)" in kin.describe() and not kin.is_linear


def test_fines_slowing_matches_a_time_transform_when_only_the_sink_is_fines():
    # one class breaking into the sink, the sink the fines: F = 1 - M_1 and
    # dM_1/dt = -S_1 M_1 / (1 + c (1 - M_1)). Separating, (1 + c (1 - M)) / M dM = -S_1 dt,
    # integrated from M = 1: (1 + c) ln M_1 - c M_1 + c = -S_1 t (exact, implicit in M_1)
    S = np.array([0.01, 0.0])
    b = np.array([[0.0, 0.0], [1.0, 0.0]])
    c = 3.0
    kin = kinetics(S, b, fines_mask=[0.0, 1.0], kappa=lambda F: 1.0 / (1.0 + c * F),
                   dkappa=lambda F: -c / (1.0 + c * F) ** 2)
    t = np.array([30.0, 100.0, 300.0])
    M1 = batch_nonlinear(kin, [1.0, 0.0], t, rtol=1e-10, atol=1e-14).M[:, 0]
    # the implicit exact solution, evaluated at the computed M_1 (rtol 1e-10 solve)
    assert np.allclose((1 + c) * np.log(M1) - c * M1 + c, -0.01 * t, rtol=1e-7, atol=1e-9)


def test_fines_slowing_needs_all_three_parts():
    grid, S, b, feed = _linear()
    with pytest.raises(InputError, match="together"):
        kinetics(S, b, kappa=lambda F: 1.0)
    with pytest.raises(InputError, match=r"weights in \[0, 1\]"):
        kinetics(S, b, fines_mask=np.full(S.size, 1.5), kappa=lambda F: 1.0, dkappa=lambda F: 0.0)


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2 ** 32 - 1), st.floats(-2.0, 2.0), kernel_st)
def test_every_term_together_conserves_mass(seed, lam, kernel):
    grid, S, b, feed = _linear(25)
    rng = np.random.default_rng(seed)
    kin = kinetics(S, b, w=rng.random((25, 25)), lam=lam, aggregation=Aggregation(kernel, XREF), grid=grid,
                   fines_mask=(grid.x < 3e-4).astype(float), kappa=lambda F: np.exp(-F), dkappa=lambda F: -np.exp(-F))
    y = np.append(rng.random(25), rng.random())
    r = kin.rate(y)
    # breakage columns of b sum to 1 and aggregation births equal its losses: the total is
    # zero to rounding of the gross fluxes (breakage S M plus aggregation losses)
    gross = float(np.sum(kin.rates(y[:-1]) * y[:-1])) + float(np.abs(kin.aggregation.rate(y[:-1])).sum())
    assert abs(r.sum()) <= 1e-13 * gross * 25
    assert np.abs(kin.jacobian(y).sum(axis=0)).max() <= 1e-12 * np.abs(kin.jacobian(y)).sum()
