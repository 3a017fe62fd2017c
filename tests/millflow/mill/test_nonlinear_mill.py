"""Continuous mills with non-linear kinetics (millflow.mill.nonlinear): the linear limit
through the non-linear code paths (aggregation with a zero kernel is non-linear code with
linear physics), an independent transient route to the steady state, the micromixing
limits, and the failures."""
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import rtd
from millflow.errors import SolverError
from millflow.mill.well_mixed import solve_well_mixed
from millflow.mill import nonlinear as nl
from millflow.mill.axial import solve_axial_grid
from millflow.mill.segregated import segregated
from millflow.nonlinear import Aggregation, constant_kernel, kinetics
from tests.millflow.mill.nonlinear_scene import TAU, breakage_scene



def _scene(n=40):
    grid, S, b, feed = breakage_scene(n)
    return grid, S, b, feed


def _nonlinear(grid, S, b, beta0=0.02, lam=-1.0):
    w = np.zeros((S.size, S.size))
    w[:, S.size // 2:] = 3.0  # fines cushion
    return kinetics(S, b, w=w, lam=lam, aggregation=Aggregation(constant_kernel(beta0), grid.x[-1]), grid=grid)


def _zero_kernel(grid, S, b):
    return kinetics(S, b, aggregation=Aggregation(constant_kernel(0.0), grid.x[-1]), grid=grid)


def test_linear_scene_takes_the_exact_path():
    grid, S, b, feed = _scene()
    r = nl.well_mixed(kinetics(S, b), feed, TAU)
    assert r.method.startswith("exact linear") and r.iterations == 0
    # the same solver and arithmetic: equal to rounding (1e-14 of the unit feed)
    np.testing.assert_allclose(r.product, solve_well_mixed(S, b, feed, TAU), rtol=0, atol=1e-14)


def test_nonlinear_code_with_linear_physics_matches_the_linear_solvers():
    grid, S, b, feed = _scene()
    kin = _zero_kernel(grid, S, b)
    assert not kin.is_linear
    # Newton converges to the exact linear answer (rounding of a 41 x 41 LU, ~1e-15)
    assert np.abs(nl.well_mixed(kin, feed, TAU).product - solve_well_mixed(S, b, feed, TAU)).max() < 1e-13
    p = feed
    for _ in range(4):
        p = solve_well_mixed(S, b, p, TAU / 4)
    assert np.abs(nl.tanks_in_series(kin, feed, TAU, 4).product - p).max() < 1e-13
    ax = nl.axial_dispersion(kin, feed, TAU, 8.0, m_cells=16)
    _, _, p_ax = solve_axial_grid(S, b, feed, TAU, 8.0, 16)
    assert np.abs(ax.product - p_ax).max() < 1e-12  # the same discretisation, solved by Newton
    mm = nl.micromixing_limits(kin, feed, rtd.TanksInSeries(TAU, 3))
    exact, _, err, _ = segregated(S, b, feed, rtd.TanksInSeries(TAU, 3), holdup=False)
    # both limits are the exact linear RTD answer, to the ODE/quadrature tolerance (rtol 1e-9)
    assert np.abs(mm.segregated - exact).max() < 1e-7 and np.abs(mm.max_mixedness - exact).max() < 1e-7


def test_well_mixed_newton_against_the_transient_route():
    grid, S, b, feed = _scene()
    kin = _nonlinear(grid, S, b)
    r = nl.well_mixed(kin, feed, TAU)
    y = np.append(r.product, r.overflow_mass)
    # the stated criterion: max|F| <= NEWTON_RTOL x the scale of the terms of F
    assert r.residual <= nl.NEWTON_RTOL * nl.residual_scale(kin, np.append(feed, 0.0), y, TAU)
    assert r.mass_balance_error < 1e-13
    y0 = np.append(feed, 0.0)
    # independent: integrate the dynamic perfect mixer dM/dt = (f - M)/tau + R(M) to steady state
    sol = solve_ivp(lambda t, y: (y0 - y) / TAU + kin.rate(y), (0, 60 * TAU), y0, method="Radau",
                    jac=lambda t, y: -np.eye(y.size) / TAU + kin.jacobian(y), rtol=1e-11, atol=1e-15)
    assert np.abs(sol.y[:-1, -1] - r.product).max() < 1e-9  # exp(-60) transient left, ODE tolerance


def test_tanks_one_cell_is_well_mixed_and_many_cells_approach_plug_flow():
    grid, S, b, feed = _scene(30)
    kin = _nonlinear(grid, S, b)
    one, pm = nl.tanks_in_series(kin, feed, TAU, 1), nl.well_mixed(kin, feed, TAU)
    # two Newton solves of one equation (a chain of one cell, a single cell): within both estimates
    assert np.abs(one.product - pm.product).max() <= one.error_estimate + pm.error_estimate < 1e-11
    pf = nl.plug_flow(kin, feed, TAU).product
    d40 = np.abs(nl.tanks_in_series(kin, feed, TAU, 40).product - pf).max()
    d10 = np.abs(nl.tanks_in_series(kin, feed, TAU, 10).product - pf).max()
    assert d40 < d10 / 3  # the distance to plug flow falls as 1/n (4x more cells, ~4x closer)


def test_micromixing_limits_differ_for_nonlinear_kinetics():
    grid, S, b, feed = _scene(30)
    kin = _nonlinear(grid, S, b, beta0=0.05)
    mm = nl.micromixing_limits(kin, feed, rtd.PerfectMixing(TAU))
    # maximum mixedness of an exponential RTD is the perfect mixer itself
    assert np.abs(mm.max_mixedness - nl.well_mixed(kin, feed, TAU).product).max() < 1e-8
    assert not mm.coincide and mm.spread > 100 * mm.error_estimate


def test_micromixing_for_linear_kinetics_says_they_coincide():
    grid, S, b, feed = _scene(30)
    mm = nl.micromixing_limits(kinetics(S, b), feed, rtd.TanksInSeries(TAU, 2))
    assert mm.coincide and mm.spread == 0.0 and "coincide" in mm.note


def test_newton_failure_names_unit_and_residual():
    grid, S, b, feed = _scene(30)
    kin = _nonlinear(grid, S, b, beta0=5.0)
    with pytest.raises(SolverError, match=r"perfectly mixed mill: .*residual .* > tol") as exc:
        nl.well_mixed(kin, feed, TAU, max_iter=1)
    assert "\n" not in str(exc.value)


def test_micromixing_with_a_tabulated_hazard_axial_dispersion():
    # the axial-dispersion RTD has no closed-form survival: the hazard is tabulated and
    # splined; with linear physics (zero kernel) both limits must be the exact RTD answer
    grid, S, b, feed = _scene(30)
    model = rtd.AxialDispersion(TAU, 10.0)
    mm = nl.micromixing_limits(_zero_kernel(grid, S, b), feed, model)
    exact, _, _, _ = segregated(S, b, feed, model, holdup=False)
    assert np.abs(mm.segregated - exact).max() < 1e-8  # quadrature / ODE at rtol 1e-9
    assert np.abs(mm.max_mixedness - exact).max() < 1e-8
    assert mm.info["hazard_interpolation_error"] < 1e-8


def test_pseudo_transient_continuation_reaches_the_newton_answer():
    # Newton converges on its own in every case tried; the fallback is exercised by
    # starting with it, from a bad start (all mass in the class above the sink)
    grid, S, b, feed = _scene(30)
    kin = _nonlinear(grid, S, b, beta0=5.0, lam=-3.0)
    y_in = np.append(feed, 0.0)
    bad = np.zeros(31)
    bad[-2] = 1.0
    y, res, step, its, how = nl._newton_cell(kin, y_in, TAU, bad, tol=1e-12, max_iter=200, unit="test",
                                             phases=("pseudo-transient", "newton"))
    assert how == "pseudo-transient + newton" and res <= 1e-12
    ref = nl.well_mixed(kin, feed, TAU)
    assert np.abs(y[:-1] - ref.product).max() < 1e-12  # the same root, both to residual 1e-12


def test_newton_criterion_is_relative_to_the_feed_and_the_state():
    """The feed rate in other units (x 1e3, with w / 1e3 so that w M, hence the physics,
    is unchanged): the product scales exactly, where an absolute 1e-12 on max|F| would
    ask for 1e-15 relative accuracy, below rounding of the 1e3-sized terms."""
    grid, S, b, feed = _scene()
    w = np.zeros((S.size, S.size))
    w[:, S.size // 2:] = 3.0
    ref = nl.well_mixed(kinetics(S, b, w=w, lam=1.0), feed, TAU)
    big = nl.well_mixed(kinetics(S, b, w=w / 1e3, lam=1.0), 1e3 * feed, TAU)
    # same root; both to NEWTON_RTOL relative (plus the conditioning of the 41 x 41 solve)
    assert np.abs(big.product / 1e3 - ref.product).max() < 1e-10
    assert big.error_estimate < 1e-9 * 1e3


def test_a_converged_answer_at_the_rounding_level_is_accepted():
    """A residual of a few 1e-12 on a state of order 1 (tau S ~ 30) is converged under the
    scaled criterion: no iteration needed; a residual of 1e-6 is not, and says so."""
    grid, S, b, feed = _scene()
    kin = _nonlinear(grid, S, b)
    ref = nl.well_mixed(kin, feed, TAU)
    y_in = np.append(feed, 0.0)
    y_star = np.append(ref.product, ref.overflow_mass)
    near = y_star + 3e-13 * np.sign(np.arange(y_star.size) % 2 - 0.5)
    f = y_in - near + TAU * kin.rate(near)
    assert 1e-12 < np.abs(f).max() < nl.NEWTON_RTOL * nl.residual_scale(kin, y_in, near, TAU)
    y, res, step, its, _ = nl._newton_cell(kin, y_in, TAU, near, tol=nl.NEWTON_RTOL, max_iter=0, unit="test")
    assert its == 0 and np.abs(y - y_star).max() < 1e-11  # the polishing step only
    far = y_star + 1e-6
    with pytest.raises(SolverError, match=r"test: .*residual .* > tol 1e-11 x scale"):
        nl._newton_cell(kin, y_in, TAU, far, tol=nl.NEWTON_RTOL, max_iter=0, unit="test")


@pytest.mark.parametrize("lam, outside", [(1.0, 5e-4), (-1.0, 5e-5)])
def test_micromixing_limits_are_not_bounds_class_by_class(lam, outside):
    """Four tanks in series share the RTD of rtd.TanksInSeries(tau, 4) and are a state of
    intermediate micromixing; with coupled non-linear rates (nipping lam > 0, cushioning
    lam < 0) their product lies outside both limits in some class, by far more than the
    error estimates of either solve: the limits are extremes, not bounds (as documented)."""
    grid, S, b, feed = _scene()
    w = np.zeros((S.size, S.size))
    w[:, S.size // 2:] = 3.0
    kin = kinetics(S, b, w=w, lam=lam)
    four = nl.tanks_in_series(kin, feed, TAU, 4)
    mm = nl.micromixing_limits(kin, feed, rtd.TanksInSeries(TAU, 4))
    lo = np.minimum(mm.segregated, mm.max_mixedness)
    hi = np.maximum(mm.segregated, mm.max_mixedness)
    beyond = float(np.maximum(lo - four.product, four.product - hi).max())
    assert beyond > outside > 1e3 * (mm.error_estimate + four.error_estimate)
    assert "not bounds" in mm.note
