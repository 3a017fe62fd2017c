"""The compiled row recurrences (millflow/_eigenbasis.c) against their numpy versions.

The compiled kernel is optional: where it was not built, millflow.linalg runs the
numpy loops. Both must give the same basis to rounding, every solve must say which
one ran, and the fallback must still meet the references. CI sets
MILLFLOW_REQUIRE_COMPILED=1 so that a packaging change cannot lose the compiled
kernel without a failing test.
"""
import json
import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from millflow import linalg
from millflow.batch import batch_solve
from millflow.compiled import kernel as load_kernel

DATA = Path(__file__).parent.parent / "data"
EIGEN = load_kernel("eigenbasis")  # the built kernel (None where it was not built)
compiled = pytest.mark.skipif(EIGEN is None, reason="compiled kernel not built")


def test_kernel_is_compiled_where_required():
    if os.environ.get("MILLFLOW_REQUIRE_COMPILED") != "1":
        pytest.skip("MILLFLOW_REQUIRE_COMPILED is not set")
    assert linalg.kernel_name() == "compiled", "millflow._eigenbasis did not build or import"


def test_solves_report_the_kernel():
    res = batch_solve([1.0, 0.5, 0.0], np.tril(np.ones((3, 3)), -1) / [2, 1, 1], [1, 0, 0], [1.0])
    assert res.info["kernel"] == linalg.kernel_name()


@st.composite
def clustered_kernels(draw):
    """Random valid kernels whose rates repeat exactly, nearly or not at all."""
    n = draw(st.integers(2, 40))
    distinct = draw(st.lists(st.floats(1e-6, 1e6), min_size=1, max_size=n - 1))
    picks = draw(st.lists(st.integers(0, len(distinct) - 1), min_size=n - 1, max_size=n - 1))
    nudge = draw(st.lists(st.sampled_from([0.0, 1e-12, 1e-9, 1e-4]), min_size=n - 1, max_size=n - 1))
    S = np.r_[[distinct[p] * (1 + e) for p, e in zip(picks, nudge)], 0.0]
    raw = np.tril(np.array(draw(st.lists(st.floats(0.0, 1.0), min_size=n * n, max_size=n * n))).reshape(n, n), -1)
    raw[-1, :-1] += 1e-3
    b = raw / raw.sum(axis=0).clip(min=1e-300)
    b[:, -1] = 0.0
    return S, b


def _scale(X):
    return max(float(np.abs(X[np.isfinite(X)]).max(initial=1.0)), 1.0)


@compiled
@settings(max_examples=80, deadline=None)
@given(clustered_kernels(), st.sampled_from([1e-3, 0.05, 0.8, np.inf]))
def test_compiled_basis_equals_numpy_basis(kernel, gap):
    S, b = kernel
    A = linalg._minus_breakage_matrix(S, b)
    labels = linalg.cluster_rates(S, gap) if np.isfinite(gap) else np.zeros(S.size, dtype=int)
    if np.all(np.bincount(labels) == 1):
        X0 = linalg._eigenvectors_distinct_numpy(A, S)
        X1 = linalg._eigenvectors_distinct(A, S, EIGEN)
        np.testing.assert_allclose(X1, X0, rtol=0, atol=1e-12 * _scale(X0))
    else:
        X0, cc0, D0 = linalg._block_basis_numpy(A, S, labels)
        X1, cc1, D1 = linalg._block_basis(A, S, labels, EIGEN)
        np.testing.assert_array_equal(cc1, cc0)
        np.testing.assert_allclose(X1, X0, rtol=0, atol=1e-12 * _scale(X0))
        np.testing.assert_allclose(D1, D0, rtol=0, atol=1e-12 * _scale(D0))


@pytest.mark.parametrize("case", ["baseline", "stiff", "degenerate"])
def test_numpy_fallback_meets_the_references(case):
    path = DATA / "batch_reference.json"
    if not path.exists():
        pytest.skip("tests/data/batch_reference.json missing")
    ref = json.loads(path.read_text())[case]
    res = batch_solve(ref["S"], ref["b"], ref["feed"], ref["t"], kernel="numpy")
    assert res.info["kernel"] == "numpy"
    np.testing.assert_allclose(res.M, np.array(ref["M"]), rtol=0, atol=1e-13)
    assert res.M.min() >= -1e-15


@compiled
@pytest.mark.parametrize(
    "args, match",
    [
        ((np.eye(3), np.ones(3, dtype=np.float32), np.eye(3)), "S"),
        ((np.eye(2), np.ones(3), np.eye(3)), "A"),
        ((np.eye(3), np.ones(3), np.eye(3)[:, :2].copy()), "X"),
        ((np.eye(3), np.ones(3), np.asfortranarray(np.eye(3) + np.tri(3, k=-1))), "contiguous"),
    ],
)
def test_compiled_kernel_rejects_wrong_buffers(args, match):
    with pytest.raises((ValueError, BufferError), match=match):
        EIGEN.distinct(*args)


@compiled
def test_compiled_kernel_rejects_read_only_output():
    X = np.eye(3)
    X.flags.writeable = False
    with pytest.raises((ValueError, BufferError)):
        EIGEN.distinct(np.eye(3), np.array([3.0, 2.0, 0.0]), X)


@compiled
def test_compiled_clustered_kernel_rejects_unsorted_cluster_indices():
    S = np.array([1.0, 1.0, 1.0, 0.0])
    A = linalg._minus_breakage_matrix(S, np.tril(np.ones((4, 4)), -1) / [3, 2, 1, 1])
    cc = np.array([2, 0, 1], dtype=np.int64)
    with pytest.raises(ValueError, match="cc"):
        EIGEN.clustered(A, S, np.eye(4), cc, np.array([0, 0, 0, 1]), np.eye(3))


def test_kernel_choice_is_an_argument_checked_by_name():
    from millflow.errors import InputError

    with pytest.raises(InputError, match="kernel = 'fast'"):
        batch_solve([1.0, 0.0], [[0, 0], [1, 0]], [1.0, 0.0], [1.0], kernel="fast")
    res = batch_solve([1.0, 0.0], [[0, 0], [1, 0]], [1.0, 0.0], [1.0], kernel="numpy")
    assert res.info["kernel"] == "numpy"
