"""Batch grinding (eq. 4): analytic cases, high-precision references, properties, errors."""
import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from millflow import batch_grind
from millflow.batch import batch_solve, plug_flow_profile
from millflow.breakage import b_from_B, normalized_B
from millflow.errors import BreakageError, InputError

DATA = Path(__file__).parent.parent / "data"


def chain_b(n):
    """Every class breaks entirely into the next finer one."""
    b = np.zeros((n, n))
    b[np.arange(1, n), np.arange(n - 1)] = 1.0
    return b


def test_single_class_decays_exponentially():
    t = np.array([0.0, 0.1, 1.0, 10.0])
    M = batch_grind([3.0, 0.0], [[0, 0], [1, 0]], [1.0, 0.0], t)
    np.testing.assert_allclose(M[:, 0], np.exp(-3.0 * t), rtol=1e-14, atol=1e-300)
    np.testing.assert_allclose(M[:, 1], 1 - np.exp(-3.0 * t), rtol=1e-14, atol=1e-16)


def test_two_class_closed_form():
    # classes 1 -> 2 -> sink with S1 != S2: M2 = f1 S1 (e^{-S1 t} - e^{-S2 t})/(S2 - S1) + f2 e^{-S2 t}
    S1, S2, f1, f2 = 2.0, 0.5, 0.7, 0.3
    b = np.array([[0, 0, 0], [0.6, 0, 0], [0.4, 1, 0]])
    t = np.linspace(0, 5, 11)
    M = batch_grind([S1, S2, 0.0], b, [f1, f2, 0.0], t)
    M2 = 0.6 * f1 * S1 * (np.exp(-S1 * t) - np.exp(-S2 * t)) / (S2 - S1) + f2 * np.exp(-S2 * t)
    np.testing.assert_allclose(M[:, 0], f1 * np.exp(-S1 * t), atol=1e-15)
    np.testing.assert_allclose(M[:, 1], M2, atol=1e-15)
    np.testing.assert_allclose(M[:, 2], 1 - M[:, 0] - M[:, 1], atol=1e-15)


@pytest.mark.parametrize("n", [2, 5, 30, 100])
def test_equal_rates_chain_is_poisson(n):
    # equal rates, where Reid divides by zero: M_k(t) = e^{-St} (St)^k / k!
    S = np.r_[np.full(n - 1, 1.3), 0.0]
    feed = np.zeros(n)
    feed[0] = 1.0
    t = np.array([0.0, 0.2, 3.0, 40.0])
    M = batch_grind(S, chain_b(n), feed, t)
    for k in range(n - 1):
        expected = np.exp(-1.3 * t + k * np.log(np.maximum(1.3 * t, 1e-300)) - math.lgamma(k + 1))
        expected[t == 0] = 1.0 if k == 0 else 0.0
        np.testing.assert_allclose(M[:, k], expected, atol=1e-14)
    np.testing.assert_allclose(M.sum(axis=1), 1.0, atol=1e-13)


def test_nearly_equal_rates_match_equal_limit():
    n = 20
    S_eq = np.r_[np.full(n - 1, 0.8), 0.0]
    S_near = np.r_[0.8 * (1 + 1e-10 * np.arange(n - 1)), 0.0]
    feed = np.r_[1.0, np.zeros(n - 1)]
    t = np.linspace(0, 30, 7)
    M_eq = batch_grind(S_eq, chain_b(n), feed, t)
    M_near = batch_grind(S_near, chain_b(n), feed, t)
    np.testing.assert_allclose(M_near, M_eq, atol=1e-12)


def test_huge_and_tiny_St():
    n = 30
    x = 2.0 ** (-np.arange(n) / 2)
    b = b_from_B(normalized_B(x, 0.4, 0.8, 3.0))
    S = np.r_[1e6 * x[:-1], 0.0]
    feed = np.r_[1.0, np.zeros(n - 1)]
    M = batch_grind(S, b, feed, [1e-14, 1e6])
    np.testing.assert_allclose(M[0, 0], np.exp(-1e6 * 1e-14), rtol=1e-14)
    assert M[1, -1] == pytest.approx(1.0, abs=1e-13)
    np.testing.assert_allclose(M[1, :-1], 0.0, atol=1e-15)


@pytest.fixture(scope="module")
def reference():
    path = DATA / "batch_reference.json"
    if not path.exists():
        pytest.skip("tests/data/batch_reference.json missing: run tests/data/make_batch_reference.py")
    return json.loads(path.read_text())


@pytest.mark.parametrize("case", ["baseline", "stiff", "degenerate"])
def test_against_high_precision_reference(reference, case):
    ref = reference[case]
    M = batch_grind(ref["S"], ref["b"], ref["feed"], ref["t"])
    np.testing.assert_allclose(M, np.array(ref["M"]), rtol=0, atol=1e-13)
    assert M.min() >= -1e-15
    np.testing.assert_allclose(M.sum(axis=1), np.sum(ref["feed"]), atol=1e-13)


@pytest.mark.parametrize("method", ["BDF", "Radau", "LSODA"])
def test_ode_path_agrees_with_exact(method):
    n = 25
    x = 2.0 ** (-np.arange(n) / 4)
    b = b_from_B(normalized_B(x, 0.5, 1.0, 4.0))
    S = np.r_[0.8 * x[:-1] / x[0], 0.0]
    feed = np.r_[0.5, 0.5, np.zeros(n - 2)]
    t = np.array([0.0, 0.5, 2.0, 8.0])
    exact = batch_grind(S, b, feed, t)
    res = batch_solve(S, b, feed, t, method=method, rtol=1e-10, atol=1e-13)
    assert res.method == method
    np.testing.assert_allclose(res.M, exact, atol=1e-8)


def test_result_reports_method_error_and_time():
    res = batch_solve([1.0, 0.0], [[0, 0], [1, 0]], [1.0, 0.0], [1.0])
    assert res.method == "exact"
    assert 0 < res.error_estimate < 1e-13
    assert res.runtime_s > 0
    assert res.mass_balance_error < 1e-15


def test_plug_flow_profile_is_batch_at_contact_time():
    n = 15
    x = 2.0 ** (-np.arange(n) / 2)
    b = b_from_B(normalized_B(x, 0.4, 0.8, 3.0))
    S = np.r_[x[:-1], 0.0]
    feed = np.r_[1.0, np.zeros(n - 1)]
    y = np.array([0.0, 0.25, 1.0])
    profile = plug_flow_profile(S, b, feed, tau=4.0, positions=y)
    np.testing.assert_allclose(profile, batch_grind(S, b, feed, 4.0 * y), atol=0)
    np.testing.assert_allclose(profile[0], feed)


@st.composite
def kernels(draw):
    n = draw(st.integers(2, 25))
    rates = draw(st.lists(st.floats(1e-6, 1e6), min_size=n - 1, max_size=n - 1))
    S = np.r_[rates, 0.0]
    raw = np.tril(np.array(draw(st.lists(st.floats(0.0, 1.0), min_size=n * n, max_size=n * n))).reshape(n, n), -1)
    raw[-1, :-1] += 1e-3  # every column has somewhere to go
    b = raw / np.where(raw.sum(axis=0) > 0, raw.sum(axis=0), 1.0)
    feed = np.array(draw(st.lists(st.floats(0.0, 1.0), min_size=n, max_size=n)))
    feed = feed / feed.sum() if feed.sum() > 0 else np.r_[1.0, np.zeros(n - 1)]
    return S, b, feed


@settings(max_examples=60, deadline=None)
@given(kernels(), st.lists(st.floats(0.0, 1e3), min_size=1, max_size=5))
def test_properties_over_random_kernels(kernel, times):
    S, b, feed = kernel
    t = np.sort(np.array(times))
    M = batch_grind(S, b, feed, t)
    assert np.all(np.isfinite(M))
    assert M.min() >= -1e-13
    np.testing.assert_allclose(M.sum(axis=1), feed.sum(), atol=1e-12)
    # cumulative mass finer than each size never decreases with time
    fines = np.cumsum(M[:, ::-1], axis=1)
    assert np.all(np.diff(fines, axis=0) >= -1e-12)


@pytest.mark.parametrize(
    "S, b, feed, t, match",
    [
        ([1.0, -1.0, 0.0], np.tril(np.ones((3, 3)), -1) / [2, 1, 1], [1, 0, 0], 1.0, "class 2"),
        ([1.0, np.nan, 0.0], np.tril(np.ones((3, 3)), -1) / [2, 1, 1], [1, 0, 0], 1.0, "class 2"),
        ([1.0, 1.0, 0.5], np.tril(np.ones((3, 3)), -1) / [2, 1, 1], [1, 0, 0], 1.0, "sink"),
        ([1.0, 1.0, 0.0], np.tril(np.ones((3, 3)), -1), [1, 0, 0], 1.0, "sums to"),
        ([1.0, 1.0, 0.0], -np.tril(np.ones((3, 3)), -1) / [2, 1, 1], [1, 0, 0], 1.0, "expected >= 0"),
        ([1.0, 1.0, 0.0], np.ones((2, 2)), [1, 0, 0], 1.0, "shape"),
        ([1.0, 1.0, 0.0], np.tril(np.ones((3, 3)), -1) / [2, 1, 1], [1, 0], 1.0, "feed"),
        ([1.0, 1.0, 0.0], np.tril(np.ones((3, 3)), -1) / [2, 1, 1], [1, -0.1, 0], 1.0, "feed: class 2"),
        ([1.0, 1.0, 0.0], np.tril(np.ones((3, 3)), -1) / [2, 1, 1], [1, 0, 0], -1.0, "t"),
        ([1.0, 1.0, 0.0], np.tril(np.ones((3, 3)), -1) / [2, 1, 1], [1, 0, 0], np.inf, "t"),
    ],
)
def test_bad_input_gives_clear_error(S, b, feed, t, match):
    with pytest.raises((InputError, BreakageError), match=match):
        batch_grind(S, b, feed, t)


def test_unknown_method_lists_valid_ones():
    with pytest.raises(InputError, match="BDF"):
        batch_solve([1.0, 0.0], [[0, 0], [1, 0]], [1.0, 0.0], 1.0, method="euler")


def test_grind_and_flowsheet_results_say_which_kernel_ran():
    """Issue 16: every result says which kernel ran (compiled C or numpy)."""
    import millflow as mf
    from millflow.compiled import status
    from millflow.flowsheet import load, solve, summary, to_dataset
    from tests import paths
    g = mf.SizeGrid.geometric(top_m=2e-3, ratio=2 ** 0.25, n=20)
    ds = mf.grind(g, mf.PowerLawRate(A=0.02, alpha=1.0, x0=1e-3), mf.NormalizedBreakage(0.5, 0.8, 3.0),
                  np.r_[1.0, np.zeros(19)], [60.0])
    assert ds.attrs["kernel"] == status() and "eigenbasis=" in status()
    sol = solve(load(paths.FLOWSHEETS / "open_circuit_ball_mill.toml"))
    assert summary(sol)["kernel"] == status() and to_dataset(sol).attrs["kernel"] == status()
