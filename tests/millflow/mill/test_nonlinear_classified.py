"""Non-linear kinetics with classification and networks of cells (millflow.mill.nonlinear):
first-order physics through the Newton code against the exact linear mill
(millflow.steady_mill, same classification and transport), non-linear kinetics against
a transient run to steady state of the same cells."""
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import rtd
from millflow import steady_mill
from millflow.classifiers import screen_discharge
from millflow.errors import InputError
from millflow.mill import nonlinear as nl
from millflow.nonlinear import Aggregation, constant_kernel, kinetics
from tests.millflow.mill.nonlinear_scene import TAU, breakage_scene



def _scene(n=30):
    grid, S, b, feed = breakage_scene(n)
    d = screen_discharge(grid.x, 2e-3, 3.0)  # a grate: coarse classes retained (d* -> 0 above 2 mm)
    return grid, S, b, feed, np.maximum(d, 1e-3)


def _nonlinear(grid, S, b, beta0=0.02, lam=-1.0):
    w = np.zeros((S.size, S.size))
    w[:, S.size // 2:] = 3.0  # fines cushion
    return kinetics(S, b, w=w, lam=lam, aggregation=Aggregation(constant_kernel(beta0), grid.x[-1]), grid=grid)


@pytest.mark.parametrize("transport, where", [
    (rtd.PerfectMixing(TAU), "discharge"),
    (rtd.TanksInSeries(TAU, 4), "discharge"),
    (rtd.TanksInSeries(TAU, 4), "cells"),
    (rtd.RecirculatingCells(TAU, 5, 1.5), "discharge"),
    (rtd.RecirculatingCells(TAU, 5, 1.5), "cells"),
    (rtd.RecirculatingCells(TAU, 4, 0.7, bypass=0.1), [2, 4]),
])
def test_first_order_through_newton_matches_the_exact_linear_mill(transport, where):
    grid, S, b, feed, d = _scene()
    kin = kinetics(S, b, w=np.ones((S.size, S.size)), lam=0.0)  # lambda = 0: Phi = 1 exactly, Newton path
    assert not kin.is_linear
    exact = steady_mill(S, b, feed, transport, d, where=where, tol=1e-12)["product"].to_numpy()
    if isinstance(transport, rtd.PerfectMixing):
        r = nl.well_mixed(kin, feed, TAU, d)
    elif isinstance(transport, rtd.TanksInSeries):
        r = nl.tanks_in_series(kin, feed, TAU, 4, d, where)
    else:
        r = nl.cells(kin, feed, transport, d, where)
    # the Newton code's residual (its own transport and classification operators) vanishes
    # at the linear answer it starts from; the polishing step keeps it there
    assert "exact" not in r.method and r.residual < 1e-13
    assert np.abs(r.product - exact).max() < 1e-10
    assert r.error_estimate < 1e-9 and r.mass_balance_error < 1e-12
    # the linear kinetics object takes the exact linear path and gives the same answer
    lin = kinetics(S, b)
    r0 = (nl.well_mixed(lin, feed, TAU, d) if isinstance(transport, rtd.PerfectMixing) else
          nl.tanks_in_series(lin, feed, TAU, 4, d, where) if isinstance(transport, rtd.TanksInSeries) else
          nl.cells(lin, feed, transport, d, where))
    assert np.abs(r0.product - exact).max() < 1e-12


def _transient(kin, feed, transport, d, where, t_end):
    """Dynamic cells m' = source + T m/V + V R(m/V) integrated to steady state (Radau):
    an independent route to the same steady product."""
    from millflow.mill.cells import _factors, network_of
    net = network_of(transport)
    n, n1 = net.n, kin.n + 1
    V, F, o = net.volumes, net.flows, net.outlet
    dx = np.append(d, 1.0)  # the overflow leaves unclassified
    G, H = _factors(dx, n1, n, where)
    src = (1 - net.bypass) * net.inlet[:, None] * np.append(feed, 0.0)[None, :]

    def rhs(t, m):
        c = m.reshape(n, n1) / V[:, None]
        out = src.copy()
        for k in range(n):
            out[k] += sum(G[:, l] * F[k, l] * c[l] for l in range(n) if l != k)
            out[k] -= (G[:, k] * (F[:, k].sum() - F[k, k]) + H[:, k] * o[k]) * c[k]
            out[k] += V[k] * kin.rate(c[k])
        return out.ravel()

    sol = solve_ivp(rhs, (0, t_end), np.zeros(n * n1), method="LSODA", rtol=1e-11, atol=1e-14)
    c = sol.y[:, -1].reshape(n, n1) / V[:, None]
    return net.bypass * np.append(feed, 0.0) + (H * o[None, :] * c.T).sum(axis=1)


@pytest.mark.parametrize("where", ["discharge", "cells"])
def test_nonlinear_recirculating_cells_against_a_transient_run(where):
    grid, S, b, feed, d = _scene(16)
    kin = _nonlinear(grid, S, b)
    tr = rtd.RecirculatingCells(TAU, 3, 1.0)
    r = nl.cells(kin, feed, tr, d, where)
    assert r.mass_balance_error < 1e-12 and r.error_estimate < 1e-10
    # the retained coarse classes (d* ~ 1e-3) relax over ~tau / d*
    ref = _transient(kin, feed, tr, d, where, 100 * TAU / d.min())
    assert np.abs(r.product - ref[:-1]).max() < 1e-8 and abs(r.overflow_mass - ref[-1]) < 1e-8
    # classification matters: the retained coarse classes are ground longer
    r1 = nl.cells(kin, feed, tr)
    assert np.abs(r.product - r1.product).max() > 1e-2


def test_nonlinear_classified_well_mixed_against_one_cell_and_transient():
    grid, S, b, feed, d = _scene(16)
    kin = _nonlinear(grid, S, b)
    r = nl.well_mixed(kin, feed, TAU, d)
    one = nl.cells(kin, feed, rtd.RecirculatingCells(TAU, 1, 0.0), d)
    # two solvers of one equation: apart by no more than their two error estimates, both small
    assert np.abs(r.product - one.product).max() <= r.error_estimate + one.error_estimate
    assert max(r.error_estimate, one.error_estimate) < 1e-9
    ref = _transient(kin, feed, rtd.RecirculatingCells(TAU, 1, 0.0), d, "discharge", 100 * TAU / d.min())
    assert np.abs(r.product - ref[:-1]).max() < 1e-8
    # hold-up = tau p / d*: the coarse classes fill the mill
    assert np.allclose(r.info["holdup"], TAU * r.product / d, rtol=1e-12, atol=1e-14)
    # tanks in series, d* in the last cell: the chain of classified cells in the network code
    t4 = nl.tanks_in_series(kin, feed, TAU, 4, d)
    c4 = nl.cells(kin, feed, rtd.RecirculatingCells(TAU, 4, 0.0), d)
    assert np.abs(t4.product - c4.product).max() <= t4.error_estimate + c4.error_estimate


def test_bad_classification_inputs_are_one_line_errors():
    grid, S, b, feed, d = _scene(16)
    kin = _nonlinear(grid, S, b)
    with pytest.raises(InputError, match="d_i\\* > 0"):
        nl.well_mixed(kin, feed, TAU, np.zeros(16))
    with pytest.raises(InputError, match="cell numbers in 1..3"):
        nl.cells(kin, feed, rtd.RecirculatingCells(TAU, 3, 1.0), d, [4])
    with pytest.raises(InputError, match="network of cells"):
        nl.cells(kin, feed, rtd.PlugFlow(TAU), d)
