"""Tests of millflow.psd: fractions <-> cumulative passing, regridding, percentiles."""
import math
import warnings

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from hypothesis.extra.numpy import arrays
from numpy.testing import assert_allclose, assert_array_equal

from millflow import psd
from millflow.errors import GridError
from millflow.grid import SizeGrid

# Mass conservation: fractions are differences of one cumulative curve that starts at
# exactly 1, with the rounding residual put back; the sum is 1 to a few ulp.
MASS_TOL = 1e-14


fractions = st.integers(2, 60).flatmap(
    lambda n: arrays(float, n, elements=st.floats(0, 1, allow_nan=False)).filter(lambda a: a.sum() > 1e-3)
)


def _norm(a):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return psd.validate_fractions(a, normalize=True)


# ------------------------------------------------------------------------------- basics
def test_cum_passing_and_retained_by_hand():
    f = np.array([0.1, 0.2, 0.3, 0.4])
    assert_allclose(psd.cum_passing(f), [1.0, 0.9, 0.7, 0.4], rtol=1e-15)
    assert_allclose(psd.cum_retained(f), [0.1, 0.3, 0.6, 1.0], rtol=1e-15)
    assert_allclose(psd.retained([1.0, 0.9, 0.7, 0.4]), f, atol=1e-15)


@given(fractions)
@settings(max_examples=60, deadline=None)
def test_retained_inverts_cum_passing(a):
    f = _norm(a)
    back = psd.retained(psd.cum_passing(f))
    # fractions summing to 1 within SUM_TOL are accepted as they are; retained takes
    # P(x_1) = 1, so the input's own sum defect may move into class 1. Cumulative sums of
    # N terms carry up to ~N/2 ulps of 1 in rounding, which differencing returns as an
    # absolute error (a fresh machine found 1.4e-15 on 57 classes): atol N eps.
    assert_allclose(back, f, rtol=0, atol=f.size * np.finfo(float).eps + abs(f.sum() - 1.0))
    assert abs(back.sum() - 1.0) <= MASS_TOL


def test_normalize_is_explicit_and_warns():
    with pytest.raises(GridError, match=r"sum to 1.1.*normalize=True"):
        psd.validate_fractions([0.5, 0.6])
    with pytest.warns(UserWarning, match=r"summed to 1.1"):
        f = psd.validate_fractions([0.5, 0.6], normalize=True)
    assert_allclose(f, [0.5 / 1.1, 0.6 / 1.1], rtol=1e-15)
    assert abs(f.sum() - 1) <= MASS_TOL


@pytest.mark.parametrize(
    "frac, match",
    [
        ([0.5, -0.1, 0.6], r"class 2 \(x = 0.0005 m\) has fraction -0.1; expected >= 0"),
        ([0.5, np.nan, 0.5], r"class 2 \(x = 0.0005 m\) has fraction nan"),
        ([0.5, 0.3, 0.1], r"sum to 0.9"),
        ([0.5, 0.5], r"2 fractions for a grid of 3 classes"),
    ],
)
def test_bad_fractions_name_the_class(frac, match):
    g = SizeGrid.geometric(1e-3, 2.0, 3)
    with pytest.raises(GridError, match=match):
        psd.validate_fractions(frac, g)
    if len(frac) == 3:
        with pytest.raises(GridError, match=match.split(" \\(")[0]):
            psd.regrid(frac, g, g.refine(2))


@pytest.mark.parametrize(
    "cum, match",
    [
        ([1.0, 0.5, 0.7], r"rises from 0.5 to 0.7 at class 3"),
        ([1.0, np.nan, 0.2], r"class 2 is nan"),
        ([100.0, 80.0, 20.0], r"not percent"),
        ([0.9, 0.5, 0.2], r"top edge is 0.9"),
    ],
)
def test_bad_cumulative(cum, match):
    with pytest.raises(GridError, match=match):
        psd.retained(cum)


# ------------------------------------------------------------------------------ regrid
@given(fractions, st.integers(1, 5))
@settings(max_examples=60, deadline=None)
def test_reduction_to_subset_edges_is_exact(a, k):
    coarse = SizeGrid.geometric(2e-3, 2 ** 0.5, a.size)
    fine = coarse.refine(k)
    f_fine = psd.regrid(_norm(a), coarse, fine)
    back = psd.regrid(f_fine, fine, coarse)
    # exact up to re-summing the cumulative: a few ulp
    assert_allclose(back, _norm(a), atol=4e-16 * a.size)
    assert abs(f_fine.sum() - 1) <= MASS_TOL and abs(back.sum() - 1) <= MASS_TOL


@given(fractions, st.floats(0.3, 1.0), st.sampled_from([2 ** 0.5, 2 ** 0.25, 1.7]), st.integers(2, 40))
@settings(max_examples=80, deadline=None)
def test_regrid_conserves_mass_between_unaligned_grids(a, shift, ratio, n_to):
    src = SizeGrid.geometric(1e-3, 2 ** 0.25, a.size)
    dst = SizeGrid.geometric(1e-3 * (1 + shift), ratio, n_to)  # top above source top
    f = psd.regrid(_norm(a), src, dst)
    assert f.shape == (n_to,)
    assert np.all(f >= 0)
    assert abs(math.fsum(f) - 1) <= MASS_TOL and abs(f.sum() - 1) <= MASS_TOL


def test_regrid_sink_mass_stays_in_sink():
    src = SizeGrid.geometric(1e-3, 2.0, 3)  # sink below 2.5e-4
    dst = SizeGrid.geometric(1e-3, 2.0, 6)  # finer classes below 2.5e-4
    f = psd.regrid([0.2, 0.3, 0.5], src, dst)
    assert_allclose(f, [0.2, 0.3, 0, 0, 0, 0.5], atol=1e-16)


def test_regrid_top_below_source_needs_explicit_lump():
    src = SizeGrid.geometric(4e-3, 2.0, 4)
    dst = SizeGrid.geometric(2e-3, 2.0, 3)
    with pytest.raises(GridError, match=r"mass fraction 0.25 is coarser than the top edge 0.002 m"):
        psd.regrid([0.25, 0.25, 0.25, 0.25], src, dst)
    with pytest.warns(UserWarning, match="added to class 1"):
        f = psd.regrid([0.25, 0.25, 0.25, 0.25], src, dst, lump_top=True)
    assert_allclose(f, [0.5, 0.25, 0.25], atol=1e-16)


# --------------------------------------------------------------------------- sieves
SIEVES = np.array([2e-3, 1e-3, 5e-4, 2.5e-4, 1.25e-4])
PASSING = np.array([1.0, 0.8, 0.5, 0.3, 0.1])


def test_from_sieves_exact_at_sieves_and_sink_below():
    grid = SizeGrid.from_edges(SIEVES).refine(4)
    f = psd.from_sieves(SIEVES, PASSING, grid)
    assert abs(f.sum() - 1) <= MASS_TOL
    assert_allclose(psd.cum_passing(f)[::4], PASSING, atol=1e-15)
    assert f[-1] == pytest.approx(0.1, abs=1e-15)  # all mass below the smallest sieve
    # a grid reaching finer than the smallest sieve: the extra classes stay empty
    deep = SizeGrid.between(2e-3, 1e-5, 2 ** 0.25)
    g = psd.from_sieves(SIEVES, PASSING, deep)
    below = deep.x < SIEVES[-1]
    assert np.all(g[below][:-1] == 0) and g[-1] == pytest.approx(0.1, abs=1e-15)


@given(
    arrays(float, 8, elements=st.floats(0.0, 1.0)),
    st.integers(2, 8),
)
@settings(max_examples=80, deadline=None)
def test_pchip_is_monotone_and_stays_between_sieve_values(a, k):
    P = np.sort(a)[::-1]
    P[0] = 1.0
    grid = SizeGrid.geometric(1e-3, 2 ** 0.5, 8).refine(k)
    f = psd.from_sieves(SizeGrid.geometric(1e-3, 2 ** 0.5, 8).x, P, grid)
    assert np.all(f >= 0)  # a monotone cumulative gives no negative mass
    C = psd.cum_passing(f)
    for m in range(7):  # no overshoot between two sieves
        seg = C[m * k:(m + 1) * k + 1]
        assert np.all(seg <= P[m] + 1e-15) and np.all(seg >= P[m + 1] - 1e-15)


def test_from_sieves_oversize_is_error_unless_lumped():
    grid = SizeGrid.from_edges(SIEVES)
    cum = PASSING * 0.9
    with pytest.raises(GridError, match=r"mass fraction 0.1 is coarser than the top edge 0.002 m"):
        psd.from_sieves(SIEVES, cum, grid)
    with pytest.warns(UserWarning, match="0.1 coarser"):
        f = psd.from_sieves(SIEVES, cum, grid, oversize="lump")
    assert f[0] == pytest.approx(0.1 + 0.9 * 0.2, abs=1e-15)


@pytest.mark.parametrize(
    "sizes, cum, match",
    [
        ([1e-3, 2e-3], [1.0, 0.5], r"size_m\[1\]"),
        ([1e-3], [1.0], r"at least 2 sieve sizes"),
        ([2e-3, 1e-3, 5e-4], [1.0, 0.4, 0.6], r"rises from 0.4 to 0.6 at class 3 \(x = 0.0005 m\)"),
        ([2e-3, 1e-3], [100.0, 40.0], r"not percent"),
    ],
)
def test_from_sieves_bad_input(sizes, cum, match):
    with pytest.raises(GridError, match=match):
        psd.from_sieves(sizes, cum, SizeGrid.geometric(2e-3, 2.0, 4))


# ------------------------------------------------------------------------- percentiles
# Rosin-Rammler P(x) = 1 - exp(-(x/x63)^n): P80 = x63 (-ln 0.2)^(1/n), P50 = x63 (ln 2)^(1/n).
# Gates-Gaudin-Schuhmann P(x) = (x/k)^m: P80 = k 0.8^(1/m).
# Measured PCHIP-in-ln-x error of P80 (RR, x63 = 0.3 mm, n = 1.1): 1.6e-3 (ratio 2^(1/2)),
# 7.7e-5 (2^(1/4)), 1.6e-5 (2^(1/8)); the tolerances below leave a factor ~3.
@pytest.mark.parametrize("q, rtol", [(2, 5e-3), (4, 3e-4), (8, 5e-5)])
def test_p80_rosin_rammler(q, rtol):
    x63, n = 3e-4, 1.1
    grid = SizeGrid.between(4e-3, 1e-6, 2 ** (1 / q))
    P = 1 - np.exp(-(grid.x / x63) ** n)
    f = psd.retained(P / P[0])
    assert psd.p80(grid, f) == pytest.approx(x63 * (-math.log(0.2)) ** (1 / n), rel=rtol)
    assert psd.p50(grid, f) == pytest.approx(x63 * math.log(2) ** (1 / n), rel=rtol)


def test_p80_gates_gaudin_schuhmann_by_hand():
    k, m = 4e-3, 0.7  # top of the distribution at the grid top: P(x_1) = 1 exactly
    grid = SizeGrid.between(4e-3, 1e-6, 2 ** 0.25)
    f = psd.retained((grid.x / k) ** m)
    # 4e-3 * 0.8**(1/0.7) = 2.9092... mm by hand
    assert psd.percentile_size(grid, f, 80) == pytest.approx(k * 0.8 ** (1 / m), rel=2e-4)


def test_percentile_at_an_edge_is_exact():
    grid = SizeGrid.geometric(1e-3, 2.0, 4)
    assert psd.percentile_size(grid, [0.2, 0.3, 0.3, 0.2], 80) == 5e-4
    assert psd.percentile_size(grid, [0.2, 0.3, 0.3, 0.2], 100) == 1e-3


@pytest.mark.parametrize(
    "percent, match",
    [(10, r"P10 lies below the grid: 0.2 of the mass passes the finest edge 0.000125 m"),
     (0, r"percent = 0"), (120, r"percent = 120"), (np.nan, r"percent = nan")],
)
def test_percentile_outside_grid(percent, match):
    grid = SizeGrid.geometric(1e-3, 2.0, 4)
    with pytest.raises(GridError, match=match):
        psd.percentile_size(grid, [0.2, 0.3, 0.3, 0.2], percent)


@settings(max_examples=60)
@given(st.integers(0, 2**32 - 1), st.sampled_from([20.0, 50.0, 80.0, 95.0]))
def test_percentile_is_a_crossing_inside_its_bracketing_class(seed, percent):
    # rough random PSDs: whichever interpolant reads the crossing (the local cubic in ln x,
    # or PCHIP where that cubic is not monotone), the size lies between the two edges whose
    # cumulative passing brackets the percentile, and interpolating the cumulative passing
    # at that size gives the percentile back (to the root finder's tolerance, 1e-9 in P)
    grid = SizeGrid.between(4e-3, 1e-5, 2 ** 0.25)
    f = np.random.default_rng(seed).random(grid.n) ** 3
    f /= f.sum()
    P = psd.cum_passing(f)
    P[0] = 1.0
    q = percent / 100
    if P[-1] >= q:
        return
    k = int(np.flatnonzero(P >= q)[-1])
    got = psd.percentile_size(grid, f, percent)
    assert grid.x[k + 1] * (1 - 1e-12) <= got <= grid.x[k] * (1 + 1e-12)
    # the unchecked form for the library's own loops gives the same number
    assert psd.percentile_size(grid.x, f, percent, validate=False) == pytest.approx(got, rel=1e-14)


def test_cum_passing_at_arbitrary_sizes():
    grid = SizeGrid.geometric(1e-3, 2.0, 4)
    f = [0.2, 0.3, 0.3, 0.2]
    out = psd.cum_passing_at(grid, f, [2e-3, 5e-4, 1e-5])
    assert_array_equal(out, [1.0, 0.8, 0.2])  # 5e-4 is the edge of class 2: P = 0.3+0.3+0.2
