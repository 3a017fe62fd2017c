"""Non-linear kinetics with every transport of the linear mill (millflow.mill.nonlinear,
nonlinear_axial, nonlinear_mill): first-order physics through the non-linear paths against
the exact linear mill, non-linear answers against independent routes (solve_ivp on the
equations written out here, scipy quadrature of closed forms, compositions by hand), and
each path's error estimate against refinement or an independent solve."""
import numpy as np
import pytest
from scipy.integrate import quad, solve_ivp

import rtd
from millflow import steady_mill
from millflow.classifiers import screen_discharge
from millflow.errors import InputError, SolverError
from millflow.mill import Mill, transfer_matrix
from millflow.mill import nonlinear as nl
from millflow.nonlinear import Aggregation, batch_nonlinear, constant_kernel, kinetics
from tests.millflow.mill.nonlinear_scene import TAU, breakage_scene



def _scene(n=16):
    grid, S, b, feed = breakage_scene(n)
    return grid, S, b, feed


def _nonlinear(grid, S, b, beta0=0.02, lam=-1.0):
    w = np.zeros((S.size, S.size))
    w[:, S.size // 2:] = 3.0  # fines cushion
    return kinetics(S, b, w=w, lam=lam, aggregation=Aggregation(constant_kernel(beta0), grid.x[-1]), grid=grid)


class _ExitAgesOnly:
    """An RTD model without a mixing structure (only its transform, density and mean)."""

    mean = TAU

    def laplace(self, s):
        return 1.0 / (1.0 + np.asarray(s) * TAU)

    def pdf(self, t):
        return np.exp(-np.asarray(t) / TAU) / TAU

    def cdf(self, t):
        return 1.0 - np.exp(-np.asarray(t) / TAU)


def _first_order(S, b):
    """First-order physics the non-linear solvers must run (Phi = 1 exactly, not declared linear)."""
    kin = kinetics(S, b, w=np.zeros((S.size, S.size)), lam=1.0)
    assert not kin.is_linear
    return kin


# ------------------------------------------------------ first order, every transport
@pytest.mark.parametrize("case", ["plug_axis", "axial_axis", "axial_dispersion", "open_sampled", "open_flux",
                                  "parallel", "series_cells"])
def test_first_order_through_every_non_linear_transport_matches_the_linear_mill(case):
    grid, S, b, feed = _scene()
    d = np.maximum(screen_discharge(grid.x, 2e-3, 3.0), 0.3)  # slower coarse classes along the axis
    disp = np.linspace(1.0, 2.0, S.size)
    kw = {}
    T = {"plug_axis": rtd.PlugFlow(TAU), "axial_axis": rtd.AxialDispersion(TAU, 8.0),
         "axial_dispersion": rtd.AxialDispersion(TAU, 8.0), "open_sampled": rtd.AxialDispersion(TAU, 8.0, bc="open"),
         "open_flux": rtd.AxialDispersion(TAU, 8.0, bc="open"),
         "parallel": rtd.Parallel(rtd.PerfectMixing(TAU), rtd.TanksInSeries(TAU, 3), weights=[0.4, 0.6]),
         "series_cells": rtd.Series(rtd.RecirculatingCells(TAU / 2, 3, 1.0), rtd.AxialDispersion(TAU / 2, 8.0))}[case]
    if case in ("plug_axis", "axial_axis", "open_sampled", "open_flux"):
        kw["d"] = d
    if case in ("axial_dispersion", "open_flux"):
        kw["dispersion"] = disp
    if case == "open_flux":
        kw["discharge"] = "flux"
    lin = steady_mill(S, b, feed, T, kw.get("d"), dispersion=kw.get("dispersion"), discharge=kw.get("discharge"),
                      tol=1e-10)
    ds = steady_mill(_first_order(S, b), None, feed, T, kw.get("d"), dispersion=kw.get("dispersion"),
                     discharge=kw.get("discharge"), tol=1e-8)
    assert ds.attrs["method"].startswith("non-linear kinetics") and "exact linear" not in ds.attrs["method"]
    est = ds.attrs["error_estimate"] + lin.attrs["error_estimate"]
    assert np.abs(ds["product"].values - lin["product"].values).max() <= est
    # hold-up [s]: the linear mill's estimate is relative to the feed times its mean residence time
    assert np.abs(ds["holdup"].values - lin["holdup"].values).max() <= est * lin.attrs["tau_s"]
    assert ds.attrs["mass_balance_error"] < 1e-9


# ------------------------------------------------------ the generic entry points
def test_steady_mill_and_mill_take_a_kinetics_object():
    grid, S, b, feed = _scene()
    kin = _nonlinear(grid, S, b)
    T = rtd.TanksInSeries(TAU, 3)
    ds = steady_mill(kin, None, feed, T, x=grid, locations=["discharge", "cell:2", "holdup"])
    r = nl.tanks_in_series(kin, feed, TAU, 3)
    # the same solver and arithmetic: equal to rounding (1e-14 of the unit feed)
    np.testing.assert_allclose(ds["product"].values, r.product, rtol=0, atol=1e-14)
    assert ds.attrs["overflow_mass"] == pytest.approx(r.overflow_mass, rel=0, abs=1e-14)
    assert ds["cell_holdup"].shape == (3, S.size) and ds["sample"].shape == (3, S.size)
    assert ds.attrs["kinetics"] == kin.describe() and "Newton on the chain" in ds.attrs["method"]
    m = Mill(kin, None, T, x=grid)
    assert m.method == "nonlinear" and m.kinetics is kin and "kinetics=" in repr(m)
    np.testing.assert_allclose(m.product(feed), r.product, rtol=0, atol=1e-14)
    np.testing.assert_allclose(m.steady(feed)["product"].values, r.product, rtol=0, atol=1e-14)
    with pytest.raises(InputError, match="not a matrix times the feed"):
        transfer_matrix(kin, None, T)
    with pytest.raises(InputError, match="carries its own b"):
        steady_mill(kin, b * 0.5, feed, T)
    with pytest.raises(InputError, match="method = 'cells'"):
        steady_mill(kin, None, feed, T, method="cells")
    with pytest.raises(InputError, match="mixing structure"):
        steady_mill(kin, None, feed, _ExitAgesOnly())
    # first-order kinetics as a Kinetics object: the linear mill, exactly
    lin = kinetics(S, b)
    np.testing.assert_allclose(steady_mill(lin, None, feed, T)["product"].values,
                               steady_mill(S, b, feed, T)["product"].values, rtol=0, atol=1e-14)


def test_series_and_parallel_are_their_parts_by_hand():
    grid, S, b, feed = _scene()
    kin = _nonlinear(grid, S, b)
    a, c = nl.well_mixed(kin, feed, TAU / 2), None
    c = nl.plug_flow(kin, a.product, TAU / 2)
    ser = nl.solve_transport(kin, feed, rtd.Series(rtd.PerfectMixing(TAU / 2), rtd.PlugFlow(TAU / 2)))
    # the part's overflow passes the later part unchanged
    assert np.abs(ser.product - c.product).max() <= ser.error_estimate
    assert abs(ser.overflow_mass - (a.overflow_mass + c.overflow_mass)) <= ser.error_estimate
    par = nl.solve_transport(kin, feed, rtd.Parallel(rtd.PerfectMixing(TAU), rtd.PlugFlow(TAU), weights=[0.3, 0.7]))
    by_hand = 0.3 * nl.well_mixed(kin, feed, TAU).product + 0.7 * nl.plug_flow(kin, feed, TAU).product
    assert np.abs(par.product - by_hand).max() <= par.error_estimate
    with pytest.raises(InputError, match="cannot carry classification"):
        nl.solve_transport(kin, feed, rtd.Series(rtd.PerfectMixing(TAU), rtd.PlugFlow(TAU)), np.ones(S.size))


# ------------------------------------------------------ plug flow with d* in the velocity
def test_classified_plug_flow_against_an_independent_integration():
    grid, S, b, feed = _scene()
    kin = _nonlinear(grid, S, b)
    d = np.maximum(screen_discharge(grid.x, 2e-3, 3.0), 0.2)
    r = nl.plug_flow(kin, feed, TAU, d)
    v = np.append(d, 1.0)
    # dF/dz = tau R(F / v), F(0) = f, written out again and integrated by Radau at 1e-12
    sol = solve_ivp(lambda z, F: TAU * kin.rate(F / v), (0, 1), np.append(feed, 0.0), method="Radau",
                    rtol=1e-12, atol=1e-15, jac=lambda z, F: TAU * kin.jacobian(F / v) / v[None, :])
    ref = sol.y[:, -1]
    assert np.abs(r.product - ref[:-1]).max() <= r.error_estimate
    assert r.error_estimate < 1e-7
    # without classification plug flow is the batch grind in contact time (batch_nonlinear)
    r1 = nl.plug_flow(kin, feed, TAU)
    batch = batch_nonlinear(kin, feed, [TAU], method="Radau", rtol=1e-11, atol=1e-14)
    assert np.abs(r1.product - batch.M[0]).max() <= r1.error_estimate + batch.error_estimate


# ------------------------------------------------------ axial grids: estimates against refinement
@pytest.mark.parametrize("pe", [2.0, 10.0, 50.0])
def test_axial_error_estimates_bound_the_error_against_a_refined_reference(pe):
    grid, S, b, feed = _scene(14)
    kin = _nonlinear(grid, S, b)
    ref = nl.axial_dispersion(kin, feed, TAU, pe, tol=1e-11)
    for m in (16, 32, 64):  # one grid checked against half of it
        r = nl.axial_dispersion(kin, feed, TAU, pe, m_cells=m)
        actual = np.abs(r.product - ref.product).max()
        assert actual <= r.error_estimate
        assert r.error_estimate <= 5.0 * actual + 1e-12  # second order: |p_M - p_M/2| ~ 3 x the error
    r = nl.axial_dispersion(kin, feed, TAU, pe, tol=1e-6)  # refined to a tolerance
    assert np.abs(r.product - ref.product).max() <= r.error_estimate + ref.error_estimate
    assert r.error_estimate <= 1e-6


@pytest.mark.parametrize("discharge", ["sampled", "flux"])
def test_open_vessel_with_non_linear_kinetics(discharge):
    grid, S, b, feed = _scene(14)
    kin = _nonlinear(grid, S, b)
    ref = nl.axial_open(kin, feed, TAU, 6.0, discharge=discharge, tol=1e-10)
    r = nl.axial_open(kin, feed, TAU, 6.0, discharge=discharge, tol=1e-6)
    assert np.abs(r.product - ref.product).max() <= r.error_estimate + ref.error_estimate
    # mass: one Peclet number (sampled) or the net flux (flux) conserve it to rounding
    assert ref.mass_balance_error < 1e-9
    # the open vessel is not the closed one (the sampled concentration sees the back-mixing)
    closed = nl.axial_dispersion(kin, feed, TAU, 6.0, tol=1e-8)
    assert np.abs(ref.product - closed.product).max() > 1e-3


# ------------------------------------------------------ slowing-down in the material's age
def test_kappa_of_age_is_segregated_flow_exactly():
    # one class breaking into the sink at S kappa(t), kappa = 1/(1 + s t): exp(-S theta(t)),
    # theta = ln(1 + s t)/s, averaged over the exit ages of three tanks (scipy quad, 1e-12)
    S1, s = 0.004, 0.01
    S, b = np.array([S1, 0.0]), np.array([[0.0, 0.0], [1.0, 0.0]])
    kin = kinetics(S, b, kappa_t=lambda t: 1.0 / (1.0 + s * t))
    T = rtd.TanksInSeries(TAU, 3)
    r = nl.solve_transport(kin, [1.0, 0.0], T)
    exact, _ = quad(lambda t: float(T.pdf(t)) * (1 + s * t) ** (-S1 / s), 0, np.inf, epsabs=1e-14, epsrel=1e-13)
    assert abs(r.product[0] - exact) <= r.error_estimate + 1e-12
    assert r.error_estimate < 1e-8
    # theta in closed form gives the same; plug flow is the batch grind at theta(tau)
    th = kinetics(S, b, theta_t=lambda t: np.log1p(s * t) / s)
    assert abs(nl.solve_transport(th, [1.0, 0.0], T).product[0] - exact) < 1e-9
    plug = nl.solve_transport(kin, [1.0, 0.0], rtd.PlugFlow(TAU))
    assert abs(plug.product[0] - (1 + s * TAU) ** (-S1 / s)) <= plug.error_estimate + 1e-12
    # kappa = 1: the first-order mill
    grid, S, b, feed = _scene()
    one = kinetics(S, b, kappa_t=lambda t: 1.0)
    ds = steady_mill(one, None, feed, rtd.PerfectMixing(TAU))
    lin = steady_mill(S, b, feed, rtd.PerfectMixing(TAU))
    assert np.abs(ds["product"].values - lin["product"].values).max() <= ds.attrs["error_estimate"] + 1e-13


def test_kappa_of_age_refusals_are_one_line_errors():
    grid, S, b, feed = _scene()
    kin = kinetics(S, b, kappa_t=lambda t: 1.0 / (1.0 + t / TAU))
    # cells and axes with classification are solved (the age-structured balances,
    # test_age_classified.py, test_age_axis.py); a composition has nowhere to put d*
    with pytest.raises(InputError, match="cannot carry classification"):
        steady_mill(kin, None, feed, rtd.Series(rtd.PerfectMixing(TAU / 2), rtd.PlugFlow(TAU / 2)),
                    np.full(S.size, 0.5))
    with pytest.raises(InputError, match="combines with no other non-linear term"):
        kinetics(S, b, w=np.ones((S.size, S.size)), lam=-1.0, kappa_t=lambda t: 1.0)
    with pytest.raises(InputError, match="no rate R"):
        kin.rate(np.append(feed, 0.0))


# ------------------------------------------------------ robustness at hard corners
@pytest.mark.parametrize("beta0, lam", [(5.0, -1.5), (1.0, -3.0)])
def test_strong_aggregation_and_cushioning_converge_to_the_start_up_limit(beta0, lam):
    """Newton stalls here and pseudo-transient continuation alone did not reach the root (it
    needed more than Newton's 60 iterations, then wandered off): its own budget, and the
    mill's dynamics integrated to steady state as the last fallback, converge; the answer is
    the state a start-up reaches (transient_mill at 3000 tau)."""
    from millflow.mill import transient_mill

    grid, S, b, feed = _scene(20)
    d = np.maximum(screen_discharge(grid.x, 2e-3, 3.0), 1e-3)
    kin = _nonlinear(grid, S, b, beta0=beta0, lam=lam)
    T = rtd.RecirculatingCells(TAU, 4, 1.0)
    r = nl.cells(kin, feed, T, d, "cells")
    assert "pseudo-transient" in r.method
    ds = transient_mill(kin, None, T, [3000 * TAU], feed=feed, d=d, where="cells", rtol=1e-7, atol=1e-11)
    end = ds["product"].values[0]
    # the start-up's own time error plus what is left of the transient (relaxed to 1e-9)
    assert np.abs(end - r.product).max() <= ds.attrs["error_estimate"] + 1e-7
    assert abs(float(ds["overflow"].values[0]) - r.overflow_mass) < 1e-7


# ------------------------------------------------------ Newton's estimate against refinement
@pytest.mark.parametrize("which", ["well_mixed", "tanks", "cells"])
def test_newton_error_estimates_bound_the_distance_to_a_converged_root(which):
    grid, S, b, feed = _scene(20)
    kin = _nonlinear(grid, S, b, beta0=0.05)
    d = np.maximum(screen_discharge(grid.x, 2e-3, 3.0), 1e-2)

    def run(tol):
        if which == "well_mixed":
            return nl.well_mixed(kin, feed, TAU, d, tol=tol)
        if which == "tanks":
            return nl.tanks_in_series(kin, feed, TAU, 5, d, "cells", tol=tol)
        return nl.cells(kin, feed, rtd.RecirculatingCells(TAU, 3, 1.0), d, tol=tol)

    loose, tight = run(1e-7), run(1e-14)
    # the tight root is converged to rounding; the loose one's estimate covers the distance
    assert np.abs(loose.product - tight.product).max() <= loose.error_estimate + tight.error_estimate
    assert tight.error_estimate < 1e-12
    h_loose, h_tight = (r.info["holdup"] if "holdup" in r.info else r.info["cell_holdup"].sum(axis=0)
                        for r in (loose, tight))
    assert np.abs(h_loose - h_tight).max() <= (loose.info["holdup_error_estimate"]
                                               + tight.info["holdup_error_estimate"])


def test_micromixing_limits_keep_their_old_names():
    assert nl.micromixing_bounds is nl.micromixing_limits and nl.MicromixingBounds is nl.MicromixingLimits
    grid, S, b, feed = _scene()
    mm = nl.micromixing_limits(_nonlinear(grid, S, b), feed, rtd.PerfectMixing(TAU))
    assert isinstance(mm, nl.MicromixingLimits) and "not bounds" in mm.note


def test_bad_inputs_are_one_line_errors():
    grid, S, b, feed = _scene()
    kin = _nonlinear(grid, S, b)
    with pytest.raises(InputError, match="integer number of tanks"):
        nl.solve_transport(kin, feed, rtd.TanksInSeries(TAU, 2.5))
    with pytest.raises(InputError, match="where = 'axis'"):
        nl.solve_transport(kin, feed, rtd.PerfectMixing(TAU), np.ones(S.size), where="axis")
    with pytest.raises(InputError, match="same Peclet number"):
        nl.solve_transport(kin, feed, rtd.AxialDispersion(TAU, 5.0, bc="open"), np.linspace(1, 0.5, S.size),
                           dispersion=np.ones(S.size))
    with pytest.raises(SolverError, match="did not converge") as exc:
        nl.well_mixed(_nonlinear(grid, S, b, beta0=5.0), feed, TAU, max_iter=1, ptc_iter=1)
    assert "\n" not in str(exc.value)
