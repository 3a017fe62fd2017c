"""The compiled class loop of a row of cells (millflow/_cells.c) against numpy's gtsv loop.

Rows of cells with back-mixing (rtd.RecirculatingCells) are solved class by class; the
compiled loop (Thomas elimination) and the numpy loop (LAPACK gtsv per class) must
agree to rounding for every classification and feed shape, and the mill must say
which ran.
"""
import os

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import rtd
from millflow import steady_mill
from millflow.mill import cells as mill_cells
from millflow.breakage import b_from_B, normalized_B
from millflow.compiled import kernel as load_kernel

CELLS = load_kernel("cells")  # the built kernel (None where it was not built)
compiled = pytest.mark.skipif(CELLS is None, reason="compiled kernel not built")


def _kernel(n_cls=30):
    x = 2.0 ** (-np.arange(n_cls) / 2)
    b = b_from_B(normalized_B(x, 0.4, 0.8, 3.0))
    S = np.r_[0.05 * (x[:-1] / x[0]) ** 1.2, 0.0]
    return x, S, b


def test_kernel_is_compiled_where_required():
    if os.environ.get("MILLFLOW_REQUIRE_COMPILED") != "1":
        pytest.skip("MILLFLOW_REQUIRE_COMPILED is not set")
    assert CELLS is not None, "millflow._cells did not build or import"


def test_mill_reports_the_cells_kernel():
    x, S, b = _kernel()
    ds = steady_mill(S, b, np.r_[1.0, np.zeros(S.size - 1)], rtd.RecirculatingCells(60.0, 4, r=0.5))
    assert ds.attrs["method"] == "cells"
    assert ds.attrs["kernel"] == ("compiled" if CELLS is not None else "numpy")


@compiled
@settings(max_examples=60, deadline=None)
@given(
    n_cells=st.integers(3, 40),
    r=st.floats(0.0, 20.0),
    dead=st.floats(0.0, 0.5),
    bypass=st.floats(0.0, 0.5),
    tau=st.floats(1.0, 1e4),
    d_kind=st.sampled_from(["none", "screen", "wide"]),
    where=st.sampled_from(["discharge", "cells", (1, 3)]),
    columns=st.integers(0, 3),
)
def test_compiled_loop_equals_gtsv_loop(n_cells, r, dead, bypass, tau, d_kind, where, columns):
    x, S, b = _kernel()
    net = rtd.RecirculatingCells(tau, n_cells, r=r, dead=dead, bypass=bypass).network()
    if mill_cells.is_chain(net):  # no back-mixing: the cell-by-cell path, no class loop
        return
    d = {"none": None, "screen": np.where(x > 0.05, 1e-3, 1.0), "wide": np.geomspace(1e3, 1e-3, S.size)}[d_kind]
    rng = np.random.default_rng(n_cells)
    feed = rng.random(S.size) if columns == 0 else rng.random((S.size, columns))
    fast = mill_cells.solve_cells(S, b, feed, net, d, where)
    ref = mill_cells.solve_cells(S, b, feed, net, d, where, kernel="numpy")
    assert (fast.kernel, ref.kernel) == ("compiled", "numpy")
    # rounding differs (Thomas vs gtsv); retained coarse classes with strong back-mixing
    # make the class systems mildly ill-conditioned (both ~1e-12 from a 40-digit
    # solve there, test_both_loops_meet_a_high_precision_solve)
    scale = np.abs(ref.holdup).max()
    np.testing.assert_allclose(fast.holdup, ref.holdup, rtol=0, atol=1e-10 * scale)
    np.testing.assert_allclose(fast.product, ref.product, rtol=0, atol=1e-10 * np.abs(ref.product).max())
    assert fast.holdup.min() >= 0.0


def _class_loop_mpmath(S, b, feed, net, d, where, dps=40):
    """The class-by-class cell balance in ``dps`` digits (mpmath LU per class)."""
    import mpmath as mp

    offdiag, drain, exit_rate, G, H = mill_cells.cell_operators(net, d, where, S.size)
    n, inlet = net.n, (1 - net.bypass) * np.asarray(net.inlet)
    hold = []
    with mp.workdps(dps):
        for i in range(S.size):
            M = mp.matrix(n, n)
            for k in range(n):
                for l in range(n):
                    diag = (mp.mpf(S[i]) + mp.mpf(G[i, k]) * mp.mpf(drain[k])
                            + mp.mpf(H[i, k]) * mp.mpf(exit_rate[k]))
                    M[k, l] = diag if k == l else -mp.mpf(offdiag[k, l]) * mp.mpf(G[i, l])
            rhs = mp.matrix([mp.mpf(inlet[k]) * mp.mpf(feed[i])
                             + mp.fsum(mp.mpf(b[i, j]) * mp.mpf(S[j]) * hold[j][k] for j in range(i))
                             for k in range(n)])
            hold.append(mp.lu_solve(M, rhs))
        return np.array([[float(hold[i][k]) for i in range(S.size)] for k in range(n)])


def test_both_loops_meet_a_high_precision_solve():
    # coarse classes retained 1000-fold behind a screen, back-mixing ratio 8, 12 cells
    x, S, b = _kernel()
    net = rtd.RecirculatingCells(1.0, 12, r=8.0).network()
    d = np.where(x > 0.05, 1e-3, 1.0)
    feed = np.random.default_rng(12).random(S.size)
    ref = _class_loop_mpmath(S, b, feed, net, d, "discharge")
    got = [mill_cells.solve_cells(S, b, feed, net, d, "discharge", kernel=k) for k in (None, "numpy")]
    for sol in got:
        np.testing.assert_allclose(sol.holdup, ref, rtol=0, atol=1e-11 * np.abs(ref).max())


def test_numpy_fallback_closes_the_mass_balance(monkeypatch):
    x, S, b = _kernel()
    feed = np.r_[1.0, np.zeros(S.size - 1)]
    monkeypatch.setenv("MILLFLOW_KERNEL", "numpy")  # the environment picks the kernel for whole solves
    ds = steady_mill(S, b, feed, rtd.RecirculatingCells(60.0, 6, r=2.0), np.where(x > 0.1, 0.01, 1.0))
    assert ds.attrs["kernel"] == "numpy"
    assert ds.attrs["mass_balance_error"] < 1e-12


@compiled
def test_compiled_loop_rejects_wrong_buffers():
    N, n = 4, 3
    args = [np.zeros((N, n - 1)), np.ones((N, n)), np.zeros((N, n - 1)), np.zeros((N, N)),
            np.ones((N, n)), np.empty((N, n))]
    bad = list(args)
    bad[1] = np.ones((N, n), dtype=np.float32)
    with pytest.raises(ValueError, match="diag"):
        CELLS.tridiagonal_classes(*bad, N, n, 1)
    bad = list(args)
    bad[5] = np.empty((N, n + 1))
    with pytest.raises(ValueError, match="holdup"):
        CELLS.tridiagonal_classes(*bad, N, n, 1)
    with pytest.raises(ValueError, match="cells"):
        CELLS.tridiagonal_classes(*args, N, 0, 1)


@compiled
def test_compiled_loop_reports_a_zero_pivot():
    N, n = 2, 3
    diag = np.ones((N, n))
    diag[1, 0] = 0.0
    got = CELLS.tridiagonal_classes(np.zeros((N, n - 1)), diag, np.zeros((N, n - 1)),
                                                   np.zeros((N, N)), np.ones((N, n)), np.empty((N, n)), N, n, 1)
    assert got == 2
