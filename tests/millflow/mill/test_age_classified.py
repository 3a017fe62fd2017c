"""Slowing-down in the particle's age with classification (millflow.mill.age_cells): the
age-structured cell balance against segregated flow (d* = 1), the linear classified mill
(kappa = 1), closed forms integrated by scipy quad, its mass balance, its error estimate
against a tight solve, and the refusal of classification on the axis of plug flow and of the
open vessel."""
import numpy as np
import pytest
from scipy.integrate import quad

import rtd
from millflow import steady_mill
from millflow.mill import nonlinear as nl
from millflow.mill.age_cells import age_structured
from millflow.nonlinear import kinetics
from tests.millflow.mill.nonlinear_scene import TAU, breakage_scene

S_SLOW = 2.0
CELLS = {"perfect_mixing": lambda: rtd.PerfectMixing(TAU), "tanks_3": lambda: rtd.TanksInSeries(TAU, 3),
         "recirculating": lambda: rtd.RecirculatingCells(TAU, 4, 0.5)}


def _scene(n=16):
    grid, S, b, feed = breakage_scene(n)
    d = np.linspace(0.3, 1.0, n)  # coarse classes held back, d*_N = 1
    return S, b, feed, d


def _slow(S, b):
    return kinetics(S, b, kappa_t=lambda t: 1.0 / (1.0 + S_SLOW * t / TAU))


@pytest.mark.parametrize("name", list(CELLS))
def test_no_classification_is_segregated_flow(name):
    S, b, feed, _ = _scene()
    kin, T = _slow(S, b), CELLS[name]()
    r = age_structured(kin, feed, T, None)
    ref = nl.age_slowing(kin, feed, T, tol=1e-12)
    assert np.abs(r.product - ref.product).max() < 1e-9
    assert np.abs(r.info["holdup"] - ref.info["holdup"]).max() < 1e-9 * TAU
    # d* = 1 given explicitly goes the age-structured way and agrees too
    ones = nl.age_slowing(kin, feed, T, np.ones(S.size))
    assert "age-structured" in ones.method
    assert np.abs(ones.product - ref.product).max() < 1e-9


@pytest.mark.parametrize("name", list(CELLS))
@pytest.mark.parametrize("where", ["discharge", "cells"])
def test_kappa_one_is_the_linear_classified_mill(name, where):
    S, b, feed, d = _scene()
    T = CELLS[name]()
    one = kinetics(S, b, kappa_t=lambda t: 1.0)
    r = nl.solve_transport(one, feed, T, d, where=where)
    lin = steady_mill(S, b, feed, T, d, where=where, locations=["discharge", "holdup"])
    assert np.abs(r.product - lin["product"].values).max() < 1e-9
    # and through steady_mill with the kinetics object
    ds = steady_mill(one, None, feed, T, d, where=where)
    assert np.abs(ds["product"].values - lin["product"].values).max() < 1e-9


def test_a_class_that_does_not_break():
    # hold-up tau / d*, product = feed, whatever kappa
    kin = kinetics(np.array([0.0]), np.zeros((1, 1)), kappa_t=lambda t: 1.0 / (1.0 + t))
    r = age_structured(kin, [1.0], rtd.PerfectMixing(TAU), np.array([0.25]))
    assert abs(r.product[0] - 1.0) < 1e-12
    assert abs(r.info["holdup"][0] - TAU / 0.25) < 1e-9 * TAU


@pytest.mark.parametrize("d1, d2", [(0.4, 1.0), (2.0, 0.5)])
def test_two_classes_in_closed_form(d1, d2):
    """Class 1 breaks at S1 kappa(a) into class 2, which does not break; a perfect mixer.

    m1(a) = f1 (1 + s a/t_ref)^(-S1 t_ref/s) exp(-d1 a/tau), so p1 = (d1/tau) int m1 and,
    integrating the balance of class 2 over all ages, p2 = f2 + int S1 kappa m1 (scipy quad)."""
    S1, t_ref, f = 3.0 / TAU, 0.5 * TAU, np.array([0.7, 0.3])
    kappa = lambda a: 1.0 / (1.0 + S_SLOW * a / t_ref)  # noqa: E731
    kin = kinetics(np.array([S1, 0.0]), np.array([[0.0, 0.0], [1.0, 0.0]]), kappa_t=kappa)
    m1 = lambda a: f[0] * (1.0 + S_SLOW * a / t_ref) ** (-S1 * t_ref / S_SLOW) * np.exp(-d1 * a / TAU)  # noqa: E731
    h1 = quad(m1, 0, np.inf, epsabs=1e-15, epsrel=1e-13, limit=400)[0]
    broken = quad(lambda a: S1 * kappa(a) * m1(a), 0, np.inf, epsabs=1e-15, epsrel=1e-13, limit=400)[0]
    exact = np.array([d1 / TAU * h1, f[1] + broken])
    r = age_structured(kin, f, rtd.PerfectMixing(TAU), np.array([d1, d2]))
    assert np.abs(r.product - exact).max() < 1e-10
    assert abs(r.info["holdup"][0] - h1) < 1e-10 * TAU
    assert abs(r.info["holdup"][1] - TAU / d2 * exact[1]) < 1e-10 * TAU
    # theta in closed form only (kappa = theta' by the stencil): the same to ~1e-10
    th = kinetics(kin.S, kin.b, theta_t=lambda a: t_ref / S_SLOW * np.log1p(S_SLOW * a / t_ref))
    assert np.abs(age_structured(th, f, rtd.PerfectMixing(TAU), np.array([d1, d2])).product - exact).max() < 1e-9


@pytest.mark.parametrize("name", list(CELLS))
@pytest.mark.parametrize("where", ["discharge", "cells", (2,)])
def test_mass_balance_closes(name, where):
    S, b, feed, d = _scene()
    T = CELLS[name]()
    if where == (2,) and name == "perfect_mixing":
        where = "cells"
    r = nl.solve_transport(_slow(S, b), feed, T, d, where=where)
    assert r.mass_balance_error < 1e-12
    assert r.product.min() > -1e-15


@pytest.mark.parametrize("rtol", [1e-5, 1e-7, 1e-10])
@pytest.mark.parametrize("name", ["perfect_mixing", "tanks_3", "recirculating"])
def test_error_estimate_bounds_the_error_against_a_tight_solve(name, rtol):
    S, b, feed, d = _scene()
    kin, T = _slow(S, b), CELLS[name]()
    ref = age_structured(kin, feed, T, d, "cells", rtol=3e-13, atol=1e-17, tail=1e-16)
    r = age_structured(kin, feed, T, d, "cells", rtol=rtol)
    err = max(np.abs(r.product - ref.product).max(), np.abs(r.info["holdup"] - ref.info["holdup"]).max() / TAU)
    assert err <= r.error_estimate
    assert r.error_estimate < 1e3 * rtol


def test_the_plug_flow_solver_routes_classification_on_its_axis():
    """nl.plug_flow with kappa(t) and d: the age-position balance of plug flow
    (millflow.mill.age_axis.age_structured_plug; tested in test_age_axis.py)."""
    S, b, feed, d = _scene()
    assert "age-structured plug flow" in nl.plug_flow(_slow(S, b), feed, TAU, d).method
