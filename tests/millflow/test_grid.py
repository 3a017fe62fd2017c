"""Tests of millflow.grid: construction, refinement and validation of size grids."""
import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from numpy.testing import assert_allclose, assert_array_equal

from millflow.errors import GridError
from millflow.grid import SizeGrid, as_sizes, class_label


def test_geometric_values_by_hand():
    g = SizeGrid.geometric(1e-3, 2.0, 4)
    assert_allclose(g.x, [1e-3, 5e-4, 2.5e-4, 1.25e-4], rtol=1e-15)
    assert g.n == 4 and len(g) == 4
    assert g.ratio == pytest.approx(2.0, rel=1e-14)
    assert_allclose(g.lower_m, [5e-4, 2.5e-4, 1.25e-4, 0.0], rtol=1e-15)


def test_representative_size_is_upper_edge():
    g = SizeGrid.from_edges([4e-3, 2e-3, 1e-3])
    assert g.x is g.upper_m
    assert_array_equal(g.x, [4e-3, 2e-3, 1e-3])


def test_from_edges_drops_trailing_zero_and_non_geometric_ratio_is_none():
    g = SizeGrid.from_edges([3e-3, 2e-3, 1e-3, 0.0])
    assert g.n == 3
    assert g.ratio is None


def test_between_lands_on_bottom_when_power_of_ratio():
    g = SizeGrid.between(1.2e-3, 37.5e-6, 2 ** 0.5)  # 1.2 mm / 37.5 um = 32 = sqrt2^10
    assert g.n == 11
    assert g.x[-1] == 37.5e-6
    assert g.x[0] == 1.2e-3


def test_between_goes_at_least_to_bottom_otherwise():
    g = SizeGrid.between(1e-3, 38e-6, 2 ** 0.5)
    assert g.x[-1] <= 38e-6 < g.x[-2]


@given(k=st.integers(1, 6), n=st.integers(2, 30), q=st.sampled_from([2, 4, 8]))
@settings(max_examples=40, deadline=None)
def test_refine_keeps_edges_and_splits_ratio(k, n, q):
    g = SizeGrid.geometric(2e-3, 2 ** (1 / q), n)
    r = g.refine(k)
    assert r.n == (n - 1) * k + 1
    # the original edges survive bit for bit (exact reduction back to g relies on it)
    assert_array_equal(r.x[::k], g.x)
    assert r.ratio == pytest.approx(2 ** (1 / (q * k)), rel=1e-12)


def test_refine_non_geometric_splits_each_interval():
    g = SizeGrid.from_edges([8e-3, 2e-3, 1e-3])
    r = g.refine(2)
    assert_allclose(r.x, [8e-3, 4e-3, 2e-3, math.sqrt(2) * 1e-3, 1e-3], rtol=1e-15)


def test_frozen_and_read_only():
    g = SizeGrid.geometric(1e-3, 2.0, 3)
    with pytest.raises(dataclasses.FrozenInstanceError):
        g.upper_m = np.array([1.0])
    with pytest.raises(ValueError):
        g.upper_m[0] = 5.0


def test_equality_hash_repr():
    a = SizeGrid.geometric(1e-3, 2.0, 3)
    b = SizeGrid.from_edges([1e-3, 5e-4, 2.5e-4])
    assert a == b and hash(a) == hash(b)
    assert "n=3" in repr(a) and "ratio=2" in repr(a)


def test_size_coord_has_units():
    c = SizeGrid.geometric(1e-3, 2.0, 3).size_coord()
    assert c.dims == ("size",) and c.attrs["units"] == "m"


@pytest.mark.parametrize(
    "edges, match",
    [
        ([1e-3, 2e-3], r"upper_m\[1\] \(edge 2\) = 0.002 m is not below"),
        ([1e-3, 1e-3], r"upper_m\[1\] \(edge 2\)"),
        ([1e-3, -1e-4], r"upper_m\[1\] \(edge 2\) = -0.0001 m: sizes must be > 0"),
        ([1e-3, np.nan], r"upper_m\[1\] \(edge 2\) = nan: sizes must be finite"),
        ([[1e-3]], r"1-D"),
        ([], r"non-empty"),
    ],
)
def test_bad_edges_name_index_and_value(edges, match):
    with pytest.raises(GridError, match=match):
        SizeGrid(edges)


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda: SizeGrid.geometric(1e-3, 1.0, 5), r"ratio = 1.0"),
        (lambda: SizeGrid.geometric(1e-3, 0.5, 5), r"ratio = 0.5"),
        (lambda: SizeGrid.geometric(-1e-3, 2.0, 5), r"top_m = -0.001"),
        (lambda: SizeGrid.geometric(1e-3, 2.0, 0), r"n = 0"),
        (lambda: SizeGrid.between(1e-3, 2e-3, 2.0), r"bottom_m = 0.002"),
        (lambda: SizeGrid.geometric(1e-3, 2.0, 3).refine(0), r"k = 0"),
        (lambda: SizeGrid.from_edges([1e-3, 2e-3, 0.0]), r"edges_m\[1\]"),
    ],
)
def test_bad_constructor_arguments(call, match):
    with pytest.raises(GridError, match=match):
        call()


def test_as_sizes_and_labels():
    g = SizeGrid.geometric(1e-3, 2.0, 3)
    assert as_sizes(g) is g.x
    assert_array_equal(as_sizes([3.0, 2.0]), [3.0, 2.0])
    with pytest.raises(GridError, match=r"x\[1\]"):
        as_sizes([1.0, 2.0])
    assert class_label(6, np.full(8, 1.2e-4)) == "class 7 (x = 0.00012 m)"
    assert g.label(0) == "class 1 (x = 0.001 m)"


def test_grids_beyond_the_memory_budget_are_refused_before_allocation(monkeypatch):
    """Issue 10 §2: n = 100000 asked for 74.5 GiB and ratio 1.0000001 for 31.7 PiB; now a
    GridError says what it would need (nothing of that size is allocated)."""
    import pytest

    from millflow.errors import GridError
    with pytest.raises(GridError, match=r"1e\+05 classes needs 74\.5 GiB .* budget of 4 GiB"):
        SizeGrid.geometric(1e-3, 1.01, 100000)
    with pytest.raises(GridError, match=r"ratio 1\.0000001\) needs .* GiB"):
        SizeGrid.between(1e-2, 1e-5, 1.0000001)
    with pytest.raises(GridError, match=r"refine\(100000\)"):
        SizeGrid.geometric(1e-3, 2.0, 10).refine(100000)
    monkeypatch.setenv("MILLFLOW_MEMORY_BUDGET_GB", "1e-6")  # about 1 kB: 11 classes pass, 12 do not
    assert SizeGrid.geometric(1e-3, 2.0, 11).n == 11
    with pytest.raises(GridError, match="MILLFLOW_MEMORY_BUDGET_GB"):
        SizeGrid.geometric(1e-3, 2.0, 12)
