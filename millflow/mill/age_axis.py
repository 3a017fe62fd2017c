"""Slowing-down in the particle's age with classification on the axis of an axial-dispersion mill.

With S_i = S_i0 kappa(a), a the age of a particle (the time since it entered the mill
[s]), and classification on the axis of the closed axial-dispersion vessel (class i
travels at the relative axial velocity v_i = d_i* and disperses with the relative
dispersion w_i, :mod:`millflow.mill.axial`), a particle's age and its position are not
tied: classes travel at different speeds and a particle changes class as it breaks. The
state is the hold-up density c_i(z, a) over position z = y/L in [0, 1] and age, and it
obeys one linear equation in the age::

    dc_i/da = (1/tau) L_i c_i + kappa(a) (K c)_i,
    L_i c = -d/dz [ v_i c - (w_i/Pe) dc/dz ],

with the closed-vessel (Danckwerts) boundaries: no flux through z = 0 but the feed,
c_i'(1) = 0 and the outflow v_i c_i(1) at the discharge. The feed enters at z = 0 at age 0.
K = (b - I) diag(S) is the breakage operator of eq. 4, tau = L/u [s] and Pe = u L / D the
transport's. Product p_i = int_0^inf v_i c_i(1, a) da (what leaves at every age), hold-up
per unit feed rate [s] tau int_0^inf int_0^1 c_i dz da.

Discretisation in z: exactly the vertex-centred finite volumes of the linear axial mill
(nodes z_k = k h, h = 1/M, volumes h, h/2 at the ends; Scharfetter-Gummel fluxes
alpha_k c_k - beta_k c_(k+1), alpha = (D/h) B(-P), beta = (D/h) B(P), D = w/Pe, P = v h / D;
outflow v_i c_i at the last node). On the masses m_ik = tau h_k c_ik of the volumes the
age equation becomes the linear ODE dm/da = (kappa(a) Kb + T) m, m(0) = feed at node 0,
Kb = I_nodes (x) K and T the transport (block tridiagonal, its columns sum to minus the
outflow): the form :mod:`millflow.mill.age_cells` solves for cells, with the finite-volume
transport in place of the cells'. The integral over z is the trapezoidal rule of the
finite volumes, so with kappa = 1 the integral over ages of m is the linear mill's
finite-volume solution on the same grid (to the ODE's tolerance).

Solved by scipy's BDF with the sparse analytic Jacobian kappa(a) Kb + T, the product and
hold-up integrals carried as 2N extra states, up to the age A at which the mass still in
the mill falls below ``tail`` of the feed; the rest is closed with the operator frozen at
kappa(A) (one sparse LU solve): its product has the total of the true tail and both are
non-negative, so no class of the product moves by more than the mass left, and no
hold-up / tau by more than the mass left times its slowest transport decay time / tau.
Mass is conserved to rounding (every column of kappa Kb + T sums to minus its outflow, a
linear invariant BDF keeps).

Error estimate (max abs error of the product and of hold-up / tau, in the feed's units):
the grid is refined by doubling M (:func:`millflow.mill.axial.refine_grids`: Richardson
with the observed order, extrapolated when it is 2 and the cell Peclet number <= 1) and
the estimate is the grid's Richardson estimate + the ODE's (the finest grid solved again
at tolerances 10x tighter; the difference times the sum of |weights| of the
extrapolation) + the tail bound. What is exact: the breakage terms lumped at the nodes
and the exponentially fitted fluxes are the linear mill's second-order scheme; the only
approximations are the grid in z (Richardson), the ODE in the age (tight against loose)
and the tail (bounded).

Plug flow with classification on the axis (no dispersion) is the limit of M upwind cells
in a row (M tanks in series with d* at every outlet) as M -> infinity, whose error is a
power series in 1/M: :func:`age_structured_plug` extrapolates it by Romberg's table. The
open vessel is not solved here (:data:`OPEN_REFUSED`).
"""
from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from millflow.errors import InputError, SolverError
from millflow.linalg import breakage_matrix
from millflow.mill.age_cells import AGE_TAIL, _kappa_of, integrate_ages
from millflow.mill.axial import refine_grids
from millflow.mill.finite_volume import closed_faces, node_losses, tridiagonal
from millflow.mill.nonlinear_cell import NonlinearSteady, _check
from millflow.nonlinear.kinetics import Kinetics
from millflow.threads import limit_blas_threads

__all__ = ["age_structured_axial", "age_structured_plug", "AXIS_MAX_STATE", "AXIS_TOL", "OPEN_REFUSED"]

#: Default target of the error estimate (max abs error of product and hold-up / tau, of the feed).
AXIS_TOL = 1e-7
#: Largest ODE state (classes x nodes) the age-position balance may reach on its finest grid.
AXIS_MAX_STATE = 2**16
#: The ODE's relative tolerance is this share of ``tol`` (its error must not disturb the
#: Richardson estimate of the grid); absolute tolerance a tenth of that, of the feed.
ODE_SHARE = 1e-2
#: Why the open vessel with classification on the axis stays refused.
OPEN_REFUSED = ("kappa(t) (slowing-down in the particle's age) with classification on the axis of the open axial-"
                "dispersion vessel is not solved (its discharge samples a concentration on an infinite line); "
                "expected the closed vessel rtd.AxialDispersion(tau, pe) (millflow.mill.age_axis), a cell "
                "transport, or d = None")


def _fv_transport(v, w, pe: float, tau: float, m_cells: int):
    """The finite-volume transport on the masses of the volumes, node-major (index k N + i).

    Returns (T (n, n) sparse csc [1/s], exit (N, n) sparse: the outflow rate of each class
    at the discharge node [1/s], weights (M + 1,) the volumes [fraction of the length]).
    The node balances of the linear mill (:func:`millflow.mill.finite_volume.tridiagonal`
    on :func:`~millflow.mill.finite_volume.closed_faces`, losses the outflow v at the last
    node) on the masses m = tau h_k c: T = -A diag(1 / (tau h_k)), so T's column of node k
    of class i sums to minus its outflow (zero but at the last node).
    """
    faces = closed_faces(pe, m_cells, v, w)
    lower, diag, upper = tridiagonal(faces, node_losses(faces, v))
    n_cls, nodes = diag.shape
    scale = 1.0 / (tau * faces.weights)  # c = m / (tau h_k)
    idx = np.arange(nodes)[:, None] * n_cls + np.arange(n_cls)[None, :]  # (nodes, N) state index
    rows = np.concatenate([idx[1:].ravel(), idx[:-1].ravel(), idx.ravel()])
    cols = np.concatenate([idx[:-1].ravel(), idx[1:].ravel(), idx.ravel()])
    vals = -np.concatenate([(lower.T * scale[:-1, None]).ravel(), (upper.T * scale[1:, None]).ravel(),
                            (diag.T * scale[:, None]).ravel()])
    n = nodes * n_cls
    T = sp.csc_matrix((vals, (rows, cols)), shape=(n, n))
    out = np.asarray(v, float) * scale[-1]
    exit_ = sp.csr_matrix((out, (np.arange(n_cls), idx[-1])), shape=(n_cls, n))
    return T, exit_, faces.weights


def _slowest_decay(v, w, pe: float, tau: float) -> float:
    """Slowest decay rate [1/s] of the transport alone, from each class's operator on 32 volumes."""
    T, _, _ = _fv_transport(v, w, pe, tau, 32)
    n_cls = v.size
    dense = T.toarray()
    rates = [np.min(-np.linalg.eigvals(dense[i::n_cls, i::n_cls]).real) for i in range(n_cls)]
    return float(min(rates))


def _solve_ages(kap, K, T, exit_, y0, fsum, tau, horizon, rtol, atol, tail):
    """One solve of the age ODE on one grid: (product, hold-up [s], age A, mass left, points)."""
    n, n_cls = y0.size, K.shape[0]
    nodes = n // n_cls
    Kb = sp.kron(sp.identity(nodes, format="csc"), sp.csc_matrix(K), format="csc")
    # Q = int_0^a m carried as n extra states (dQ/da = m): the Jacobian keeps the band of
    # the transport (states for the N product and hold-up integrals alone would be dense
    # rows, and the sparse LU's column ordering fills them in)
    eye, zero = sp.identity(n, format="csc"), sp.csc_matrix((n, n))
    J_T = sp.bmat([[T, zero], [eye, zero]], format="csc")
    J_K = sp.bmat([[Kb, zero], [zero, zero]], format="csc")
    KT = np.ascontiguousarray(K.T)

    def rhs(a, y):
        m = y[:n]
        return np.concatenate([T @ m + kap(a) * (m.reshape(nodes, n_cls) @ KT).ravel(), m])

    def jac(a, _y):
        return J_T + kap(a) * J_K

    A, yA, Q, steps = integrate_ages(rhs, jac, y0, fsum=fsum, tscale=tau, horizon=horizon, rtol=rtol, atol=atol,
                                     tail=tail, method="BDF", what="age-structured axial mill")
    Q = Q + splu(-(T + kap(A) * Kb).tocsc()).solve(yA)  # + int_A^inf m at kappa(A)
    p = exit_ @ Q
    hold = Q.reshape(nodes, n_cls).sum(axis=0)
    return p, hold, A, float(max(yA.sum(), 0.0)), steps


@limit_blas_threads
def age_structured_axial(kin: Kinetics, feed, transport, d=None, *, dispersion=None, tol: float = AXIS_TOL,
                         rtol: float | None = None, tail: float = AGE_TAIL, m_start: int = 16,
                         m_cells: int | None = None, max_state: int = AXIS_MAX_STATE, error_estimate: bool = True,
                         holdup: bool = True) -> NonlinearSteady:
    """A closed axial-dispersion mill with S_i = S_i0 kappa(a) and classification on the axis.

    The age-position balance of the module docstring, discretised in z by the linear axial
    mill's finite volumes and refined by doubling the grid until the error estimate is
    below ``tol``.

    Parameters
    ----------
    kin : millflow.nonlinear.Kinetics
        First-order rates S_i0 [1/s] and b with kappa(t) (``kinetics(..., kappa_t=...)`` or
        ``theta_t``), the age t in s.
    feed : (N,) feed flows (mass per unit time; the product is in the same units).
    transport : rtd.AxialDispersion with bc "closed": tau = L/u [s] (``.tau``, its mean) and
        Pe (``.pe``).
    d : (N,) relative axial velocity d_i* > 0 of each class [-] (None: 1).
    dispersion : (N,) relative dispersion w_i > 0 [-] (None: 1).
    tol : target of the error estimate: max abs error of the product and of the hold-up /
        tau, in the feed's units.
    rtol : relative tolerance of the ODE in the age (None: :data:`ODE_SHARE` x ``tol``);
        its absolute tolerance is a tenth of it, of the feed.
    tail : share of the feed left in the mill at which the ODE stops and the tail is closed.
    m_start : the first grid's number of volumes (then 2x, 4x, ...).
    m_cells : solve on this one grid only (error estimate: ODE and tail, no grid part; the
        fit's fixed grid).
    max_state : largest state N (M + 1) of a grid; the refinement stops below it (and is
        refused up front when the grid needed for a cell Peclet number <= 1 exceeds it).
    error_estimate : with False one ODE solve per grid and no tighter solve (the ODE part
        of the estimate is then left out).
    holdup : whether ``info["holdup"]`` (N,) the hold-up per unit feed rate [s] is filled.

    Returns
    -------
    NonlinearSteady
        ``product`` (N,), ``error_estimate`` the sum of the grid, ODE and tail parts (each
        in ``info``: ``grid_error``, ``ode_error``, ``tail_error``), ``info["m_cells"]`` the
        finest grid, ``info["order"]`` the observed order, ``info["history"]`` the grids.
    """
    import rtd

    if isinstance(transport, rtd.PlugFlow):
        return age_structured_plug(kin, feed, transport, d, tol=tol, rtol=rtol, tail=tail, max_state=max_state,
                                   error_estimate=error_estimate, holdup=holdup)
    if not isinstance(transport, rtd.AxialDispersion):
        raise InputError(f"transport {transport!r}: the age-position balance is solved for rtd.AxialDispersion "
                         "(closed vessel)")
    if transport.bc != "closed":
        raise InputError(OPEN_REFUSED)
    tau, pe = float(transport.tau), float(transport.pe)
    feed, tau = _check(kin, feed, tau)
    if kin.age is None:
        raise InputError("age_structured_axial: the kinetics have no kappa(t) (kinetics(..., kappa_t=...))")
    n_cls = kin.n
    v = np.ones(n_cls) if d is None else np.asarray(d, float)
    w = np.ones(n_cls) if dispersion is None else np.asarray(dispersion, float)
    for name, x in (("d", v), ("dispersion", w)):
        if x.shape != (n_cls,) or not np.all(np.isfinite(x)) or np.any(x <= 0):
            raise InputError(f"{name}: expected ({n_cls},) values > 0")
    if not (np.isfinite(pe) and pe > 0):
        raise InputError(f"Pe = {pe!r}: expected a Peclet number > 0")
    cell_pe = float(np.max(v / w)) * pe
    m_max = max_state // n_cls - 1
    need = max(int(m_start), int(np.ceil(cell_pe))) if m_cells is None else int(m_cells)
    if n_cls * (need + 1) > max_state:
        raise InputError(f"age-structured axial mill: {n_cls} classes x {need + 1} nodes (the grid where the cell "
                         f"Peclet number Pe d*/dispersion h = {cell_pe:.3g} h reaches 1) exceed the state limit "
                         f"{max_state} (AXIS_MAX_STATE); expected fewer classes or a smaller Pe")
    start = time.perf_counter()
    K = breakage_matrix(kin.S, kin.b)
    kap, stencil = _kappa_of(kin.age, tau)
    fsum = max(float(feed.sum()), 1e-300)
    slow = _slowest_decay(v, w, pe, tau)
    if not slow > 0:
        raise InputError(f"transport {transport!r}: some class never leaves the mill (decay rate <= 0)")
    horizon = 80.0 / slow + 10.0 * tau
    rtol = max(ODE_SHARE * tol if rtol is None else float(rtol), 1e-13)
    atol = 0.1 * rtol
    tail_hold = max(1.0, 1.0 / (slow * tau))  # hold-up / tau of the tail per unit of mass left
    solves = {}

    def solve(M, rt, at):
        T, exit_, _ = _fv_transport(v, w, pe, tau, M)
        y0 = np.zeros(T.shape[0])
        y0[:n_cls] = feed  # the feed enters the volume of z = 0 at age 0
        p, hold, A, left, pts = _solve_ages(kap, K, T, exit_, y0, fsum, tau, horizon, rt, at, tail)
        solves[M] = (A, left, pts)
        return p, hold, left

    def grid(M):
        p, hold, left = solve(M, rtol, atol)
        return np.linspace(0.0, 1.0, M + 1), left, np.concatenate([p, hold / tau])

    if m_cells is not None:
        z, left, both = grid(int(m_cells))
        estimate, order, history, weight, M = float("nan"), float("nan"), [], 1.0, int(m_cells)
        grid_err = 0.0
    else:
        both, estimate, order, history, finest, _, extrapolated = refine_grids(
            grid, cell_pe, tol=0.5 * tol, m_start=m_start, m_max=max(m_max, 4 * m_start),
            bytes_per_cell=8.0 * 60 * n_cls)
        M = finest[0].size - 1
        left, loose = finest[1], finest[2]
        weight = 5.0 / 3.0 if extrapolated else 1.0  # sum |w| of r = p4 + (p4 - p2) / 3
        grid_err = estimate
    ode_err = 0.0
    if error_estimate:
        p2, h2, left2 = solve(M, max(0.1 * rtol, 3e-14), 0.1 * atol)
        tight = np.concatenate([p2, h2 / tau])
        ode_err = weight * float(np.abs(tight - loose).max())
        if m_cells is not None:
            both, left = tight, left2
    tail_err = left * tail_hold
    err = grid_err + ode_err + tail_err
    p = both[:n_cls]
    A, _, pts = solves[M]
    how = ("age-structured axial dispersion: finite volumes in z, BDF in the particle's age with the sparse "
           "Jacobian, tail closed at kappa(A), grid refined (Richardson)")
    if stencil:
        how += " (kappa = theta' by a 4th-order stencil)"
    info = {"kinetics": kin.describe(), "m_cells": M, "state_size": n_cls * (M + 1), "order": order,
            "history": history, "grid_error": float(grid_err), "ode_error": float(ode_err),
            "tail_error": float(tail_err), "age_horizon_s": A, "mass_left_at_horizon": left / fsum,
            "ode_points": pts, "rtol": rtol,
            "classification": "none" if d is None else "d* on the axis (relative axial velocity)"}
    if holdup:
        info.update(holdup=tau * both[n_cls:], holdup_overflow=0.0)
    return NonlinearSteady(p, 0.0, how, 0.0, float(err), float(abs(p.sum() - feed.sum())), 0,
                           time.perf_counter() - start, info)


def _upwind_transport(v, tau: float, m_cells: int):
    """Plug flow on M equal cells in a row, node-major (index k N + i): the upwind finite volumes.

    Class i leaves every cell at the rate v_i M / tau [1/s] into the next one (the last
    one's outflow is the discharge): M tanks in series with d* = v at every outlet, whose
    limit M -> infinity is plug flow with class i travelling at v_i. Returns (T sparse csc,
    exit (N, n) sparse) as :func:`_fv_transport`.
    """
    n_cls, M = v.size, int(m_cells)
    rate = np.asarray(v, float) * M / tau
    idx = np.arange(M)[:, None] * n_cls + np.arange(n_cls)[None, :]
    rows = np.concatenate([idx.ravel(), idx[1:].ravel()])
    cols = np.concatenate([idx.ravel(), idx[:-1].ravel()])
    vals = np.concatenate([-np.tile(rate, M), np.tile(rate, M - 1)])
    n = M * n_cls
    T = sp.csc_matrix((vals, (rows, cols)), shape=(n, n))
    exit_ = sp.csr_matrix((rate, (np.arange(n_cls), idx[-1])), shape=(n_cls, n))
    return T, exit_


def _romberg_weights(levels: int) -> np.ndarray:
    """Weights c_j with R = sum_j c_j u(M_0 2^j) the Richardson (Romberg) extrapolation in h = 1/M.

    Each level removes the next power of h (h, h^2, ...): R_(j,l) = R_(j,l-1) +
    (R_(j,l-1) - R_(j-1,l-1)) / (2^l - 1).
    """
    table = [np.eye(levels)[j] for j in range(levels)]
    for lev in range(1, levels):
        table = [table[j] + (table[j] - table[j - 1]) / (2.0 ** lev - 1.0) for j in range(1, len(table))]
    return table[-1]


@limit_blas_threads
def age_structured_plug(kin: Kinetics, feed, transport, d=None, *, tol: float = AXIS_TOL,
                        rtol: float | None = None, tail: float = AGE_TAIL, m_start: int = 8,
                        levels: int | None = None, max_state: int = AXIS_MAX_STATE, error_estimate: bool = True,
                        holdup: bool = True) -> NonlinearSteady:
    """Plug flow with S_i = S_i0 kappa(a) and classification on the axis (class i at velocity d_i* u).

    The age-position balance of the module docstring without dispersion,
    dc_i/da = -(v_i/tau) dc_i/dz + kappa(a) (K c)_i, discretised in z by M upwind volumes
    (M equal cells in a row, class i leaving each at the rate v_i M / tau: the age-structured
    ODE of :func:`_solve_ages` with that transport) on M = ``m_start`` 2^j, j = 0, 1, ...
    The cells converge to plug flow as M -> infinity with an error that is a power series in
    h = 1/M (tanks in series tend to plug flow so: (1 + x h)^(-1/h) = e^(-x) (1 + x^2 h / 2
    + ...)), so the products and hold-ups of the grids are extrapolated to h = 0 by
    Romberg's table (each level removes the next power of h). Error estimate: the last
    two diagonal entries' difference, plus the ODE's (the finest grid again at rtol / 10,
    times the sum of |weights| of the extrapolation) and the tail bound. Refinement stops
    when the estimate is below ``tol`` (max abs error of the product and of hold-up / tau,
    in the feed's units); ``levels`` fixes the number of grids instead (the fit's forward
    model: smooth in the parameters), the estimate then being what those grids give.

    Parameters
    ----------
    kin : millflow.nonlinear.Kinetics
        S_i0 [1/s], b and kappa(t), the age t in s.
    feed : (N,) feed flows.
    transport : rtd.PlugFlow, tau [s] its mean.
    d : (N,) relative axial velocity d_i* > 0 [-] (None: 1, no classification).
    tol, rtol, tail, max_state, error_estimate, holdup : as :func:`age_structured_axial`.
    m_start : cells of the first grid (then 2x, 4x, ...).
    levels : number of grids (None: refine until the estimate meets ``tol``).

    Returns
    -------
    NonlinearSteady
        ``info``: ``m_cells`` (the finest grid), ``grids``, ``grid_error``, ``ode_error``,
        ``tail_error``, ``holdup`` [s].
    """
    import rtd

    if not isinstance(transport, rtd.PlugFlow):
        raise InputError(f"transport {transport!r}: age_structured_plug solves rtd.PlugFlow")
    tau = float(transport.mean)
    feed, tau = _check(kin, feed, tau)
    if kin.age is None:
        raise InputError("age_structured_plug: the kinetics have no kappa(t) (kinetics(..., kappa_t=...))")
    n_cls = kin.n
    v = np.ones(n_cls) if d is None else np.asarray(d, float)
    if v.shape != (n_cls,) or not np.all(np.isfinite(v)) or np.any(v <= 0):
        raise InputError(f"d: expected ({n_cls},) values > 0")
    if levels is not None and not (isinstance(levels, int) and 2 <= levels <= 12):
        raise InputError(f"levels = {levels!r}: expected an integer in [2, 12]")
    m_start = int(m_start)
    if n_cls * m_start * 4 > max_state:
        raise InputError(f"age-structured plug flow: {n_cls} classes x {4 * m_start} cells (three grids from "
                         f"{m_start}) exceed the state limit {max_state} (AXIS_MAX_STATE); expected fewer classes")
    start = time.perf_counter()
    K = breakage_matrix(kin.S, kin.b)
    kap, stencil = _kappa_of(kin.age, tau)
    fsum = max(float(feed.sum()), 1e-300)
    # the slowest class crosses in tau / min(v); the cells' spread decays at v M / tau or faster
    horizon = 20.0 * tau / float(np.min(v)) + 80.0 * tau / (float(np.min(v)) * m_start)
    rtol = max(ODE_SHARE * tol if rtol is None else float(rtol), 1e-13)
    atol = 0.1 * rtol
    tail_hold = max(1.0, 1.0 / float(np.min(v)))  # hold-up / tau of the tail per unit of mass left

    def solve(M, rt, at):
        T, exit_ = _upwind_transport(v, tau, M)
        y0 = np.zeros(T.shape[0])
        y0[:n_cls] = feed  # the feed enters the first cell at age 0
        p, hold, A, left, pts = _solve_ages(kap, K, T, exit_, y0, fsum, tau, horizon, rt, at, tail)
        return np.concatenate([p, hold / tau]), left, A, pts

    grids, values, lefts = [], [], []
    estimate, extrapolated = np.inf, None
    while True:
        M = m_start * 2 ** len(grids)
        if n_cls * M > max_state:
            break
        u, left, A, pts = solve(M, rtol, atol)
        grids.append(M)
        values.append(u)
        lefts.append(left)
        if len(grids) >= 3:
            now = _romberg_weights(len(grids)) @ np.array(values)
            before = _romberg_weights(len(grids) - 1) @ np.array(values[:-1])
            estimate = float(np.abs(now - before).max())
            extrapolated = now
            if (levels is None and estimate <= 0.5 * tol) or (levels is not None and len(grids) >= levels):
                break
        elif levels is not None and len(grids) >= levels:
            extrapolated = _romberg_weights(len(grids)) @ np.array(values)
            estimate = float(np.abs(values[-1] - values[-2]).max())
            break
    if extrapolated is None:
        raise InputError(f"age-structured plug flow: {n_cls} classes leave room for fewer than three grids under the "
                         f"state limit {max_state}; expected fewer classes or a smaller m_start")
    weights = _romberg_weights(len(grids))
    ode_err = 0.0
    if error_estimate:
        tight, _, _, _ = solve(grids[-1], max(0.1 * rtol, 3e-14), 0.1 * atol)
        ode_err = float(np.abs(weights).sum()) * float(np.abs(tight - values[-1]).max())
    tail_err = float(np.abs(weights).sum()) * max(lefts) * tail_hold
    err = estimate + ode_err + tail_err
    if levels is None and err > tol:
        raise SolverError(f"age-structured plug flow: error estimate {err:.3g} above the tolerance {tol:g} at "
                          f"{grids[-1]} cells (the state limit {max_state}); loosen tol or use fewer classes")
    p = extrapolated[:n_cls]
    how = ("age-structured plug flow: upwind cells in z (M tanks, d* at every outlet), BDF in the particle's age, "
           f"Romberg extrapolation to M -> infinity over M = {grids}")
    if stencil:
        how += " (kappa = theta' by a 4th-order stencil)"
    info = {"kinetics": kin.describe(), "m_cells": grids[-1], "grids": grids, "grid_error": estimate,
            "ode_error": ode_err, "tail_error": tail_err, "age_horizon_s": A, "ode_points": pts, "rtol": rtol,
            "classification": "none" if d is None else "d* on the axis (relative axial velocity)"}
    if holdup:
        info.update(holdup=tau * extrapolated[n_cls:], holdup_overflow=0.0)
    return NonlinearSteady(p, 0.0, how, 0.0, float(err), float(abs(p.sum() - feed.sum())), 0,
                           time.perf_counter() - start, info)
