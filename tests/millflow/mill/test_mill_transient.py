"""Transient mill (eq. 1 in time): tracer pulses reproduce the transport's own E(t);
start-up and step changes end at the steady state.

Tolerances: time integration with rtol 1e-10 gives ~1e-9 relative on E(t); the axial
method of lines carries the O(h^2) error of its grid (checked by its order).
"""
import numpy as np
import pytest
import rtd

from millflow.batch import batch_grind
from millflow.errors import InputError
from millflow.mill import steady_mill
from millflow.mill.axial import solve_axial
from millflow.mill.transient import transient_mill

N = 6
B = np.tril(np.ones((N, N)), -1)
B[:, :-1] /= B[:, :-1].sum(axis=0)
S_BREAK = np.array([1e-2, 5e-3, 2e-3, 1e-3, 5e-4, 0.0])
T = np.linspace(0.0, 3000.0, 31)


@pytest.mark.parametrize("model", [rtd.PerfectMixing(600.0), rtd.TanksInSeries(600.0, 3),
                                   rtd.RecirculatingCells(600.0, 4, r=1.0, bypass=0.1),
                                   rtd.Series(rtd.PlugFlow(100.0), rtd.PerfectMixing(500.0))])
def test_tracer_pulse_reproduces_E(model):
    ds = transient_mill(np.zeros(N), B, model, T, pulse=np.eye(N)[0], rtol=1e-10, atol=1e-14)
    E = model.pdf(T)
    assert float(np.abs(ds["product"][:, 0] - E).max()) < 1e-8 * E.max()


def test_axial_pulse_converges_to_E_with_order_two():
    model = rtd.AxialDispersion(600.0, 10.0)
    E = model.pdf(T)
    err = [float(np.abs(transient_mill(np.zeros(2), [[0, 0], [1, 0]], model, T, pulse=[1.0, 0.0], m_cells=m,
                                       rtol=1e-9)["product"][:, 0] - E).max()) for m in (25, 50, 100)]
    orders = np.log2(np.array(err[:-1]) / np.array(err[1:]))
    assert np.all(orders > 1.8), orders
    assert err[-1] < 1e-3 * E.max()


def test_pulse_with_breakage_is_E_times_batch_grind():
    model = rtd.TanksInSeries(600.0, 3)
    ds = transient_mill(S_BREAK, B, model, T, pulse=np.eye(N)[0], rtol=1e-10, atol=1e-14)
    ref = model.pdf(T)[:, None] * batch_grind(S_BREAK, B, np.eye(N)[0], T)
    np.testing.assert_allclose(ds["product"], ref, atol=1e-9 * ref.max())


@pytest.mark.parametrize("model", [rtd.TanksInSeries(600.0, 3), rtd.AxialDispersion(600.0, 10.0),
                                   rtd.PlugFlow(600.0)])
def test_startup_and_step_reach_steady_state(model):
    d = np.linspace(0.5, 1.0, N)
    f0, f1 = np.eye(N)[0], np.full(N, 1.0 / N)
    t = np.array([0.0, 300.0, 1e5])
    up = transient_mill(S_BREAK, B, model, t, feed=f0, d=d, m_cells=50)
    if isinstance(model, rtd.AxialDispersion):  # the method of lines vs the steady state on its grid
        ref0 = solve_axial(S_BREAK, B, f0, 600.0, 10.0, d, m_cells=50)
        ref0 = {"product": ref0.product, "holdup": ref0.holdup}
        ref1 = {"product": solve_axial(S_BREAK, B, f1, 600.0, 10.0, d, m_cells=50).product}
    else:
        ref0 = steady_mill(S_BREAK, B, f0, model, d)
        ref1 = steady_mill(S_BREAK, B, f1, model, d)
    tol = 1e-7  # rtol 1e-8 of the time integration on O(1) flows
    np.testing.assert_allclose(up["product"][-1], ref0["product"], atol=tol)
    np.testing.assert_allclose(up["holdup"][-1], ref0["holdup"], rtol=1e-6)
    assert float(up["holdup"][0].sum()) == 0.0
    step = transient_mill(S_BREAK, B, model, t, feed=f1, initial_feed=f0, d=d, m_cells=50)
    np.testing.assert_allclose(step["product"][0], ref0["product"], atol=tol)
    np.testing.assert_allclose(step["product"][-1], ref1["product"], atol=tol)


def test_pulse_mass_is_conserved():
    model = rtd.RecirculatingCells(600.0, 3, r=0.5)
    t = np.linspace(0.0, 2e4, 2001)
    ds = transient_mill(S_BREAK, B, model, t, pulse=np.eye(N)[0])
    out = np.trapezoid(ds["product"].sum("size"), t) if hasattr(np, "trapezoid") else np.trapz(
        ds["product"].sum("size"), t)
    assert abs(out + float(ds["holdup"][-1].sum()) - 1.0) < 1e-5  # trapezoid in time


def test_unsupported_transient_requests():
    with pytest.raises(InputError, match="delta"):
        transient_mill(S_BREAK, B, rtd.PlugFlow(1.0), T, pulse=np.eye(N)[0])
    with pytest.raises(InputError, match="only a tracer pulse"):
        transient_mill(S_BREAK, B, rtd.Series(rtd.PlugFlow(1.0), rtd.PerfectMixing(1.0)), T, feed=np.eye(N)[0])
