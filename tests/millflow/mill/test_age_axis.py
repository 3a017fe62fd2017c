"""Slowing-down in the particle's age with classification on the axis of the closed
axial-dispersion vessel (millflow.mill.age_axis): the age-position balance against the
linear classified axial mill (kappa = 1), against segregated flow with the vessel's exit-age
density (v = w = 1), its mass balance, its observed order in z, its error estimate against
a much finer reference, the routing through the non-linear entry points, and the refusals
(the state limit); plug flow with classification on the axis (the extrapolated upwind
cells) against its exact limits; and the open vessel (its whole line, flux and sampled
discharges) against the linear open vessel and segregated flow with its open density."""
import numpy as np
import pytest

import rtd
from millflow.errors import InputError
from millflow.mill import nonlinear as nl
from millflow.mill.age_axis import age_structured_axial, age_structured_open, age_structured_plug
from millflow.mill.age_cells import age_structured
from millflow.mill.axial_open import solve_axial_open
from millflow.mill.axial import solve_axial
from millflow.nonlinear import kinetics
from tests.millflow.mill.nonlinear_scene import TAU, breakage_scene

S_SLOW = 2.0
N = 6


def _scene(n=N, strong=False):
    grid, S, b, feed = breakage_scene(n)
    # classes held back on the axis: d* 0.3 .. 1, or 0.2 for the three coarse classes
    d = np.where(np.arange(n) < 3, 0.2, 1.0) if strong else np.linspace(0.3, 1.0, n)
    return S, b, feed, d


def _slow(S, b):
    return kinetics(S, b, kappa_t=lambda t: 1.0 / (1.0 + S_SLOW * t / TAU))


def _err(r, ref_p, ref_h):
    """Max abs error of the product and of hold-up / tau (what the estimate bounds)."""
    return max(np.abs(r.product - ref_p).max(), np.abs(r.info["holdup"] - ref_h).max() / TAU)


@pytest.mark.parametrize("pe, dispersion", [(1.0, None), (10.0, None), (10.0, "varied")])
def test_kappa_one_is_the_linear_classified_axial_mill(pe, dispersion):
    S, b, feed, d = _scene()
    w = None if dispersion is None else np.linspace(2.0, 0.5, S.size)
    one = kinetics(S, b, kappa_t=lambda t: 1.0)
    r = age_structured_axial(one, feed, rtd.AxialDispersion(TAU, pe), d, dispersion=w, tol=1e-6)
    lin = solve_axial(S, b, feed, TAU, pe, d=d, w=w, tol=1e-10)
    # both are estimates of the same continuous mill: within the sum of the two estimates
    assert _err(r, lin.product, lin.holdup) <= r.error_estimate + lin.error_estimate
    assert r.error_estimate < 1e-6


@pytest.mark.parametrize("pe", [1.0, 20.0])
def test_no_classification_is_segregated_flow(pe):
    S, b, feed, _ = _scene()
    kin, T = _slow(S, b), rtd.AxialDispersion(TAU, pe)
    r = age_structured_axial(kin, feed, T, None, tol=1e-6)
    ref = nl.age_slowing(kin, feed, T, tol=1e-11)  # exit-age quadrature with the closed vessel's E(t)
    # v = w = 1: the transport commutes with breakage; within the sum of the two estimates
    assert _err(r, ref.product, ref.info["holdup"]) <= r.error_estimate + ref.error_estimate
    assert r.error_estimate < 1e-6


@pytest.mark.parametrize("pe, strong", [(1.0, True), (30.0, False)])
def test_mass_balance_closes(pe, strong):
    S, b, feed, d = _scene(strong=strong)
    r = age_structured_axial(_slow(S, b), feed, rtd.AxialDispersion(TAU, pe), d, tol=1e-5)
    # breakage conserves mass and the transport's columns sum to minus its outflow (a
    # linear invariant of BDF): rounding over ~1000 steps of the integrals, ~1e-12 measured
    assert r.mass_balance_error < 1e-11
    assert r.product.min() > -1e-15


def test_observed_order_is_two_on_a_smooth_case():
    S, b, feed, d = _scene()
    kin, T = _slow(S, b), rtd.AxialDispersion(TAU, 1.0)
    ys = []
    for M in (16, 32, 64, 128):
        r = age_structured_axial(kin, feed, T, d, m_cells=M, rtol=1e-11, error_estimate=False)
        ys.append(np.concatenate([r.product, r.info["holdup"] / TAU]))
    diffs = [np.abs(ys[k + 1] - ys[k]).max() for k in range(3)]
    orders = np.log2(np.array(diffs[:-1]) / np.array(diffs[1:]))
    # the exponentially fitted fluxes are central differences to O(P^2) at cell Peclet <= 1:
    # second order (the ODE's error, ~1e-11, is far below the differences, ~1e-6)
    assert np.all(np.abs(orders - 2.0) < 0.1), orders


@pytest.mark.parametrize("pe, strong", [(1.0, True), (10.0, True), pytest.param(100.0, False, marks=pytest.mark.slow)])
def test_error_estimate_bounds_the_error_against_a_finer_reference(pe, strong):
    S, b, feed, d = _scene(strong=strong)
    kin, T = _slow(S, b), rtd.AxialDispersion(TAU, pe)
    ref = age_structured_axial(kin, feed, T, d, tol=1e-8)
    r = age_structured_axial(kin, feed, T, d, tol=1e-5)
    # the reference is converged 1e3 times further than the solve under test (measured:
    # actual / estimate 0.5 at Pe 1, 0.03 at Pe 10, 0.2 at Pe 100)
    assert ref.info["m_cells"] >= 2 * r.info["m_cells"] and ref.error_estimate < 1e-8
    assert _err(r, ref.product, ref.info["holdup"]) + ref.error_estimate <= r.error_estimate
    assert r.error_estimate < 1e-5


def test_the_non_linear_entry_points_reach_it():
    S, b, feed, d = _scene()
    kin, T = _slow(S, b), rtd.AxialDispersion(TAU, 5.0)
    r = nl.solve_transport(kin, feed, T, d, where="axis", tol=1e-6)
    assert "age-structured axial" in r.method and r.error_estimate < 1e-6
    a = nl.age_slowing(kin, feed, T, d)
    assert "age-structured axial" in a.method
    assert np.abs(a.product - r.product).max() <= a.error_estimate + r.error_estimate
    # a relative dispersion alone (d = None) is classification on the axis too
    w = np.linspace(2.0, 0.5, S.size)
    rw = nl.solve_transport(kin, feed, T, dispersion=w, tol=1e-6)
    assert "age-structured axial" in rw.method


def test_what_is_not_built_is_refused():
    S, b, feed, d = _scene()
    kin = _slow(S, b)
    with pytest.raises(InputError, match="age and position are not tied"):  # cells carry no axis
        age_structured(kin, feed, rtd.TanksInSeries(TAU, 3), d, "axis")
    with pytest.raises(InputError, match="exceed the state limit 4096"):
        age_structured_axial(kin, feed, rtd.AxialDispersion(TAU, 1e4), d, max_state=4096)
    with pytest.raises(InputError, match="exceed the state limit 64"):
        age_structured_plug(kin, feed, rtd.PlugFlow(TAU), d, max_state=64)


# ------------------------------------------------------------------ plug flow on the axis
@pytest.mark.parametrize("strong", [False, True])
def test_plug_flow_kappa_one_is_the_linear_classified_plug_flow(strong):
    """kappa = 1: plug flow with class i at d_i* u is eq. 4 with rates S/d* (exact, steady_mill);
    the extrapolated cells agree within the two estimates, the estimate below 1e-7."""
    from millflow.mill import steady_mill

    S, b, feed, d = _scene(strong=strong)
    one = kinetics(S, b, kappa_t=lambda t: 1.0)
    r = age_structured_plug(one, feed, rtd.PlugFlow(TAU), d, tol=1e-7)
    lin = steady_mill(S, b, feed, rtd.PlugFlow(TAU), d, locations=["discharge", "holdup"])
    assert _err(r, lin["product"].values, lin["holdup"].values) <= r.error_estimate + lin.attrs["error_estimate"]
    assert r.error_estimate < 1e-7
    assert abs(r.product.sum() - feed.sum()) < 1e-12 * feed.sum()  # breakage conserves mass; rounding


def test_plug_flow_without_classification_is_the_batch_grind_at_theta():
    """v = 1: every particle leaves at age tau, so the product is eq. 4 at theta(tau) =
    int_0^tau kappa = (tau / s) ln(1 + s) (exact); within the estimate."""
    from millflow.batch import batch_solve

    S, b, feed, _ = _scene()
    r = age_structured_plug(_slow(S, b), feed, rtd.PlugFlow(TAU), None, tol=1e-7)
    exact = batch_solve(S, b, feed, [TAU / S_SLOW * np.log1p(S_SLOW)]).M[0]
    assert np.abs(r.product - exact).max() <= r.error_estimate < 1e-7


@pytest.mark.parametrize("strong", [False, True])
def test_plug_flow_estimate_bounds_the_error_against_a_tighter_solve(strong):
    """Slowing-down with classification: the estimate at tol 1e-6 is at least the actual
    error against the solve at tol 1e-10 (more grids, tighter ODE: its own estimate is
    ~1e-11, below the tested error)."""
    S, b, feed, d = _scene(strong=strong)
    kin = _slow(S, b)
    r = age_structured_plug(kin, feed, rtd.PlugFlow(TAU), d, tol=1e-6)
    ref = age_structured_plug(kin, feed, rtd.PlugFlow(TAU), d, tol=1e-10)
    assert ref.error_estimate < 1e-10
    assert _err(r, ref.product, ref.info["holdup"]) <= r.error_estimate <= 1e-6


def test_plug_flow_entry_points_reach_it():
    S, b, feed, d = _scene()
    kin = _slow(S, b)
    for r in (nl.age_slowing(kin, feed, rtd.PlugFlow(TAU), d), nl.solve_transport(kin, feed, rtd.PlugFlow(TAU), d),
              nl.plug_flow(kin, feed, TAU, d)):
        assert "age-structured plug flow" in r.method


# ------------------------------------------------------------------ the open vessel
def _open(pe):
    return rtd.AxialDispersion(TAU, pe, bc="open")


@pytest.mark.parametrize("pe, discharge, dispersion", [(1.0, "flux", None), (10.0, "flux", None),
                                                       (1.0, "sampled", None), (10.0, "sampled", None),
                                                       (10.0, "flux", "varied")])
def test_open_kappa_one_is_the_linear_open_vessel(pe, discharge, dispersion):
    S, b, feed, d = _scene()
    w = None if dispersion is None else np.linspace(2.0, 0.5, S.size)  # unequal Peclet numbers: flux only
    one = kinetics(S, b, kappa_t=lambda t: 1.0)
    r = age_structured_open(one, feed, _open(pe), d, dispersion=w, discharge=discharge, tol=1e-6)
    lin = solve_axial_open(S, b, feed, TAU, pe, d=d, w=w, discharge=discharge, tol=1e-10)
    # two estimates of the same continuous mill (hold-up with the back-dispersion layer when
    # sampled): within the sum of the two estimates (the linear one's hold-up part is in
    # units of tau (1 + 2/Pe) >= tau, so it bounds hold-up / tau as well)
    assert _err(r, lin.product, lin.holdup) <= r.error_estimate + lin.error_estimate * (1.0 + 2.0 / pe)
    assert r.error_estimate < 1e-6


@pytest.mark.parametrize("pe", [1.0, 10.0])
def test_open_without_classification_is_segregated_flow_with_the_open_density(pe):
    S, b, feed, _ = _scene()
    kin, T = _slow(S, b), _open(pe)
    r = age_structured_open(kin, feed, T, None, discharge="sampled", tol=1e-6)
    # segregated flow over the open density E (what the sampled discharge measures); the
    # hold-up int (1 - F) exp(K theta) f dt against the sampled one with its back layer
    ref = nl.age_slowing(kin, feed, T, tol=1e-11)
    assert _err(r, ref.product, ref.info["holdup"]) <= r.error_estimate + ref.error_estimate
    assert r.error_estimate < 1e-6


@pytest.mark.parametrize("pe, strong", [(1.0, False), (10.0, True)])
def test_open_flux_mass_balance_and_estimate_against_a_tighter_solve(pe, strong):
    S, b, feed, d = _scene(strong=strong)
    kin, T = _slow(S, b), _open(pe)
    one = age_structured_open(kin, feed, T, d, discharge="flux", m_cells=32, rtol=1e-6)
    # the flux product is f + K int kappa U: the columns of K sum to zero, so on one grid the
    # mass balance closes to rounding whatever the grid and the ODE tolerance
    assert one.mass_balance_error < 1e-12 * feed.sum()
    r = age_structured_open(kin, feed, T, d, discharge="flux", tol=1e-5)
    # the refined product is extrapolated and clipped at 0 (refine_grids): within its estimate
    assert r.mass_balance_error <= r.error_estimate
    ref = age_structured_open(kin, feed, T, d, discharge="flux", tol=1e-8)
    assert _err(r, ref.product, ref.info["holdup"]) <= r.error_estimate + ref.error_estimate
    assert ref.error_estimate < 0.1 * r.error_estimate  # the reference is the tighter one


def test_open_entry_points_reach_it_and_its_refusals():
    S, b, feed, d = _scene()
    kin, T = _slow(S, b), _open(8.0)
    a = nl.age_slowing(kin, feed, T, d)  # the sampled discharge (the linear open vessel's default)
    assert "open axial dispersion (sampled discharge)" in a.method
    r = nl.solve_transport(kin, feed, T, d, where="axis", discharge="flux", tol=1e-6)
    assert "(flux discharge)" in r.method
    s = nl.solve_transport(kin, feed, T, d, where="axis", tol=1e-6)
    assert "(sampled discharge)" in s.method
    assert np.abs(a.product - s.product).max() <= a.error_estimate + s.error_estimate
    x = age_structured_axial(kin, feed, T, d, tol=1e-6)
    assert "(sampled discharge)" in x.method
    # the flux discharge without classification: not segregated flow with E, routed here too
    f = nl.solve_transport(kin, feed, T, discharge="flux", tol=1e-6)
    assert "(flux discharge)" in f.method
    with pytest.raises(InputError, match="same Peclet number"):
        age_structured_open(kin, feed, T, d, dispersion=np.ones(S.size), discharge="sampled")
    with pytest.raises(InputError, match="exceed the state limit 4096"):
        age_structured_open(kin, feed, _open(1e4), d, max_state=4096)
    with pytest.raises(InputError, match="bc='open'"):
        age_structured_open(kin, feed, rtd.AxialDispersion(TAU, 8.0), d)


def test_a_fixed_grid_reports_its_ode_and_tail_parts():
    """m_cells fixes the grid (the fit's forward model): the estimate is then the ODE's
    (tight against loose) and the tail's only, no grid part, and says so in info."""
    S, b, feed, d = _scene()
    r = age_structured_axial(_slow(S, b), feed, rtd.AxialDispersion(TAU, 5.0), d, m_cells=32)
    assert r.info["m_cells"] == 32 and r.info["grid_error"] == 0.0
    assert 0.0 < r.error_estimate == pytest.approx(r.info["ode_error"] + r.info["tail_error"], rel=1e-12)
