"""The fit's forward model calls the core, and agrees with its public entry points.

Issue 11 §1: the fit used to carry its own copies of eqs. 3-8 and of the screen curves.
Here, on random parameter sets (hypothesis), the fit's predictions on the grid are
compared with what a user gets from the public core: ``batch_grind`` (eq. 4),
``steady_mill`` with ``rtd.PerfectMixing`` (eq. 3), ``AustinRate`` / ``PowerLawRate``
(eqs. 5, 7), ``NormalizedBreakage`` (eq. 6) and the classifier curves, put on the grid
by ``breakage_on_grid`` and ``curve_on_grid`` (class averages on the default grid: the
core's O(N^2) quadrature, against the fit's separable O(N) form of the same integrals).

Tolerance: both sides are exact methods evaluated in double precision; they differ
only in the order of floating-point operations (vectorised over the population vs one
member). Mass fractions are <= 1 and the forward substitution of eq. 3 has relative
error ~ N eps (N <= 30 here, N eps ~ 7e-15); the eigenbasis of eq. 4 is accepted by
both only when its cancellation estimate is below 1e-13. So 1e-12 absolute bounds
rounding with a margin of ~10x, and anything larger would be a different equation.
"""
from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import rtd
from millflow import classifiers
from millflow.batch import batch_grind, batch_grind_population
from millflow.synthetic import make_batch_problem
from millflow.breakage import AustinRate, NormalizedBreakage, PowerLawRate
from millflow.breakage.averaged import breakage_on_grid, curve_on_grid
from millflow.fitting.data import psd_data_from_frames
from millflow.fitting.models import ForwardModel, ModelSpec
from millflow.grid import SizeGrid
from millflow.mill import steady_mill

ROUNDING = 1e-12  # see the module docstring: exact methods, different operation order

finite = dict(allow_nan=False, allow_infinity=False)


@settings(max_examples=25, deadline=None)
@given(ln_A0=st.floats(-6.0, 1.0, **finite), alpha=st.floats(-1.0, 2.5, **finite), phi=st.floats(0.0, 1.0, **finite),
       gamma=st.floats(0.1, 2.0, **finite), beta=st.floats(2.2, 8.0, **finite))
def test_batch_forward_model_is_batch_grind(ln_A0, alpha, phi, gamma, beta):
    """Eq. 4 with eq. 5 rates and eq. 6 breakage: the fit's batch mode is batch_grind."""
    model, _, _ = make_batch_problem(n_times=3, n_sieves=8, n_grid=20, noise=0.0)
    theta = np.array([ln_A0, alpha, phi, gamma, beta])
    got = model.predict_grid(theta[None])[0]
    S, b, how = breakage_on_grid(PowerLawRate(math.exp(ln_A0), alpha, x0=1e-3), NormalizedBreakage(phi, gamma, beta),
                                 model.grid)
    assert how == "class average"
    ref = batch_grind(S, b, model._feeds[0], model.times)
    np.testing.assert_allclose(got, ref, rtol=0, atol=ROUNDING)


def test_nearly_equal_rates_are_solved_exactly():
    """Regression: the fit's old private batch solve raised numpy's LinAlgError for
    nearly equal rates (|alpha| <= 1e-3 in eq. 5), inside the default bounds. The
    population solve hands such members to the clustered method of batch_grind."""
    model, _, _ = make_batch_problem(noise=0.0)  # the benchmark's 60-class grid
    thetas = np.array([[-3.0, a, 0.4, 0.8, 3.5] for a in (0.0, 1e-9, -1e-6, 1e-4, 1e-3, 1.0)]
                      # this member made the old code raise LinAlgError ("Singular matrix")
                      + [[-2.67994691e-01, -4.53128896e-09, 9.31520644e-01, 5.13791569e-01, 5.95892768e+00]])
    got = model.predict_grid(thetas)
    for k, th in enumerate(thetas):
        S, b, _ = breakage_on_grid(PowerLawRate(math.exp(th[0]), th[1], x0=1e-3), NormalizedBreakage(*th[2:]),
                                   model.grid)
        ref = batch_grind(S, b, model._feeds[0], model.times)
        np.testing.assert_allclose(got[k], ref, rtol=0, atol=ROUNDING)
        # mass is conserved to rounding (feed total 1) even where Reid's form divides by ~0
        assert np.abs(got[k].sum(axis=1) - 1.0).max() < 1e-12


def test_population_batch_marks_members_outside_the_domain_and_solves_the_rest():
    x = SizeGrid.geometric(4e-3, 2 ** 0.5, 10).x
    b = NormalizedBreakage(0.4, 0.8, 3.0)(x)
    S = np.array([PowerLawRate(0.1, 1.0)(x), np.full(10, np.nan), PowerLawRate(0.1, 0.0)(x)])
    M = batch_grind_population(S, b, np.r_[1.0, np.zeros(9)], [0.0, 10.0])
    assert np.isnan(M[1]).all()
    for k in (0, 2):
        np.testing.assert_allclose(M[k], batch_grind(S[k], b, np.r_[1.0, np.zeros(9)], [0.0, 10.0]),
                                   rtol=0, atol=ROUNDING)


def _well_mixed_data(n=14, screens=(1.0, 2.0), balls=None):
    x = SizeGrid.geometric(4e-3, 2 ** 0.5, n).x
    rows = [pd.DataFrame({"condition": "*", "location": "feed", "size_m": x[:2], "passing": [1.0, 0.0]})]
    proc = {"condition": [], "screen_mm": [], "tau_s": []}
    for k, scr in enumerate(screens):
        for loc in ("product", "holdup"):
            rows.append(pd.DataFrame({"condition": f"c{k}", "location": loc, "size_m": x,
                                      "passing": np.linspace(1, 0, n)}))
        proc["condition"].append(f"c{k}")
        proc["screen_mm"].append(scr)
        proc["tau_s"].append(60.0 * (k + 1))
    if balls is not None:
        proc["ball_mm"] = list(balls)
    return x, psd_data_from_frames(pd.concat(rows), pd.DataFrame(proc))


@settings(max_examples=25, deadline=None)
@given(ln_A0=st.floats(-6.0, 0.0, **finite), alpha=st.floats(-1.0, 2.5, **finite),
       ln_mu=st.floats(-2.0, 2.0, **finite), Lam=st.floats(0.5, 6.0, **finite), phi=st.floats(0.0, 1.0, **finite),
       gamma=st.floats(0.1, 2.0, **finite), beta=st.floats(2.2, 8.0, **finite), ln_c50=st.floats(-3.0, 1.0, **finite),
       ln_sharp=st.floats(-1.0, 3.0, **finite))
def test_well_mixed_forward_model_is_steady_mill(ln_A0, alpha, ln_mu, Lam, phi, gamma, beta, ln_c50, ln_sharp):
    """Eq. 3 with eq. 7 rates, eq. 6 breakage and the screen curve: the fit's well-mixed
    mode is steady_mill(PerfectMixing(tau)) with classifiers.screen_discharge, product
    and hold-up, condition by condition."""
    x, data = _well_mixed_data()
    spec = ModelSpec(mode="well_mixed", rate="austin", breakage="normalized", classification="screen",
                     tau_column="tau_s")
    m = ForwardModel(spec, data, SizeGrid(x))
    theta = np.array([ln_A0, alpha, ln_mu, Lam, phi, gamma, beta, ln_c50, ln_sharp])
    got = m.predict_grid(theta[None])[0]
    S, b, _ = breakage_on_grid(AustinRate(math.exp(ln_A0), alpha, math.exp(ln_mu) * 1e-3, Lam, x0=1e-3),
                               NormalizedBreakage(phi, gamma, beta), m.grid)
    for g, (c, loc, _) in enumerate(m.groups):
        screen = m._proc["screen_mm"][c] * 1e-3
        d = curve_on_grid(lambda y: classifiers.screen_discharge(y, math.exp(ln_c50) * screen, math.exp(ln_sharp)),
                          m.grid)
        np.testing.assert_allclose(m.discharge(m._unpack(theta[None]), 1)[0, c], d, rtol=0, atol=ROUNDING)
        ds = steady_mill(S, b, m._feeds[c], rtd.PerfectMixing(m._proc["tau_s"][c]), d)
        ref = ds["product"].values if loc == "product" else ds["holdup_fraction"].values
        np.testing.assert_allclose(got[g], ref, rtol=0, atol=ROUNDING)


def test_screen_curves_are_the_classifier_module():
    """d* of the screen is one minus the corrected Tromp curve; screen_power is its
    limit for d50 far below the sizes (then (x/d50)^-n)."""
    x = SizeGrid.geometric(4e-3, 2 ** 0.5, 12).x
    d = classifiers.screen_discharge(x, 1e-3, 3.0)
    np.testing.assert_allclose(d, 1.0 - classifiers.tromp(x, 1e-3, 3.0), rtol=0, atol=ROUNDING)
    far = classifiers.screen_discharge(x, 1e-9, 2.0)
    np.testing.assert_allclose(far, classifiers.screen_power_discharge(x, 2.0, 1e-9), rtol=1e-9)
    # population axes broadcast: (P, C) parameters give (P, C, N)
    assert classifiers.screen_discharge(x, np.full((3, 2), 1e-3), np.ones((3, 1))).shape == (3, 2, 12)


@pytest.mark.parametrize("scalar, population, kwargs", [
    ("power_law_rates", "power_law_rates_population", dict(A=0.3, alpha=1.2, x0=2e-3)),
    ("austin_rates", "austin_rates_population",
     dict(A=0.3, alpha=1.2, mu0=2e-3, Lambda=3.0, xi=0.5, x_b=0.05, x_b0=0.03, eta=0.7)),
])
def test_rate_population_rows_are_the_scalar_forms(scalar, population, kwargs):
    from millflow.breakage import rates
    x = SizeGrid.geometric(8e-3, 2 ** 0.5, 12).x
    one = getattr(rates, scalar)(x, **kwargs)
    many = getattr(rates, population)(x, **{k: np.full((4, 3), v) for k, v in kwargs.items()})
    assert many.shape == (4, 3, 12)
    np.testing.assert_allclose(many[2, 1], one, rtol=1e-15, atol=0)  # the same expression


@settings(max_examples=15, deadline=None)
@given(xi=st.floats(-1.5, 1.5, **finite), eta=st.floats(-1.5, 1.5, **finite), theta=st.floats(-0.3, 0.0, **finite),
       phi=st.floats(0.05, 0.6, **finite))
def test_ball_terms_and_non_normalized_b_are_the_core(xi, eta, theta, phi):
    """Issue 15 §3: eq. 7 with its ball-size terms (rate "austin_ball") and eq. 8
    (breakage "non_normalized") are fitted forms, evaluated by the core's AustinRate
    and NonNormalizedBreakage: same numbers to rounding."""
    from millflow.breakage import NonNormalizedBreakage
    x, data = _well_mixed_data(screens=(1.0, 2.0, 1.5), balls=(20.0, 40.0, 30.0))
    spec = ModelSpec(mode="well_mixed", rate="austin_ball", breakage="non_normalized", tau_column="tau_s")
    m = ForwardModel(spec, data, SizeGrid(x))
    assert m.param_names == ("ln_A0", "alpha", "ln_mu", "Lambda", "xi", "eta", "phi", "gamma", "beta", "theta")
    theta_v = np.array([-3.0, 1.0, 0.5, 3.0, xi, eta, phi, 0.8, 3.5, theta])
    got = m.predict_grid(theta_v[None])[0]
    ref_ball = math.exp(np.log([20.0, 40.0, 30.0]).mean()) * 1e-3
    for g, (c, loc, _) in enumerate(m.groups):
        ball = [20e-3, 40e-3, 30e-3][c]
        S, b, _ = breakage_on_grid(AustinRate(math.exp(-3.0), 1.0, math.exp(0.5) * 1e-3, 3.0, xi=xi, x_b=ball,
                                              x_b0=ref_ball, eta=eta), NonNormalizedBreakage(phi, 0.8, 3.5, theta),
                                   m.grid)
        ds = steady_mill(S, b, m._feeds[c], rtd.PerfectMixing(m._proc["tau_s"][c]))
        ref = ds["product"].values if loc == "product" else ds["holdup_fraction"].values
        np.testing.assert_allclose(got[g], ref, rtol=0, atol=ROUNDING)


def test_ball_terms_and_theta_are_recovered_by_a_fit():
    """Noise-free synthetic product and hold-up samples at three ball sizes: a local fit
    from a perturbed start recovers xi, eta (eq. 7) and theta (eq. 8) with the other
    parameters held at their truth."""
    from millflow.fitting.estimate import fit
    from millflow.fitting.models import default_parameters
    x, placeholder = _well_mixed_data(n=16, screens=(1.0, 2.0, 1.5), balls=(20.0, 40.0, 30.0))
    spec = ModelSpec(mode="well_mixed", rate="austin_ball", breakage="non_normalized", tau_column="tau_s")
    m0 = ForwardModel(spec, placeholder, SizeGrid(x))
    truth = dict(ln_A0=-4.0, alpha=1.0, ln_mu=1.0, Lambda=3.0, xi=0.8, eta=-0.6, phi=0.4, gamma=0.8, beta=3.5,
                 theta=-0.2)
    y = m0.predict_cum(np.array([truth[n] for n in m0.param_names]))
    t = placeholder.table.copy()
    samples = t.location != "feed"
    t.loc[samples, "passing"] = y
    data = psd_data_from_frames(t.drop(columns=[c for c in t.columns if c not in
                                                ("condition", "location", "size_m", "passing")]),
                                placeholder.process.reset_index(), strict=False)
    m = ForwardModel(spec, data, SizeGrid(x))
    start = {"xi": 0.3, "eta": 0.0, "theta": -0.05}
    over = {n: ({"value": start[n]} if n in start else {"value": truth[n], "vary": False}) for n in m.param_names}
    res = fit(m, default_parameters(spec, over), global_search=False, starts=1, grid_check=False)
    for n in start:
        # noise-free data: the optimum is the truth; 1e-5 allows the optimiser's tolerance
        assert res.params[n].value == pytest.approx(truth[n], abs=1e-5), n


@settings(max_examples=25, deadline=None)
@given(phi=st.floats(0.0, 1.0, **finite), gamma=st.floats(0.05, 4.0, **finite), beta=st.floats(0.05, 10.0, **finite),
       ln_A=st.floats(-8.0, 3.0, **finite), alpha=st.floats(-2.0, 4.0, **finite), n=st.integers(2, 60),
       log2_ratio=st.sampled_from([1 / 16, 1 / 4, 1 / 2, 1.0]))
def test_geometric_grid_recurrence_is_the_matrix_substitution(phi, gamma, beta, ln_A, alpha, n, log2_ratio):
    """Eq. 3 with eq. 6 on a geometric grid by O(N) recurrences equals the forward
    substitution with the b matrix of breakage_population. Both sum non-negative terms
    in a different order: the difference is rounding, a few N eps relative to the
    largest flow (feeds sum to 1 here, so 1e-12 absolute, N <= 60)."""
    from millflow.breakage import breakage_population, power_law_rates_population
    from millflow.mill.well_mixed import well_mixed_population, well_mixed_population_geometric
    x = SizeGrid.geometric(1e-2, 2 ** log2_ratio, n).x
    S = power_law_rates_population(x, math.exp(ln_A), alpha, 1e-3)
    feed = np.linspace(1.0, 0.0, n) ** 2
    feed /= feed.sum()
    d = classifiers.screen_discharge(x, 2e-3, 3.0)
    ref = well_mixed_population(S, breakage_population(x, phi, gamma, beta, kind="b"), feed, 30.0, d)
    got = well_mixed_population_geometric(S, feed, phi, gamma, beta, x[0] / x[1], 30.0, d)
    np.testing.assert_allclose(got, ref, rtol=0, atol=ROUNDING)


@settings(max_examples=25, deadline=None)
@given(phi=st.floats(0.0, 1.0, **finite), gamma=st.floats(0.05, 4.0, **finite), beta=st.floats(0.05, 10.0, **finite),
       theta=st.floats(-0.3, 0.0, **finite), ln_A=st.floats(-8.0, 3.0, **finite), alpha=st.floats(-2.0, 4.0, **finite),
       n=st.integers(2, 60), log2_ratio=st.sampled_from([1 / 16, 1 / 4, 1 / 2, 1.0]))
def test_class_averaged_recurrence_is_the_matrix_substitution(phi, gamma, beta, theta, ln_A, alpha, n, log2_ratio):
    """Eq. 3 with class-averaged eqs. 6/8 on a geometric grid by the O(N) recurrences of
    well_mixed_population_separable equals the forward substitution with the class-averaged
    b of the core (averaged_breakage). Non-negative terms summed in another order, and the
    quadrature's weights combined in another order: rounding only (1e-12, feeds sum to 1)."""
    from millflow.breakage import NonNormalizedBreakage
    from millflow.breakage.averaged import averaged_breakage, averaged_power_terms, node_sizes
    from millflow.breakage.rates import power_law_rates_population
    from millflow.mill.well_mixed import well_mixed_population, well_mixed_population_separable
    x = SizeGrid.geometric(1e-2, 2 ** log2_ratio, n).x
    rate = PowerLawRate(math.exp(ln_A), alpha, 1e-3)
    brk = NonNormalizedBreakage(phi, gamma, beta, theta) if phi * (x[0] / x[-1]) ** -theta <= 1 else \
        NormalizedBreakage(phi, gamma, beta)
    S, b = averaged_breakage(rate, brk, x)
    feed = np.linspace(1.0, 0.0, n) ** 2
    feed /= feed.sum()
    d = curve_on_grid(lambda y: classifiers.screen_discharge(y, 2e-3, 3.0), x)
    ref = well_mixed_population(S, b, feed, 30.0, d)
    yy = node_sizes(x)
    S_nodes = power_law_rates_population(np.append(yy, yy[-1] / 2), math.exp(ln_A), alpha, 1e-3)[:-1]
    th = getattr(brk, "theta", 0.0)
    S2, a1, a2 = averaged_power_terms(x, S_nodes, phi, gamma, beta, th)
    R = x[0] / x[1] if n > 1 else 2.0
    c1, c2 = R ** -gamma, R ** -beta
    got = well_mixed_population_separable(S2, feed, c1 * a1, c1, c2 * a2, c2, 30.0, d)
    np.testing.assert_allclose(S2, S, rtol=1e-12, atol=0)
    np.testing.assert_allclose(got, ref, rtol=0, atol=ROUNDING)
