"""Slowing-down in the particle's age with classification: the age-structured cell balance.

With S_i = S_i0 kappa(a), a the age of a particle (the time since it entered the mill),
and classification d*, a particle's exit depends on the class it is in, which changes as
it breaks: no one exit-age density applies and segregated flow is not the answer. The
hold-up density over age M_k(a) (N classes) of each well-mixed cell k of the transport
(:func:`millflow.mill.cells.network_of`: perfect mixing, tanks in series, recirculating
cells, compartment networks) obeys one linear ODE in the age, the same a in every cell::

    dM_k/da = kappa(a) K M_k - (G_k drain_k + H_k exit_k) M_k + sum_l G_l (F_kl / V_l) M_l,
    M_k(0) = (1 - beta) u_k f,

K = (b - I) diag(S) the breakage operator of eq. 4, F, V, u, beta the network's flows,
volumes, inlet split and bypass, and G, H the classification factors on inter-cell and
exit flows exactly as the linear cells (:func:`millflow.mill.cells.cell_operators`, d* at
"discharge", "cells" or listed cells). Hold-up per unit feed rate [s] (in the feed's
units times s) int_0^inf M_k da; product beta f + sum_k H_k exit_k int_0^inf M_k da.
One perfect mixer is dm/da = (kappa(a) K - D) m, D = diag(d_i* / tau).

Without classification (G = H = 1) the transport commutes with breakage and this is
segregated flow, int E(a) exp(K theta(a)) f da; with kappa = 1 it is the linear classified
mill (each cell's eq. 3): both are checked in the tests.

Solved by LSODA with the analytic Jacobian (the ODE is linear: the Jacobian is the matrix
kappa(a) K - T itself), the hold-up integral carried as extra states, up to the age A at
which the mass still in the mill falls below ``tail`` of the feed (the slowest transport
decay rate fixes the horizon searched). The rest is closed with the operator frozen at
kappa(A): int_A^inf M = -(kappa(A) K - T)^{-1} M(A). Its product has the same total as the
true tail (all of M(A), every column of the operator conserving mass but for the exits),
and both are non-negative, so the closure moves no class by more than sum M(A): that bound
joins the error estimate. The whole solve runs at (rtol, atol) and at tolerances 10x
tighter; the tighter answer is returned and the largest difference of the product and of
hold-up / tau between the two (plus the tail bound) is the error estimate (measured).

With classification on the axis of plug flow or axial dispersion classes travel at
different speeds, so a particle's age and its position are not tied and the state is a
density in both: plug flow and the closed and open axial-dispersion vessels are solved by
:mod:`millflow.mill.age_axis` (:func:`millflow.mill.nonlinear.age_slowing` routes them there);
here classification on the axis is refused (:data:`AXIS_REFUSED`).
"""
from __future__ import annotations

import time

import numpy as np

from millflow.errors import InputError, SolverError
from millflow.linalg import breakage_matrix
from millflow.mill.cells import cell_operators, network_of
from millflow.mill.nonlinear_cell import NonlinearSteady, _check
from millflow.nonlinear.kinetics import Kinetics
from millflow.ode import integrate

__all__ = ["age_structured", "integrate_ages", "AGE_RTOL", "AGE_ATOL", "AGE_TAIL", "AXIS_REFUSED"]

#: Relative and absolute (of the feed) tolerances of the age ODE; the answer comes from a
#: second solve 10x tighter, so its error is far below these (measured in the tests).
AGE_RTOL, AGE_ATOL = 1e-10, 1e-14
#: The integration stops once the mass still in the mill is below this share of the feed.
AGE_TAIL = 1e-13
#: Why classification on the axis stays refused here (plug flow and axial dispersion: millflow.mill.age_axis).
AXIS_REFUSED = ("kappa(t) (slowing-down in the particle's age) with classification on the axis: classes travel at "
                "different speeds, so age and position are not tied and the state is a density in both, which "
                "millflow solves for plug flow and axial dispersion (closed and open vessel, millflow.mill.age_axis) "
                "only; expected rtd.PlugFlow, rtd.AxialDispersion, a cell transport with classification at its "
                "outlets (rtd.PerfectMixing, rtd.TanksInSeries, rtd.RecirculatingCells, a CompartmentNetwork) or "
                "d = None")


def _kappa_of(age, scale: float):
    """kappa(a) as a scalar function: the user's kappa, or theta'(a) by a fourth-order stencil."""
    if age.kappa is not None:
        def kap(a):
            v = float(age.kappa(a))
            if not (np.isfinite(v) and v >= 0):
                raise SolverError(f"age slowing-down: kappa({a!r}) = {v!r}; expected a finite value >= 0")
            return v
        return kap, False
    h0 = 1e-3 * scale

    def th(t):
        return float(age.theta(float(t)))

    def kap(a):
        h = h0 if a >= 2 * h0 else max(a, h0) / 2.0
        if a >= 2 * h:
            v = (th(a - 2 * h) - 8 * th(a - h) + 8 * th(a + h) - th(a + 2 * h)) / (12 * h)
        else:  # one-sided at the inlet (theta is defined for ages >= 0)
            v = (-25 * th(a) + 48 * th(a + h) - 36 * th(a + 2 * h) + 16 * th(a + 3 * h) - 3 * th(a + 4 * h)) / (12 * h)
        if not (np.isfinite(v) and v >= -1e-9):
            raise SolverError(f"age slowing-down: theta'({a!r}) = {v!r}; expected a finite kappa >= 0")
        return max(v, 0.0)
    return kap, True


def _operators(kin: Kinetics, net, d, where):
    """(K over all cells, transport T, exit weights w, initial state, bypass), cell-major order k N + i."""
    n_cls, n = kin.n, net.n
    offdiag, drain, exit_rate, G, H = cell_operators(net, d, where, n_cls)
    K = breakage_matrix(kin.S, kin.b)
    Kb = np.kron(np.eye(n), K)
    T = np.zeros((n * n_cls, n * n_cls))
    for k in range(n):
        for j in range(n):
            rows = slice(k * n_cls, (k + 1) * n_cls)
            if k == j:
                T[rows, rows] = -np.diag(G[:, k] * drain[k] + H[:, k] * exit_rate[k])
            elif offdiag[k, j] != 0.0:
                T[rows, slice(j * n_cls, (j + 1) * n_cls)] = np.diag(G[:, j] * offdiag[k, j])
    w = (H * exit_rate[None, :]).T.ravel()  # exit weight of state (k, i)
    inlet = (1.0 - float(net.bypass)) * np.asarray(net.inlet, float)
    return Kb, T, w, inlet, float(net.bypass)


def _solve(kap, Kb, T, y0, fsum, tscale, horizon, rtol, atol, tail):
    m = y0.size
    eye = np.eye(m)

    def rhs(a, z):
        y = z[:m]
        return np.concatenate([kap(a) * (Kb @ y) + T @ y, y])

    def jac(a, _z):
        J = np.zeros((2 * m, 2 * m))
        J[:m, :m] = kap(a) * Kb + T
        J[m:, :m] = eye
        return J

    A, yA, Q, steps = integrate_ages(rhs, jac, y0, fsum=fsum, tscale=tscale, horizon=horizon, rtol=rtol, atol=atol,
                                     tail=tail, method="LSODA", what="age-structured mill")
    tail_q = np.linalg.solve(-(kap(A) * Kb + T), yA)
    return Q + tail_q, A, float(max(yA.sum(), 0.0)), steps


def integrate_ages(rhs, jac, y0, *, fsum: float, tscale: float, horizon: float, rtol: float, atol: float,
                   tail: float, method: str, what: str):
    """Integrate an age-structured balance and its running integral up to the age where the mill is empty.

    The state is (M, int_0^a M): ``rhs`` and ``jac`` of both, ``y0`` the initial M (its
    integral starts at 0). The integration stops at the age A where sum(M) falls below
    ``tail`` * ``fsum``; reaching ``horizon`` first raises. Absolute tolerances ``atol``
    * ``fsum`` on M and that times ``tscale`` [s] on its integral.

    Returns
    -------
    tuple
        (A [s], M(A), int_0^A M, number of output points).

    Raises
    ------
    SolverError
        If the ODE fails or mass is still in the mill at the horizon.
    """
    m = y0.size

    def left(_a, z):
        return float(z[:m].sum()) - tail * fsum
    left.terminal, left.direction = True, -1
    at = np.concatenate([np.full(m, atol * fsum), np.full(m, atol * fsum * tscale)])
    sol = integrate(rhs, (0.0, horizon), np.concatenate([y0, np.zeros(m)]), method=method, jac=jac, rtol=rtol,
                    atol=at, events=left, what=f"{what} (the ODE in the age)")
    if sol.status != 1:
        raise SolverError(f"{what}: {sol.y[:m, -1].sum() / fsum:.3g} of the feed is still in the mill at age "
                          f"{horizon:.4g} s (the horizon); expected it below {tail:g}")
    return float(sol.t[-1]), sol.y[:m, -1], sol.y[m:, -1], int(sol.t.size)


def age_structured(kin: Kinetics, feed, transport, d=None, where="discharge", *, rtol: float = AGE_RTOL,
                   atol: float = AGE_ATOL, tail: float = AGE_TAIL, holdup: bool = True,
                   error_estimate: bool = True) -> NonlinearSteady:
    """A continuous mill of well-mixed cells with S_i = S_i0 kappa(a) and classification d*.

    The age-structured balance of the module docstring for ``transport`` (an rtd model
    with a network of cells, tau in s), ``d`` (N,) normalised discharge d_i* (None: none)
    placed by ``where`` ("discharge", "cells" or 1-based cell numbers) as the linear
    cells place it. ``info["holdup"]`` (N,) the hold-up per unit feed rate [s] (feed units
    x s), ``info["cell_holdup"]`` (cells, N), ``info["age_horizon_s"]`` where the ODE
    stopped. ``error_estimate=False``: one solve at (rtol, atol), the estimate is then the
    tail bound only (the fit's forward model, whose own noise level is set apart).
    The closed axial-dispersion vessel and plug flow with ``d`` on the axis are
    :func:`millflow.mill.age_axis.age_structured_axial` and
    :func:`~millflow.mill.age_axis.age_structured_plug` (``age_slowing`` routes them there).
    """
    net = network_of(transport)
    if net is None:
        kind = type(transport).__name__
        if kind in ("PlugFlow", "AxialDispersion") or where == "axis":
            raise InputError(AXIS_REFUSED)
        raise InputError(f"transport {transport!r}: kappa(t) with classification is solved on networks of well-mixed "
                         "cells (rtd.PerfectMixing, rtd.TanksInSeries with integer n, rtd.RecirculatingCells, a "
                         "CompartmentNetwork)")
    tau = float(getattr(transport, "mean", np.sum(net.volumes)))
    feed, tau = _check(kin, feed, tau)
    if kin.age is None:
        raise InputError("age_structured: the kinetics have no kappa(t) (kinetics(..., kappa_t=...))")
    if where == "axis":
        raise InputError(AXIS_REFUSED)
    start = time.perf_counter()
    d = None if d is None else np.asarray(d, float)
    if d is not None and (d.shape != (kin.n,) or not np.all(np.isfinite(d)) or np.any(d <= 0)):
        raise InputError(f"d: expected ({kin.n},) normalised discharge rates > 0")
    n_cls, n = kin.n, net.n
    Kb, T, w, inlet, bypass = _operators(kin, net, d, where or "discharge")
    y0 = np.kron(inlet, feed)
    fsum = max(float(feed.sum()), 1e-300)
    # the slowest decay of the transport alone bounds how long material stays
    slow = float(np.min(-np.linalg.eigvals(T).real))
    if not slow > 0:
        raise InputError(f"transport {transport!r}: some class never leaves the cells (the transport has a decay "
                         "rate <= 0)")
    horizon = 80.0 / slow + 10.0 * tau
    kap, stencil = _kappa_of(kin.age, tau)
    Q, A, left, steps = _solve(kap, Kb, T, y0, fsum, tau, horizon, rtol, atol, tail)
    err = left  # the tail closure moves no class by more than the mass left at A
    how = "age-structured cells: LSODA in the particle's age, tail closed at kappa(A)"
    if error_estimate:
        Q2, A, left2, steps = _solve(kap, Kb, T, y0, fsum, tau, horizon, max(0.1 * rtol, 3e-14), 0.1 * atol, tail)
        p1, p2 = w @ Q, w @ Q2
        diff = max(float(np.abs(p2 - p1).max()), float(np.abs(Q2 - Q).max()) / tau)
        err = diff + left2
        Q = Q2
    cells_q = Q.reshape(n, n_cls)
    p = (w * Q).reshape(n, n_cls).sum(axis=0) + bypass * feed
    info = {"kinetics": kin.describe(), "age_horizon_s": A, "mass_left_at_horizon": left / fsum, "ode_points": steps,
            "classification": "none" if d is None else f"d* at {where or 'discharge'}"}
    if stencil:
        how += " (kappa = theta' by a 4th-order stencil)"
    if holdup:
        info.update(holdup=cells_q.sum(axis=0), cell_holdup=cells_q, holdup_overflow=0.0,
                    cell_overflow=np.zeros(n))
    return NonlinearSteady(p, 0.0, how, 0.0, float(err), float(abs(p.sum() - feed.sum())), 0,
                           time.perf_counter() - start, info)
