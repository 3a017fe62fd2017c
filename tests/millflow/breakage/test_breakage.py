"""Tests of millflow.breakage: rate forms (eqs. 5, 7, 10), distributions (eqs. 6, 8)."""
import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from numpy.testing import assert_allclose, assert_array_equal

from millflow import breakage as bk
from millflow.errors import BreakageError
from millflow.grid import SizeGrid

# Two call paths to one formula: libm pow/exp may round differently between a SIMD
# path and a scalar one (array length, CPU), so 'the same' means a few ulps apart.
SAME = dict(rtol=1e-14, atol=0)

GRID = SizeGrid.geometric(4e-3, 2 ** 0.5, 12)


# ----------------------------------------------------------------------------- rates
def test_power_law_by_hand():
    S = bk.power_law_rates([2e-3, 1e-3, 5e-4, 2.5e-4], A=0.5, alpha=1.2, x0=1e-3)
    assert_allclose(S, [0.5 * 2 ** 1.2, 0.5, 0.5 * 0.5 ** 1.2, 0.0], rtol=1e-15)
    assert S[-1] == 0.0


def test_power_law_dataclass_matches_function_and_accepts_grid():
    m = bk.PowerLawRate(A=0.3, alpha=0.9, x0=1e-3)
    assert_allclose(m.rates(GRID), bk.power_law_rates(GRID.x, 0.3, 0.9, 1e-3), **SAME)
    assert_allclose(m(GRID), m.rates(GRID), **SAME)
    with pytest.raises(dataclasses.FrozenInstanceError):
        m.A = 1.0


def test_austin_by_hand():
    x = [2e-3, 1e-3, 5e-4]
    # x = mu0: correction 1/(1 + 1) = 1/2
    S = bk.austin_rates(x, A=1.0, alpha=1.0, mu0=1e-3, Lambda=2.0, x0=1e-3)
    assert S[1] == pytest.approx(0.5, rel=1e-15)
    assert S[0] == pytest.approx(2.0 / (1 + 4.0), rel=1e-15)
    assert S[-1] == 0.0
    # balls twice the reference: prefactor (1/2)^xi, mu = 2 mu0: S = 1 * 0.5 / (1 + 0.25)
    S = bk.austin_rates(x, A=1.0, alpha=1.0, mu0=1e-3, Lambda=2.0, xi=1.0, x_b=0.05, x_b0=0.025,
                        eta=1.0, x0=1e-3)
    assert S[1] == pytest.approx(0.4, rel=1e-15)


def test_austin_without_maximum_term_is_a_power_law():
    # Lambda = 0: the denominator is 2 everywhere
    S = bk.austin_rates(GRID, A=0.8, alpha=1.1, mu0=1e-3, Lambda=0.0, x0=1e-3)
    assert_allclose(S, bk.power_law_rates(GRID, 0.4, 1.1, 1e-3), rtol=1e-14)
    assert_allclose(bk.AustinRate(0.8, 1.1, 1e-3, 0.0, x0=1e-3)(GRID), S, **SAME)


def test_austin_rate_has_a_maximum():
    S = bk.austin_rates(SizeGrid.between(0.05, 1e-5, 2 ** 0.25), A=1.0, alpha=1.0, mu0=3e-3,
                        Lambda=3.0, x0=1e-3)
    k = int(np.argmax(S))
    assert 0 < k < S.size - 1


def test_process_power_law_by_hand():
    assert bk.process_power_law(2.0, [0.75, 4.0], [1.0, 0.5]) == pytest.approx(2.0 * 0.75 * 2.0, rel=1e-15)
    assert bk.process_power_law(2.0, {"speed": 0.75}, {"speed": 2.0}) == pytest.approx(1.125, rel=1e-15)
    m = bk.PowerLawRate.from_process(2.0, [0.5], [1.0], alpha=1.0)
    assert m.A == pytest.approx(1.0, rel=1e-15)


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda: bk.process_power_law(1.0, [0.5, -2.0], [1, 1]), r"process parameter params\[1\] = -2.0"),
        (lambda: bk.process_power_law(1.0, {"speed": 0.5}, {"ball": 1.0}), r"keys \['ball'\] must match"),
        (lambda: bk.process_power_law(1.0, [0.5], [1, 2]), r"1 values but exponents has 2"),
        (lambda: bk.power_law_rates(GRID, -1.0, 1.0, 1e-3), r"A = -1.0: expected >= 0"),
        (lambda: bk.power_law_rates(GRID, 1.0, np.nan, 1e-3), r"alpha = nan"),
        (lambda: bk.PowerLawRate(1.0, 1.0, x0=0.0), r"x0 = 0.0: expected > 0"),
        (lambda: bk.AustinRate(1.0, 1.0, mu0=-1e-3, Lambda=2.0), r"mu0 = -0.001"),
        (lambda: bk.AustinRate(1.0, 1.0, 1e-3, 2.0, x_b=0.05), r"give both ball sizes"),
    ],
)
def test_bad_rate_parameters(call, match):
    with pytest.raises(BreakageError, match=match):
        call()


@pytest.mark.parametrize(
    "S, match",
    [
        ([0.5, -0.1, 0.0], r"class 2 \(x = 0.002 m\) has rate -0.1 1/s; expected >= 0"),
        ([0.5, np.inf, 0.0], r"class 2 \(x = 0.002 m\) has rate inf"),
        ([0.5, 0.1, 0.2], r"class 3 \(x = 0.001 m\) is the sink and has rate 0.2"),
        ([0.5, 0.1], r"2 rates for a grid of 3 classes"),
    ],
)
def test_validate_rates_names_the_class(S, match):
    with pytest.raises(BreakageError, match=match):
        bk.validate_rates(S, [4e-3, 2e-3, 1e-3])


def test_tabulated_rate_and_user_callable():
    t = bk.TabulatedRate([0.3, 0.2, 0.1])
    assert_array_equal(t(GRID.x[:4]), [0.3, 0.2, 0.1, 0.0])  # N - 1 values: sink appended
    with pytest.raises(BreakageError, match=r"class 3 .* is the sink and has rate 0.1"):
        t(GRID.x[:3])
    with pytest.raises(BreakageError, match=r"has 3 rates; the grid has 12 classes"):
        t(GRID)
    with pytest.raises(BreakageError, match=r"class 2 has rate -0.2"):
        bk.TabulatedRate([0.3, -0.2])

    def my_rates(x):  # a user's own form plugs in like a built-in one
        S = 0.1 * (x / 1e-3) ** 2
        S[-1] = 0.0
        return S

    assert_allclose(bk.evaluate_rates(my_rates, GRID), my_rates(GRID.x.copy()))
    assert_allclose(bk.evaluate_rates(bk.PowerLawRate(1.0, 1.0), GRID), bk.PowerLawRate(1.0, 1.0)(GRID), **SAME)
    with pytest.raises(BreakageError, match=r"rates of <lambda>: class 12 .* is the sink"):
        bk.evaluate_rates(lambda x: 0.1 * x / x, GRID)


# --------------------------------------------------------------------- distributions
def test_normalized_B_by_hand():
    B = bk.normalized_B([4e-3, 2e-3, 1e-3, 5e-4], phi=0.5, gamma=1.0, beta=2.0)
    expected = np.array([
        [0, 0, 0, 0],
        [1, 0, 0, 0],
        [0.5 * 0.5 + 0.5 * 0.25, 1, 0, 0],
        [0.5 * 0.25 + 0.5 * 0.0625, 0.5 * 0.5 + 0.5 * 0.25, 1, 0],
    ])
    assert_allclose(B, expected, rtol=1e-15)
    b = bk.b_from_B(B)
    assert_allclose(b[:, 0], [0, 1 - 0.375, 0.375 - 0.15625, 0.15625], rtol=1e-15)
    assert_array_equal(b[:, -1], 0.0)  # the sink does not break


@given(
    n=st.integers(2, 80),
    ratio=st.sampled_from([2 ** 0.5, 2 ** 0.25, 2 ** 0.125, 1.7, 3.0]),
    phi=st.floats(0, 1),
    gamma=st.floats(0, 3),
    beta=st.floats(0, 8),
)
@settings(max_examples=200, deadline=None)
def test_columns_of_b_sum_to_one(n, ratio, phi, gamma, beta):
    g = SizeGrid.geometric(1e-2, ratio, n)
    B = bk.normalized_B(g, phi, gamma, beta)
    assert_array_equal(B[np.arange(1, n), np.arange(n - 1)], 1.0)  # B_{j+1,j} = 1
    b = bk.NormalizedBreakage(phi, gamma, beta).b(g)
    sums = b.sum(axis=0)
    assert np.all(np.abs(sums[:-1] - 1.0) <= 1e-14)
    assert sums[-1] == 0.0
    assert np.all(b >= 0) and np.all(np.triu(b) == 0)
    # with any rates, K = (b - I) diag(S) conserves mass: its columns sum to 0
    S = bk.power_law_rates(g, 1.0, 1.0, 1e-3)
    K = (b - np.eye(n)) * S
    assert np.all(np.abs(K.sum(axis=0)) <= 1e-14 * np.maximum(S, 1.0))


@given(phi=st.floats(0, 1), gamma=st.floats(0, 3), beta=st.floats(0, 8), n=st.integers(2, 30))
@settings(max_examples=60, deadline=None)
def test_eq8_with_theta_zero_is_eq6(phi, gamma, beta, n):
    g = SizeGrid.geometric(1e-2, 2 ** 0.25, n)
    assert_allclose(bk.non_normalized_B(g, phi, gamma, beta, theta=0.0), bk.normalized_B(g, phi, gamma, beta), **SAME)


def test_eq8_phi_depends_on_breaking_size():
    x = [4e-3, 2e-3, 1e-3]
    B = bk.non_normalized_B(x, phi0=0.4, gamma=1.0, beta=3.0, theta=0.5)  # x_max = x_1
    phi_1, phi_2 = 0.4, 0.4 * math.sqrt(2)
    assert B[2, 0] == pytest.approx(phi_1 * 0.5 + (1 - phi_1) * 0.125, rel=1e-15)
    assert B[2, 1] == 1.0 and B[1, 0] == 1.0
    assert_allclose(bk.NonNormalizedBreakage(0.4, 1.0, 3.0, 0.5).B(x), B, rtol=0)
    # phi_2 is used only through B_{3,2} = 1 here; check it on a longer grid
    B4 = bk.non_normalized_B([4e-3, 2e-3, 1e-3, 5e-4], 0.4, 1.0, 3.0, 0.5)
    assert B4[3, 1] == pytest.approx(phi_2 * 0.5 + (1 - phi_2) * 0.125, rel=1e-15)


def test_eq8_phi_above_one_names_the_class():
    with pytest.raises(BreakageError, match=r"phi_j = .* = 1.0196.* at class 28 \(x = 9.29068e-06 m\)"):
        bk.NonNormalizedBreakage(0.4, 0.8, 3.0, 0.2).B(SizeGrid.geometric(1e-3, 2 ** 0.25, 30))


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(phi=1.5, gamma=1.0, beta=3.0), r"phi = 1.5: expected a finite number in \[0, 1\]"),
        (dict(phi=0.5, gamma=-1.0, beta=3.0), r"gamma = -1.0"),
        (dict(phi=0.5, gamma=1.0, beta=np.nan), r"beta = nan"),
    ],
)
def test_bad_distribution_parameters(kwargs, match):
    with pytest.raises(BreakageError, match=match):
        bk.NormalizedBreakage(**kwargs)
    with pytest.raises(BreakageError, match=match):
        bk.normalized_B(GRID, **kwargs)


X3 = [4e-3, 2e-3, 1e-3]


@pytest.mark.parametrize(
    "b, match",
    [
        ([[0, 0, 0], [1.2, 0, 0], [-0.2, 1, 0]],
         r"receiving class 3 \(x = 0.001 m\) from breaking class 1 \(x = 0.004 m\) is -0.2; expected >= 0"),
        ([[0, 0, 0], [0.5, 0, 0], [0.4, 1, 0]], r"column of breaking class 1 \(x = 0.004 m\) sums to 0.9"),
        ([[0, 0.1, 0], [0.5, 0, 0], [0.5, 1, 0]],
         r"receiving class 1 .* from breaking class 2 .* is 0.1; expected 0 on and above"),
        ([[0, 0, 0], [0.5, 0, 0], [0.5, 1, 0.0], [0, 0, 0]], r"square"),
        ([[0, 0, 0], [np.nan, 0, 0], [0.5, 1, 0]], r"receiving class 2 .* is nan"),
    ],
)
def test_validate_b_names_classes(b, match):
    with pytest.raises(BreakageError, match=match):
        bk.validate_b(b, X3)
    with pytest.raises(BreakageError):
        bk.TabulatedBreakage(b=b)


@pytest.mark.parametrize(
    "B, match",
    [
        ([[0, 0, 0], [1, 0, 0], [1.2, 1, 0]], r"receiving class 3 .* breaking class 1 .* is 1.2; expected 0 <= B <= 1"),
        ([[0, 0, 0], [0.9, 0, 0], [0.5, 1, 0]], r"receiving class 2 .* is 0.9; expected B_\(j\+1,j\) = 1"),
        ([[0, 0, 0, 0], [1, 0, 0, 0], [0.3, 1, 0, 0], [0.4, 0.5, 1, 0]],
         r"receiving class 4 \(x = 0.0005 m\) from breaking class 1 .* is 0.4, above 0.3 .* must not increase"),
    ],
)
def test_validate_B_names_classes(B, match):
    with pytest.raises(BreakageError, match=match):
        bk.validate_B(B, X3 + [5e-4] if len(B) == 4 else X3)


def test_tabulated_breakage_roundtrip_and_user_callable():
    B = bk.normalized_B(GRID, 0.4, 0.9, 3.5)
    from_B = bk.TabulatedBreakage(B=B)
    from_b = bk.TabulatedBreakage(b=bk.b_from_B(B))
    assert_allclose(from_b.B(GRID), B, atol=1e-15)
    assert_allclose(from_B.b(GRID), bk.b_from_B(B), **SAME)
    assert_allclose(bk.B_from_b(bk.b_from_B(B)), B, atol=1e-15)
    with pytest.raises(BreakageError, match=r"is 12 x 12; the grid has 5 classes"):
        from_B.b(GRID.x[:5])
    with pytest.raises(BreakageError, match="exactly one of b= or B="):
        bk.TabulatedBreakage()
    # a published 3-digit table: loosen the column tolerance explicitly
    b3 = np.round(bk.b_from_B(B), 3)
    with pytest.raises(BreakageError, match="sums to"):
        bk.TabulatedBreakage(b=b3)
    assert bk.TabulatedBreakage(b=b3, tol=5e-3).b(GRID).shape == (12, 12)

    def my_b(x):  # everything broken goes to the next class
        return np.eye(len(x), k=-1)

    assert_array_equal(bk.evaluate_b(my_b, GRID), np.eye(12, k=-1))
    assert_allclose(bk.evaluate_b(bk.NormalizedBreakage(0.4, 0.9, 3.5), GRID), bk.b_from_B(B), **SAME)
    with pytest.raises(BreakageError, match="sums to 0.5"):
        bk.evaluate_b(lambda x: 0.5 * np.eye(len(x), k=-1), GRID)
