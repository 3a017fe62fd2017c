"""Open-vessel axial-dispersion mill with classification, size-dependent dispersion and
profiles (issue 14 §2; :mod:`millflow.mill.axial_open`).

References: segregated flow with the open density (an independent path: spectral
decomposition and the exact transform, :mod:`millflow.mill.segregated`), the identity
v = w = d* <=> rates S/d*, the flux-weighted open density for the flux discharge, and a
closed-form solution on the infinite line for three classes with unequal velocities and
dispersions. Tolerances: the finite volumes stop when their Richardson error estimate is
below tol = 1e-8 (of a unit feed); they are checked against that estimate (the observed
errors are 5-15x below it) plus a rounding allowance. Mass balance: 1e-12 (rounding of
sums of O(1) flows over a few thousand nodes).
"""
import math

import numpy as np
import pytest
import rtd
from hypothesis import given, settings, strategies as st

from millflow.breakage import b_from_B, normalized_B, power_law_rates
from millflow.errors import InputError
from millflow.grid import SizeGrid
from millflow.mill import Mill, steady_mill, transfer_matrix, transient_mill
from millflow.mill.axial_open import solve_axial_open, solve_axial_open_grid

TAU = 300.0


def kernel(n=30):
    grid = SizeGrid.geometric(1e-2, 2**0.25, n)
    S = power_law_rates(grid.x, 1.0 / 60, 1.0, 1e-3)
    S[-1] = 0.0
    b = b_from_B(normalized_B(grid.x, 0.4, 0.8, 3.0))
    feed = np.zeros(n)
    feed[:3] = [0.2, 0.5, 0.3]
    return S, b, feed


@pytest.mark.parametrize("pe", [0.5, 5.0, 50.0, 500.0])
def test_unclassified_equals_segregated_open_density(pe):
    """v = w = 1, sampled discharge: the product is segregated flow with the open E, the
    hold-up G(-K) f with total tau (1 + 2/Pe), the mean of E."""
    S, b, f = kernel()
    seg = steady_mill(S, b, f, rtd.AxialDispersion(TAU, pe, bc="open"))
    sol = solve_axial_open(S, b, f, TAU, pe)
    assert np.abs(sol.product - seg["product"].values).max() <= sol.error_estimate + 1e-13
    assert sol.error_estimate < 1e-8
    assert abs(sol.product.sum() - f.sum()) < 1e-12
    # the hold-up is extrapolated like the product (second order): 1e-7 of tau is ~100x its error
    np.testing.assert_allclose(sol.holdup, seg["holdup"].values, atol=1e-7 * TAU)
    assert abs(sol.holdup.sum() - TAU * (1 + 2 / pe)) < 1e-7 * TAU


def test_velocity_and_dispersion_scaled_alike_is_rates_over_d():
    """v = w = d* (the open vessel's default dispersion): every transport time of class i
    is scaled by 1/d_i*, so the product is segregated flow with rates S/d*, the hold-up
    that of the scaled problem divided by d*."""
    S, b, f = kernel()
    d = np.linspace(0.4, 1.0, S.size)
    model = rtd.AxialDispersion(TAU, 5.0, bc="open")
    ds = steady_mill(S, b, f, model, d)
    ref = steady_mill(S / d, b, f, model)
    assert ds.attrs["method"] == "axial_fv" and ds.attrs["discharge"] == "sampled"
    assert np.abs(ds["product"] - ref["product"]).max() <= ds.attrs["error_estimate"] + 1e-13
    np.testing.assert_allclose(ds["holdup"], ref["holdup"] / d, atol=1e-7 * TAU)
    assert ds.attrs["mass_balance_error"] < 1e-12


class _FluxWeightedOpen:
    """E_f = (1 + 1/theta) E_open / 2: the open-open vessel sampled as a flux. Transform
    exp((Pe/2)(1 - a)) (1 + a) / (2a), a = sqrt(1 + 4 s tau / Pe) (half the open E's transform,
    half the inverse Gaussian's); mean tau (1 + 1/Pe)."""

    def __init__(self, tau, pe):
        self.tau, self.pe = tau, pe
        self.open = rtd.AxialDispersion(tau, pe, bc="open")

    def laplace(self, s):
        s = np.asarray(s, dtype=complex)
        a = np.sqrt(1 + 4 * s * self.tau / self.pe)
        out = np.exp(-2 * s * self.tau / (1 + a)) * (1 + a) / (2 * a)
        return out.real if np.isrealobj(s) else out

    @property
    def mean(self):
        return self.tau * (1 + 1 / self.pe)

    @property
    def variance(self):
        mo, vo = self.open.mean, self.open.variance
        second = 0.5 * (vo + mo**2) + 0.5 * (2 * self.tau**2 / self.pe + self.tau**2)
        return second - self.mean**2

    @property
    def analytic_for_re_s_greater_than(self):
        return -self.pe / (4 * self.tau)


def test_flux_discharge_unclassified_is_the_flux_weighted_density():
    S, b, f = kernel()
    pe = 5.0
    sol = solve_axial_open(S, b, f, TAU, pe, discharge="flux")
    seg = steady_mill(S, b, f, _FluxWeightedOpen(TAU, pe))
    assert np.abs(sol.product - seg["product"].values).max() <= sol.error_estimate + 1e-13
    assert abs(sol.product.sum() - 1.0) < 1e-13
    assert abs(sol.holdup.sum() - TAU * (1 + 1 / pe)) < 1e-7 * TAU  # what has not crossed z = 1


def _three_classes_exact(tau, pe, S, beta, v, w, discharge):
    """Products of classes 1, 2, 3 (sink) for a unit feed of class 1 on the infinite line:
    class 1 -> 2 (fraction beta) and 3, class 2 -> 3; c_i sums of exponentials, class 2's
    amplitudes from continuity of c_2 and of its flux at the source plane."""
    k = tau * np.asarray(S, float)
    D = np.asarray(w, float) / pe
    v = np.asarray(v, float)

    def roots(i):
        disc = math.sqrt(v[i] ** 2 + 4 * D[i] * k[i])
        return (v[i] + disc) / (2 * D[i]), (v[i] - disc) / (2 * D[i])

    (p1, m1), (p2, m2) = roots(0), roots(1)
    C1 = 1.0 / (D[0] * (p1 - m1))

    def particular(r):  # -D2 r^2 + v2 r + k2 applied to e^(r z)
        return k[0] * beta * C1 / (-D[1] * r * r + v[1] * r + k[1])

    PL, PR = particular(p1), particular(m1)
    # A + PL = B + PR ; A p2 + PL p1 = B m2 + PR m1
    A, B = np.linalg.solve([[1.0, -1.0], [p2, -m2]], [PR - PL, PR * m1 - PL * p1])
    c1, dc1 = C1 * math.exp(m1), C1 * m1 * math.exp(m1)
    c2 = B * math.exp(m2) + PR * math.exp(m1)
    dc2 = B * m2 * math.exp(m2) + PR * m1 * math.exp(m1)
    if discharge == "flux":
        p = [v[0] * c1 - D[0] * dc1, v[1] * c2 - D[1] * dc2]
    else:
        p = [v[0] * c1, v[1] * c2]
    return np.array([p[0], p[1], 1.0 - p[0] - p[1]])


@pytest.mark.parametrize("discharge, w", [("flux", [1.0, 0.6, 1.3]), ("sampled", [0.5, 0.8, 1.0])])
def test_three_classes_against_the_closed_form(discharge, w):
    """Unequal velocities and dispersions (flux discharge), and equal Peclet numbers
    (sampled), against the exact solution on the infinite line."""
    S = np.array([0.02, 0.005, 0.0])
    beta = 0.6
    b = np.array([[0, 0, 0], [beta, 0, 0], [1 - beta, 1.0, 0]])
    v = np.array([0.5, 0.8, 1.0])
    pe = 3.0
    exact = _three_classes_exact(100.0, pe, S, beta, v, w, discharge)
    sol = solve_axial_open(S, b, np.array([1.0, 0, 0]), 100.0, pe, d=v, w=np.array(w), discharge=discharge)
    assert np.abs(sol.product - exact).max() <= sol.error_estimate + 1e-13
    assert abs(sol.product.sum() - 1.0) < 1e-12
    assert abs(sol.order - 2.0) < 0.1


def test_profile_of_a_tracer_is_flat_inside_the_mill():
    """No breakage: downstream of the feed plane v c = f exactly, so the hold-up density
    tau c(z) is tau f / v at every position in the mill (also on the grid: the fitted
    fluxes are exact for convection-dispersion)."""
    S = np.zeros(3)
    b = np.array([[0, 0, 0], [0.5, 0, 0], [0.5, 1.0, 0]])
    f = np.array([0.2, 0.3, 0.5])
    d = np.array([0.5, 0.8, 1.0])
    ds = steady_mill(S, b, f, rtd.AxialDispersion(TAU, 2.0, bc="open"), d, positions=[0.0, 0.3, 0.7, 1.0])
    np.testing.assert_allclose(ds["profile"].values, np.tile(TAU * f / d, (4, 1)), rtol=1e-12)
    np.testing.assert_allclose(ds["product"], f, atol=1e-15)


def test_profiles_and_samples_along_the_axis():
    S, b, f = kernel()
    d = np.linspace(0.5, 1.0, S.size)
    ds = steady_mill(S, b, f, rtd.AxialDispersion(TAU, 5.0, bc="open"), d, positions=np.linspace(0, 1, 11),
                     locations=["z:0.5", "discharge"])
    assert ds["profile"].dims == ("position", "size") and np.all(ds["profile"].values >= 0)
    # coarse feed classes are ground down along the mill: less coarse at the discharge end
    assert ds["profile_fraction"].values[-1, 0] < ds["profile_fraction"].values[0, 0]
    np.testing.assert_allclose(ds["sample"].sum("size"), 1.0, rtol=1e-12)


def test_transfer_matrix_and_mill_carry_the_discharge():
    S, b, f = kernel(n=12)
    d = np.linspace(0.5, 1.0, S.size)
    model = rtd.AxialDispersion(TAU, 4.0, bc="open")
    P = transfer_matrix(S, b, model, d, dispersion=np.ones(S.size), discharge="flux")
    np.testing.assert_allclose(P.sum(axis=0), 1.0, atol=1e-12)
    mill = Mill(S, b, model, d, dispersion=np.ones(S.size), discharge="flux")
    np.testing.assert_allclose(mill.product(f), P @ f, atol=1e-8)  # both within tol = 1e-8 of exact


def test_sampled_discharge_with_unequal_peclet_numbers_is_refused():
    S, b, f = kernel(n=8)
    with pytest.raises(InputError, match="same Peclet number.*discharge='flux'"):
        steady_mill(S, b, f, rtd.AxialDispersion(TAU, 4.0, bc="open"), np.linspace(0.5, 1, 8),
                    dispersion=np.ones(8))
    with pytest.raises(InputError, match="same Peclet number"):  # size-dependent dispersion alone
        steady_mill(S, b, f, rtd.AxialDispersion(TAU, 4.0, bc="open"), dispersion=np.linspace(0.5, 1, 8))
    # proportional dispersion keeps one Peclet number: accepted
    d = np.linspace(0.5, 1, 8)
    ds = steady_mill(S, b, f, rtd.AxialDispersion(TAU, 4.0, bc="open"), d, dispersion=2.0 * d)
    assert ds.attrs["mass_balance_error"] < 1e-12


def test_a_vanishing_peclet_number_is_refused_in_one_line():
    """Pe -> 0: the tails would reach 1e301 mill lengths (the mean residence time tau (1 + 2/Pe));
    a named input error, not an overflow inside the grid construction."""
    S, b, f = kernel(n=8)
    with pytest.raises(InputError, match="too small to solve"):
        steady_mill(S, b, f, rtd.AxialDispersion(TAU, 1e-300, bc="open"), np.linspace(0.5, 1, 8))
    ds = steady_mill(S, b, f, rtd.AxialDispersion(TAU, 1e-30, bc="open"), np.linspace(0.5, 1, 8))
    assert ds.attrs["mass_balance_error"] < 1e-12


@settings(max_examples=25, deadline=None)
@given(pe=st.floats(0.3, 300.0), lo=st.floats(0.05, 1.0), spread=st.floats(0.1, 3.0),
       a=st.floats(1e-4, 0.05))
def test_flux_discharge_conserves_mass_for_any_velocities_and_dispersions(pe, lo, spread, a):
    """Property: any positive velocities and dispersions, the flux discharge closes the
    mass balance to rounding and every product is non-negative."""
    n = 10
    grid = SizeGrid.geometric(1e-2, 2**0.5, n)
    S = power_law_rates(grid.x, a, 1.0, 1e-3)
    S[-1] = 0.0
    b = b_from_B(normalized_B(grid.x, 0.4, 0.8, 3.0))
    d = np.linspace(lo, 1.0, n)
    w = np.linspace(1.0, spread, n)
    f = np.zeros(n)
    f[:2] = [0.4, 0.6]
    ds = steady_mill(S, b, f, rtd.AxialDispersion(TAU, pe, bc="open"), d, dispersion=w, discharge="flux")
    assert ds.attrs["mass_balance_error"] < 1e-12
    assert np.all(ds["product"].values >= 0)


@pytest.mark.parametrize("discharge", ["sampled", "flux"])
def test_transient_start_up_ends_at_the_steady_state(discharge):
    """Start-up from empty (method of lines on the same whole-line grid): at t = 60 tau the
    product and hold-up equal the steady solution on that grid to 1e-12 (the integrator's
    tolerances are 1e-8 relative on a state that has settled to its fixed point), and the
    exact steady product to within the transient's spatial error estimate."""
    S, b, f = kernel(n=8)
    d = np.linspace(0.5, 1.0, 8)
    model = rtd.AxialDispersion(TAU, 4.0, bc="open")
    ds = transient_mill(S, b, model, [0.0, TAU, 60 * TAU], feed=f, d=d, discharge=discharge, m_cells=60)
    _, _, p, h = solve_axial_open_grid(S, b, f, TAU, 4.0, 60, d, None, discharge)
    np.testing.assert_allclose(ds["product"].values[-1], p, atol=1e-12)
    np.testing.assert_allclose(ds["holdup"].values[-1], h, atol=1e-12 * TAU)
    exact = steady_mill(S, b, f, model, d, discharge=discharge)["product"].values
    assert np.abs(ds["product"].values[-1] - exact).max() <= ds.attrs["spatial_error_estimate"]
    np.testing.assert_allclose(ds["product"].values[0], 0.0, atol=1e-15)


@pytest.mark.parametrize("discharge", ["sampled", "flux"])
def test_transient_pulse_of_a_tracer_is_the_open_density(discharge):
    """S = 0, a unit pulse of class 1: the product is the open density E(t) (sampled) or the
    flux-weighted E_f = (1 + tau/t) E / 2 (flux), to the spatial error estimate (the pulse
    sits in the feed volume: O(h) at 200 volumes, 1e-4 of the peak observed)."""
    S = np.zeros(3)
    b = np.array([[0, 0, 0], [0.5, 0, 0], [0.5, 1.0, 0]])
    model = rtd.AxialDispersion(TAU, 4.0, bc="open")
    t = np.linspace(0.1 * TAU, 6 * TAU, 40)
    ds = transient_mill(S, b, model, t, pulse=[1.0, 0, 0], d=np.ones(3), discharge=discharge, m_cells=200)
    E = model.pdf(t) * (1.0 if discharge == "sampled" else 0.5 * (1 + TAU / t))
    err = np.abs(ds["product"].values[:, 0] - E).max()
    assert err <= ds.attrs["spatial_error_estimate"] and err < 1e-3 * E.max()


def test_mill_transient_carries_dispersion_and_discharge():
    """Mill.transient passes the mill's dispersion and discharge (it used to drop the
    dispersion): the same result as transient_mill with them."""
    S, b, f = kernel(n=6)
    d, w = np.linspace(0.5, 1.0, 6), np.linspace(1.0, 2.0, 6)
    model = rtd.AxialDispersion(TAU, 4.0, bc="open")
    mill = Mill(S, b, model, d, dispersion=w, discharge="flux")
    a = mill.transient([0.0, TAU], feed=f, m_cells=40)
    ref = transient_mill(S, b, model, [0.0, TAU], feed=f, d=d, dispersion=w, discharge="flux", m_cells=40)
    np.testing.assert_allclose(a["product"], ref["product"], rtol=1e-12, atol=1e-15)
    closed = Mill(S, b, rtd.AxialDispersion(TAU, 4.0), d, dispersion=w).transient([TAU], feed=f, m_cells=40)
    ref = transient_mill(S, b, rtd.AxialDispersion(TAU, 4.0), [TAU], feed=f, d=d, dispersion=w, m_cells=40)
    np.testing.assert_allclose(closed["product"], ref["product"], rtol=1e-12, atol=1e-15)
