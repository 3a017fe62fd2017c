"""Transient mills with non-linear kinetics (millflow.mill.nonlinear_transient): start-up
ends at the steady answer of the same equations, intermediate times against the dynamics
written out here and integrated independently, the measured error estimates against a
tighter independent solve, mass conservation of a pulse, plug flow against the batch."""
import numpy as np
import pytest
from scipy.integrate import quad_vec, solve_ivp

import rtd
from millflow.classifiers import screen_discharge
from millflow.mill import transient_mill
from millflow.mill import nonlinear as nl
from millflow.mill.axial import _bernoulli
from millflow.nonlinear import Aggregation, batch_nonlinear, constant_kernel, kinetics
from tests.millflow.mill.nonlinear_scene import TAU, breakage_scene



def _scene(n=14, beta0=0.02, lam=-1.0):
    grid, S, b, feed = breakage_scene(n)
    w = np.zeros((n, n))
    w[:, n // 2:] = 3.0
    kin = kinetics(S, b, w=w, lam=lam, aggregation=Aggregation(constant_kernel(beta0), grid.x[-1]), grid=grid)
    return grid, kin, feed


def _cells_independently(kin, feed, net, d, where, t, c0=None):
    """m_k' = src + sum_l G_l F[k, l] c_l - (G_k out_k + H_k o_k) c_k + V_k R(c_k), c = m / V,
    written out cell by cell and integrated by Radau (rtol 1e-11) without a Jacobian."""
    from millflow.mill.cells import _factors

    n, n1 = net.n, kin.n + 1
    V, F, o = net.volumes, net.flows, net.outlet
    G, H = _factors(None if d is None else np.append(d, 1.0), n1, n, where)
    src = (1 - net.bypass) * net.inlet[:, None] * np.append(feed, 0.0)[None, :]

    def rhs(_t, m):
        c = m.reshape(n, n1) / V[:, None]
        out = src.copy()
        for k in range(n):
            out[k] += sum(G[:, l] * F[k, l] * c[l] for l in range(n) if l != k)
            out[k] -= (G[:, k] * (F[:, k].sum() - F[k, k]) + H[:, k] * o[k]) * c[k]
            out[k] += V[k] * kin.rate(c[k])
        return out.ravel()

    m0 = np.zeros(n * n1) if c0 is None else c0
    sol = solve_ivp(rhs, (0, t.max()), m0, method="Radau", t_eval=t, rtol=1e-11, atol=1e-14)
    c = sol.y.T.reshape(t.size, n, n1) / V[None, :, None]
    return net.bypass * np.append(feed, 0.0)[None, :] + np.einsum("in,tni->ti", H * o[None, :], c)


@pytest.mark.parametrize("transport, where", [(rtd.RecirculatingCells(TAU, 3, 1.0), "discharge"),
                                              (rtd.TanksInSeries(TAU, 3), "cells")])
def test_cells_start_up_against_the_dynamics_and_its_steady_end(transport, where):
    grid, kin, feed = _scene()
    d = np.maximum(screen_discharge(grid.x, 2e-3, 3.0), 0.05)
    t = np.array([0.0, 0.3, 1.0, 3.0]) * TAU
    ds = transient_mill(kin, None, transport, t, feed=feed, d=d, where=where)
    ref = _cells_independently(kin, feed, transport.network(), d, where, t)
    p = np.column_stack([ds["product"].values, ds["overflow"].values])
    assert np.abs(p - ref).max() <= ds.attrs["error_estimate"] + 1e-9  # + the reference's own rtol 1e-11
    assert ds.attrs["error_estimate"] < 1e-6
    # the start-up ends at the steady state of the same mill (Newton), to both estimates
    end = transient_mill(kin, None, transport, [400 * TAU], feed=feed, d=d, where=where)
    steady = nl.solve_transport(kin, feed, transport, d, where=where)
    assert np.abs(end["product"].values[0] - steady.product).max() <= end.attrs["error_estimate"] + \
        steady.error_estimate + 1e-10  # e^-(400 tau / slowest time) of the transient left: none
    hold = steady.info.get("cell_holdup", steady.info.get("cells"))
    assert np.abs(end["cell_holdup"].values[0] - hold).max() <= 1e-7 * float(np.abs(hold).max())


def test_a_step_starts_at_the_old_steady_state_and_a_pulse_conserves_mass():
    grid, kin, feed = _scene()
    T = rtd.RecirculatingCells(TAU, 3, 1.0)
    old = feed[::-1].copy()
    ds = transient_mill(kin, None, T, [0.0, TAU], feed=feed, initial_feed=old)
    assert np.abs(ds["product"].values[0] - nl.solve_transport(kin, old, T).product).max() < 1e-9
    # a pulse (no feed): what left plus what is inside is the pulse, whatever the kinetics do
    t = np.linspace(0.0, 40 * TAU, 2001)
    pulse = np.zeros(grid.n)
    pulse[0] = 1.0
    pd = transient_mill(kin, None, T, t, pulse=pulse)
    out = pd["product"].sum("size").values + pd["overflow"].values
    left = np.sum(0.5 * (out[1:] + out[:-1]) * np.diff(t))  # trapezoid: O(dt^2) of a smooth curve
    inside = float(pd["holdup"].values[-1].sum())
    assert abs(left + inside - 1.0) < 1e-4


def test_axial_method_of_lines_against_the_node_balances_written_out():
    grid, kin, feed = _scene(10)
    pe, M = 6.0, 16
    t = np.array([0.0, 0.5, 2.0]) * TAU
    ds = transient_mill(kin, None, rtd.AxialDispersion(TAU, pe), t, feed=feed, m_cells=M)
    # tau w_k dc_k/dt = F_(k-1/2) - F_(k+1/2) + tau w_k R(c_k) (+ f at node 0, - c_M at node M),
    # F_(k+1/2) = (D/h) [B(-P) c_k - B(P) c_(k+1)], D = 1/Pe, P = h Pe
    n1, h = kin.n + 1, 1.0 / M
    w = np.full(M + 1, h)
    w[[0, -1]] = h / 2
    a, bt = pe ** -1 / h * _bernoulli(np.array([-h * pe]))[0], pe ** -1 / h * _bernoulli(np.array([h * pe]))[0]

    def rhs(_t, y):
        C = y.reshape(M + 1, n1)
        flux = a * C[:-1] - bt * C[1:]
        out = TAU * w[:, None] * kin.rate_many(C)
        out[:-1] -= flux
        out[1:] += flux
        out[0] += np.append(feed, 0.0)
        out[-1] -= C[-1]
        return (out / (TAU * w[:, None])).ravel()

    sol = solve_ivp(rhs, (0, t.max()), np.zeros((M + 1) * n1), method="LSODA", t_eval=t, rtol=1e-11, atol=1e-14)
    ref = sol.y.T.reshape(t.size, M + 1, n1)[:, -1, :-1]
    # the same grid: the time error alone (the estimate also carries the grid's |p_M - p_M/2|)
    assert np.abs(ds["product"].values - ref).max() <= ds.attrs["time_error_estimate"] + 1e-9
    assert ds.attrs["spatial_error_estimate"] > ds.attrs["time_error_estimate"]
    # start-up ends at the steady Newton answer on the same grid
    end = transient_mill(kin, None, rtd.AxialDispersion(TAU, pe), [200 * TAU], feed=feed, m_cells=M)
    steady = nl.axial_dispersion(kin, feed, TAU, pe, m_cells=M)
    assert np.abs(end["product"].values[0] - steady.product).max() <= end.attrs["time_error_estimate"] + 1e-9


@pytest.mark.parametrize("discharge", ["sampled", "flux"])
def test_open_vessel_start_up_ends_at_its_steady_state(discharge):
    grid, kin, feed = _scene(8)
    T = rtd.AxialDispersion(TAU, 6.0, bc="open")
    end = transient_mill(kin, None, T, [100 * TAU], feed=feed, m_cells=8, discharge=discharge)
    steady = nl.axial_open(kin, feed, TAU, 6.0, discharge=discharge, m_cells=8)
    assert np.abs(end["product"].values[0] - steady.product).max() <= end.attrs["time_error_estimate"] + 1e-9
    assert np.abs(end["holdup"].values[0] - steady.info["holdup"]).max() <= 1e-7 * TAU


def test_plug_flow_start_up_is_the_batch_grind_delayed():
    grid, kin, feed = _scene()
    t = np.array([0.0, 0.4 * TAU, 0.999 * TAU, TAU, 2 * TAU])
    ds = transient_mill(kin, None, rtd.PlugFlow(TAU), t, feed=feed)
    batch = batch_nonlinear(kin, feed, [TAU], method="Radau", rtol=1e-11, atol=1e-14)
    p = ds["product"].values
    assert np.all(p[:3] == 0.0) and np.abs(p[3:] - batch.M[0]).max() <= ds.attrs["error_estimate"]
    # hold-up: the parcels inside, aged 0..min(t, tau): int_0^a M_batch(s) ds, by quadrature of
    # Radau's dense output (rtol 1e-11) of the batch grind
    y0 = np.append(feed, 0.0)
    sol = solve_ivp(lambda _s, y: kin.rate(y), (0, TAU), y0, method="Radau", dense_output=True, rtol=1e-11,
                    atol=1e-14, jac=lambda _s, y: kin.jacobian(y))
    for k in (1, 4):
        ref, _ = quad_vec(lambda s: sol.sol(s)[:-1], 0.0, min(t[k], TAU), epsabs=1e-11)
        assert np.abs(ds["holdup"].values[k] - ref).max() <= ds.attrs["holdup_error_estimate"] + 1e-7
