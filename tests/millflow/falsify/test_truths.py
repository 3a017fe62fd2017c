"""Truths of the falsification study: exact against the linear core (eqs. 3-6)."""
import math

import numpy as np
import pytest

from millflow.batch import batch_grind
from millflow.errors import InputError, SolverError
from millflow.falsify import (BREAKAGE_TRUTH, CallableTruth, LinearTruth, SlowingDownTruth, batch_design,
                              classification_truth, continuous_design, rtd_truth)
from millflow.fitting import ModelSpec
from millflow.fitting.models import ForwardModel

TIMES = [30.0, 60.0, 120.0, 240.0, 480.0]
# Two exact solvers of the same linear system (eigen recurrence vs batch_grind's clustered
# eigenbasis, or forward substitution vs the Mill's solver) agree to rounding amplified by the
# eigenvector condition, ~1e-13 here; 1e-11 leaves room for other BLAS paths.
EXACT = 1e-11


@pytest.fixture(scope="module")
def bdesign():
    return batch_design(TIMES, n_sieves=10)


@pytest.fixture(scope="module")
def cdesign():
    return continuous_design([30.0, 120.0, 480.0], n_sieves=10, extra_process={"screen_mm": [1.0, 1.0, 1.0]})


def test_slowing_down_at_kappa_one_is_the_linear_batch_grind(bdesign):
    tr = SlowingDownTruth(0.0)
    S, b, feed = tr.linear_parts(bdesign)
    ref = batch_grind(S[0], b, feed, np.array(TIMES))
    assert np.max(np.abs(tr.mass_fractions(bdesign) - ref)) <= EXACT
    # and the fitting package's own (vectorised) batch model at the same parameters
    lin = LinearTruth(ModelSpec(mode="batch"), BREAKAGE_TRUTH).mass_fractions(bdesign)
    assert np.max(np.abs(tr.mass_fractions(bdesign) - lin)) <= EXACT


def test_user_kappa_one_and_constant_kappa(bdesign):
    S, b, feed = SlowingDownTruth(0.0).linear_parts(bdesign)
    one = SlowingDownTruth(0.0, kappa=lambda t: 1.0)
    assert np.max(np.abs(one.mass_fractions(bdesign) - batch_grind(S[0], b, feed, np.array(TIMES)))) <= EXACT
    # constant kappa = c: the linear solution at c t
    half = SlowingDownTruth(0.0, kappa=lambda t: 0.5)
    assert np.max(np.abs(half.mass_fractions(bdesign) - batch_grind(S[0], b, feed, 0.5 * np.array(TIMES)))) <= EXACT


def test_default_kappa_theta_matches_quadrature(bdesign):
    s, T = 2.0, 480.0
    closed = SlowingDownTruth(s)
    quad = SlowingDownTruth(s, kappa=lambda t: 1.0 / (1.0 + s * t / T))
    t = np.array(TIMES)
    # closed form (T/s) ln(1 + s t/T) against adaptive quadrature at rtol 1e-12
    np.testing.assert_allclose(quad.theta(t, T), closed.theta(t, T), rtol=1e-11, atol=0)
    np.testing.assert_allclose(closed.theta(t, T), T / s * np.log1p(s * t / T), rtol=1e-14)
    assert np.max(np.abs(quad.mass_fractions(bdesign) - closed.mass_fractions(bdesign))) <= EXACT
    # slowing down: less ground than the linear batch at the same time
    lin = SlowingDownTruth(0.0).mass_fractions(bdesign)
    assert closed.mass_fractions(bdesign)[-1, 0] > lin[-1, 0]


def test_bad_kappa_is_a_solver_error(bdesign):
    with pytest.raises(SolverError, match="kappa"):
        SlowingDownTruth(0.0, kappa=lambda t: math.nan).mass_fractions(bdesign)
    with pytest.raises(InputError, match="strength"):
        SlowingDownTruth(-1.0)


def test_one_tank_is_the_perfectly_mixed_mill(cdesign):
    tis = rtd_truth("tanks_in_series", 1, BREAKAGE_TRUTH).mass_fractions(cdesign)
    wm = LinearTruth(ModelSpec(mode="well_mixed", tau_column="tau_s"), BREAKAGE_TRUTH).mass_fractions(cdesign)
    assert np.max(np.abs(tis - wm)) <= EXACT
    three = rtd_truth("tanks_in_series", 3, BREAKAGE_TRUTH).mass_fractions(cdesign)
    spec3 = ModelSpec(mode="well_mixed", tau_column="tau_s", n_tanks=3)
    wm3 = LinearTruth(spec3, BREAKAGE_TRUTH).mass_fractions(cdesign)
    assert np.max(np.abs(three - wm3)) <= EXACT
    np.testing.assert_allclose(three.sum(axis=1), 1.0, rtol=0, atol=1e-12)  # mass balance to rounding


def test_classification_strength_zero_is_no_classification(cdesign):
    c0 = classification_truth(0.0, BREAKAGE_TRUTH).mass_fractions(cdesign)
    wm = LinearTruth(ModelSpec(mode="well_mixed", tau_column="tau_s"), BREAKAGE_TRUTH).mass_fractions(cdesign)
    assert np.max(np.abs(c0 - wm)) <= EXACT
    # classification holds coarse material back: a finer product
    c2 = classification_truth(2.0, BREAKAGE_TRUTH).mass_fractions(cdesign)
    assert np.all(c2[:, 0] < wm[:, 0])


def test_axial_dispersion_truth_runs_and_conserves_mass(cdesign):
    M = rtd_truth("axial_dispersion", 8.0, BREAKAGE_TRUTH).mass_fractions(cdesign)
    np.testing.assert_allclose(M.sum(axis=1), 1.0, rtol=0, atol=1e-10)  # the mill's mass balance tolerance
    assert np.all(M >= -1e-14)


def test_passing_at_sieves_matches_the_fitting_model(bdesign):
    spec = ModelSpec(mode="batch")
    M = LinearTruth(spec, BREAKAGE_TRUTH).mass_fractions(bdesign)
    model = ForwardModel(spec, bdesign.data(), bdesign.grid)
    theta = np.array([BREAKAGE_TRUTH[n] for n in spec.param_names])
    # the same linear interpolation of cumulative passing; sieves are grid edges here
    assert np.max(np.abs(bdesign.passing_at_sieves(M).ravel() - model.predict(theta))) <= EXACT


def test_callable_truth_adapter(bdesign):
    S, b, feed = SlowingDownTruth(0.0).linear_parts(bdesign)
    tr = CallableTruth(lambda t: batch_grind(S[0], b, feed, t), BREAKAGE_TRUTH, name="ext")
    assert np.max(np.abs(tr.mass_fractions(bdesign) - SlowingDownTruth(0.0).mass_fractions(bdesign))) <= EXACT
    with pytest.raises(InputError, match="shape"):
        CallableTruth(lambda t: np.ones((len(t), 3)), {}).mass_fractions(bdesign)
    with pytest.raises(SolverError, match="sum to 1"):
        CallableTruth(lambda t: 0.9 * batch_grind(S[0], b, feed, t), {}).mass_fractions(bdesign)
    with pytest.raises(InputError, match="batch design"):
        CallableTruth(lambda t: None, {}).mass_fractions(continuous_design([60.0, 120.0]))


def test_bad_rtd_strength():
    with pytest.raises(InputError, match="integer >= 1"):
        rtd_truth("tanks_in_series", 2.5)
    with pytest.raises(InputError, match="truth.type"):
        rtd_truth("plug", 2)
