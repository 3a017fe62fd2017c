"""Fixed-pivot aggregation (and aggregation + breakage) against exact solutions, by cell
mass, with the observed order of convergence in the grid ratio.

Grids: geometric in size with volume ratio 2^(1/k), k = 1, 2, 4 (size ratio 2^(1/(3k))),
covering volumes 1e-7..1e3 of the reference volume. The error is the L1 norm of the cell
mass differences; the order is log2(e_k / e_2k) (h = ln of the volume ratio halves).
The ODE is solved to rtol 1e-10, far below the discretisation error (>= 1e-3 here),
so the measured order is that of the discretisation.
"""
import numpy as np

from millflow.grid import SizeGrid
from millflow.nonlinear import Aggregation, batch_nonlinear, constant_kernel, kinetics, pivot_volumes, sum_kernel
from millflow.nonlinear.exact import (golovin_sum, patil_andrews_steady, scott_constant, uniform_binary_breakage,
                                      volume_edges)

XREF = 1e-6


def _grid(k, top_volume=1e3, decades=10):
    n = int(round(decades * np.log(10) / np.log(2 ** (1 / k)))) + 1
    return SizeGrid.geometric(XREF * top_volume ** (1 / 3), 2 ** (1 / (3 * k)), n)


def _aggregate(kernel, exact, t, k):
    grid = _grid(k)
    lo, up = volume_edges(grid, XREF)
    M0 = scott_constant(lo, up, 1.0, 0.0)
    kin = kinetics(np.zeros(grid.n), None, aggregation=Aggregation(kernel, XREF), grid=grid)
    res = batch_nonlinear(kin, M0, [t], rtol=1e-10, atol=1e-14)
    # mass of classes + overflow stays the initial mass to rounding (by construction)
    assert res.mass_balance_error < 1e-13
    return float(np.abs(res.M[0] - exact(lo, up, 1.0, t)).sum())


def _orders(errors):
    return [float(np.log2(a / b)) for a, b in zip(errors[:-1], errors[1:])]


def test_scott_constant_kernel_second_order():
    e = [_aggregate(constant_kernel(1.0), scott_constant, 2.0, k) for k in (1, 2, 4)]
    p = _orders(e)
    # fixed pivot is second order in h = ln(ratio); the finest pair is in the asymptotic range
    assert e[-1] < 1e-2 and 1.8 < p[-1] < 2.2, (e, p)


def test_golovin_sum_kernel_converges():
    e = [_aggregate(sum_kernel(1.0), golovin_sum, 1.0, k) for k in (1, 2, 4)]
    p = _orders(e)
    # the sum kernel moves mass to the top of the grid fast; the coarse grids also feed the
    # overflow, so the order rises towards 2 with refinement (1.47 then 1.80 measured)
    assert e[-1] < 3e-2 and p[-1] > 1.6 and p[-1] > p[0], (e, p)


def test_golovin_reference_mass_and_limit():
    lo, up = volume_edges(_grid(2, top_volume=1e6, decades=14), XREF)
    # the exact solution carries total mass 1 (to the quadrature and the grid's tails)
    assert abs(golovin_sum(lo, up, 1.0, 0.7).sum() - 1.0) < 1e-9
    # at t -> 0 it is the initial exponential
    assert np.allclose(golovin_sum(lo, up, 1.0, 1e-12), scott_constant(lo, up, 1.0, 0.0), atol=1e-10)


def test_patil_andrews_steady_state_second_order():
    errs, residuals = [], []
    for k in (1, 2, 4):
        grid = _grid(k, top_volume=60.0, decades=8)
        lo, up = volume_edges(grid, XREF)
        v = pivot_volumes(grid, XREF)
        S, b = uniform_binary_breakage(v, 1.0)
        kin = kinetics(S, b, aggregation=Aggregation(constant_kernel(2.0), XREF), grid=grid)
        M0 = np.zeros(grid.n)
        M0[np.argmin(np.abs(v - 1.0))] = 1.0
        res = batch_nonlinear(kin, M0, [60.0], rtol=1e-9, atol=1e-13)
        errs.append(float(np.abs(res.M[0] - patil_andrews_steady(lo, up, 2.0, 1.0)).sum()))
        residuals.append(float(np.abs(kin.rate(np.append(res.M[0], res.overflow_mass[0])))[:-1].max()))
    p = _orders(errs)
    assert 1.8 < p[-1] < 2.2, (errs, p)  # second order, as for pure aggregation
    assert residuals[-1] < 1e-7  # t = 60 s is 60 breakage times of the mean particle: steady


def test_uniform_binary_breakage_keeps_mass_and_number():
    v = pivot_volumes(_grid(2, top_volume=10.0, decades=6), XREF)
    S, b = uniform_binary_breakage(v, 1.0)
    assert np.allclose(b[:, :-1].sum(axis=0), 1.0, atol=1e-13)  # mass, every breaking class
    # number: a parent makes 2 fragments; with the share s that lands back on its own pivot
    # removed (S_j = S0 v_j (1 - s)), the other pivots get (2 - s)/(1 - s) per event.
    # The sink takes mass only, so check parents whose fragments stay above it (rounding tolerance).
    for j in range(0, v.size - 6):
        s = 1.0 - S[j] / v[j]
        number = np.sum(b[j + 1:, j] * v[j] / v[j + 1:])
        below = 2.0 * v[-1] / v[j]  # number of fragments below the smallest pivot (kept as mass only)
        assert abs(number - (2.0 - s) / (1.0 - s)) < 1e-9 + 4.0 * below
