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
open vessel (:func:`age_structured_open`) is the same balance on its whole line
(:mod:`millflow.mill.axial_open`), with the flux discharge from the kappa-weighted
integral of the mass upstream of z = 1 and the sampled one from the concentration at z = 1
(its hold-up with the back-dispersion layer in the age as well).
"""
from __future__ import annotations

import time
from typing import NamedTuple

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from millflow.errors import InputError, SolverError
from millflow.linalg import breakage_matrix
from millflow.mill.age_cells import AGE_TAIL, _kappa_of, integrate_ages
from millflow.mill.axial import refine_grids
from millflow.mill.finite_volume import closed_faces, node_losses, open_faces, open_nodes, tridiagonal
from millflow.mill.nonlinear_cell import NonlinearSteady, _check
from millflow.nonlinear.kinetics import Kinetics
from millflow.ode import integrate
from millflow.threads import limit_blas_threads

__all__ = ["age_structured_axial", "age_structured_plug", "AXIS_MAX_STATE", "AXIS_TOL", "age_structured_open"]

#: Default target of the error estimate (max abs error of product and hold-up / tau, of the feed).
AXIS_TOL = 1e-7
#: Largest ODE state (classes x nodes) the age-position balance may reach on its finest grid.
AXIS_MAX_STATE = 2**16
#: The ODE's relative tolerance is this share of ``tol`` (its error must not disturb the
#: Richardson estimate of the grid); absolute tolerance a tenth of that, of the feed.
ODE_SHARE = 1e-2
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
    n_cls = np.size(v)
    scale = 1.0 / (tau * faces.weights)  # c = m / (tau h_k)
    T = _node_major(*tridiagonal(faces, node_losses(faces, v)), scale, n_cls)
    last = faces.outlet * n_cls + np.arange(n_cls)
    exit_ = sp.csr_matrix((np.asarray(v, float) * scale[-1], (np.arange(n_cls), last)), shape=(n_cls, T.shape[0]))
    return T, exit_, faces.weights


def _slowest_decay(v, w, pe: float, tau: float) -> float:
    """Slowest decay rate [1/s] of the transport alone, from each class's operator on 32 volumes."""
    T, _, _ = _fv_transport(v, w, pe, tau, 32)
    n_cls = v.size
    dense = T.toarray()
    rates = [np.min(-np.linalg.eigvals(dense[i::n_cls, i::n_cls]).real) for i in range(n_cls)]
    return float(min(rates))


def _age_limits(slow: float, transport, tau: float, tol: float, rtol):
    """(horizon [s], rtol, atol, hold-up / tau of the tail per unit of mass left) of an age solve.

    ``slow`` the slowest decay rate [1/s] of the transport alone: the horizon is 80 of its
    decay times plus 10 tau; the ODE's rtol :data:`ODE_SHARE` x ``tol`` unless given, its
    atol a tenth of that (of the feed).
    """
    if not slow > 0:
        raise InputError(f"transport {transport!r}: some class never leaves the mill (decay rate <= 0)")
    rtol = max(ODE_SHARE * tol if rtol is None else float(rtol), 1e-13)
    return 80.0 / slow + 10.0 * tau, rtol, 0.1 * rtol, max(1.0, 1.0 / (slow * tau))


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


def _refined(grid, solve, *, tau, m_cells, cell_pe, tol, m_start, m_max, bytes_per_cell, rtol, atol,
             error_estimate):
    """The grids of an axial age solve refined (or one fixed grid) and the ODE's share of the error.

    ``grid(M)`` -> (nodes, mass left, product and hold-up / tau) at (rtol, atol); ``solve(M,
    rt, at)`` -> (product, hold-up, mass left). Grids are doubled by
    :func:`millflow.mill.axial.refine_grids` (Richardson, to ``tol`` / 2) unless ``m_cells``
    fixes one. The ODE part: the finest grid solved again at tolerances 10x tighter, the
    difference times the sum of |weights| of the extrapolation (5/3 when extrapolated).
    Returns (product and hold-up / tau, M, order, history, grid error, ODE error, mass left).
    """
    if m_cells is not None:
        _, left, both = grid(int(m_cells))
        loose, order, history, weight, M, grid_err = both, float("nan"), [], 1.0, int(m_cells), 0.0
    else:
        both, grid_err, order, history, finest, _, extrapolated = refine_grids(
            grid, cell_pe, tol=0.5 * tol, m_start=m_start, m_max=m_max, bytes_per_cell=bytes_per_cell)
        M = max(m for m, _ in history if isinstance(m, int))  # the finest grid solved
        left, loose = finest[1], finest[2]
        weight = 5.0 / 3.0 if extrapolated else 1.0  # sum |w| of r = p4 + (p4 - p2) / 3
    ode_err = 0.0
    if error_estimate:
        p2, h2, left2 = solve(M, max(0.1 * rtol, 3e-14), 0.1 * atol)
        tight = np.concatenate([p2, h2 / tau])
        ode_err = weight * float(np.abs(tight - loose).max())
        if m_cells is not None:
            both, left = tight, left2
    return both, M, order, history, float(grid_err), ode_err, left


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
        Pe (``.pe``); bc "open" is :func:`age_structured_open` with the sampled discharge (the
        linear open vessel's default), rtd.PlugFlow :func:`age_structured_plug`.
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
    if transport.bc != "closed":  # the open vessel, with the linear open vessel's default discharge
        return age_structured_open(kin, feed, transport, d, dispersion=dispersion, discharge="sampled", tol=tol,
                                   rtol=rtol, tail=tail, m_start=m_start, m_cells=m_cells, max_state=max_state,
                                   error_estimate=error_estimate, holdup=holdup)
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
    horizon, rtol, atol, tail_hold = _age_limits(_slowest_decay(v, w, pe, tau), transport, tau, tol, rtol)
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

    both, M, order, history, grid_err, ode_err, left = _refined(
        grid, solve, tau=tau, m_cells=m_cells, cell_pe=cell_pe, tol=tol, m_start=m_start,
        m_max=max(m_max, 4 * m_start), bytes_per_cell=8.0 * 60 * n_cls, rtol=rtol, atol=atol,
        error_estimate=error_estimate)
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


def _node_major(lower, diag, upper, scale, n_cls: int):
    """-A diag(scale) of one tridiagonal system per class, node-major (index k N + i), sparse csc."""
    nodes = diag.shape[1]
    idx = np.arange(nodes)[:, None] * n_cls + np.arange(n_cls)[None, :]
    rows = np.concatenate([idx[1:].ravel(), idx[:-1].ravel(), idx.ravel()])
    cols = np.concatenate([idx[:-1].ravel(), idx[1:].ravel(), idx.ravel()])
    vals = -np.concatenate([(np.asarray(lower).T * scale[:-1, None]).ravel(),
                            (np.asarray(upper).T * scale[1:, None]).ravel(), (diag.T * scale[:, None]).ravel()])
    n = nodes * n_cls
    return sp.csc_matrix((vals, (rows, cols)), shape=(n, n))


def _open_transport(v, w, pe: float, tau: float, m_cells: int, length: float, back_layer: bool):
    """The open vessel's finite-volume transport on the masses of the volumes of the whole line.

    Returns (T_X sparse csc [1/s] on X = (m, m^) node-major, faces): m the masses of the
    whole line (:func:`millflow.mill.finite_volume.open_faces` with tails of ``length``,
    the outflow v at the last node), and with ``back_layer`` m^ the masses of the sampled
    discharge's back-dispersion layer on the nodes upstream of z = 1 (the source-free
    equations with c^(1) = c(1), which enters the layer's last node through the face
    between them, :func:`millflow.mill.axial_open.back_layer_matrix`).
    """
    faces = open_faces(pe, m_cells, v, w, length)
    n_cls = np.size(v)
    scale = 1.0 / (tau * faces.weights)
    T = _node_major(*tridiagonal(faces, node_losses(faces, v)), scale, n_cls)
    if not back_layer:
        return T, faces
    k1 = faces.outlet
    alpha, beta = faces.alpha[:, :k1 - 1], faces.beta[:, :k1 - 1]
    diag = np.zeros((n_cls, k1))
    diag[:, :-1] += alpha
    diag[:, 1:] += beta
    diag[:, -1] += faces.alpha[:, k1 - 1]  # what flows on to the fixed node z = 1
    Tb = _node_major(-alpha, diag, -beta, scale[:k1], n_cls)
    # c(1) = m_(k1) / (tau w_(k1)) enters node k1 - 1 of the layer at beta c(1)
    src = sp.csc_matrix((faces.beta[:, k1 - 1] * scale[k1],
                         ((k1 - 1) * n_cls + np.arange(n_cls), k1 * n_cls + np.arange(n_cls))),
                        shape=(k1 * n_cls, T.shape[0]))
    return sp.bmat([[T, None], [src, Tb]], format="csc"), faces


class OpenGrid(NamedTuple):
    """The open vessel's age operators on one grid (:func:`open_grid`), node-major (k N + i).

    Attributes
    ----------
    TX : sparse csc (nx, nx)
        The transport [1/s] on X = (m, m^): the masses of the whole line, then those of the
        sampled discharge's back layer (if any).
    n : int
        The states of the line (the first n of X).
    inlet : slice
        The states of the volume of z = 0, where the feed enters.
    upstream : sparse csr (N, nx)
        The mass of each class upstream of z = 1 (the discharge volume's left half).
    exit : sparse csr (N, nx)
        The product rate [1/s] of a content X: ``"sampled"`` v c(1) = v m_(k1) / (tau w_k1);
        ``"flux"`` the net flux through z = 1, -upstream TX (the transport's outflow of the
        part upstream of z = 1; breakage moves mass between classes, not across z = 1).
    hold : sparse csr (N, nx)
        The hold-up of a content X: ``upstream`` (flux; sampled without the layer), plus the
        back layer and its half volume at z = 1 on c(1) (sampled with the layer).
    faces : millflow.mill.finite_volume.AxialFaces
        The grid.
    """

    TX: sp.csc_matrix
    n: int
    inlet: slice
    upstream: sp.csr_matrix
    exit: sp.csr_matrix
    hold: sp.csr_matrix
    faces: object


def open_vessel(n_cls: int, tau: float, pe: float, d, dispersion, discharge):
    """The open vessel's checked classification: (v, w, discharge, tail length [mill lengths]).

    v = d* (None: 1), w = ``dispersion`` (None: v, one Peclet number), the discharge checked
    by :func:`millflow.mill.axial_open.check_discharge` (sampled refused for unequal Peclet
    numbers), the tails of :func:`millflow.mill.axial_open.tail_length` without breakage
    (which holds for any kappa).
    """
    from millflow.mill.axial_open import check_discharge, tail_length

    v = np.ones(n_cls) if d is None else np.asarray(d, float)
    w = v.copy() if dispersion is None else np.asarray(dispersion, float)
    for name, x in (("d", v), ("dispersion", w)):
        if x.shape != (n_cls,) or not np.all(np.isfinite(x)) or np.any(x <= 0):
            raise InputError(f"{name}: expected ({n_cls},) values > 0")
    if not (np.isfinite(pe) and pe > 0):
        raise InputError(f"Pe = {pe!r}: expected a Peclet number > 0")
    discharge = check_discharge(discharge, v, w)
    return v, w, discharge, tail_length(np.zeros(n_cls), tau, pe, v, w)


def open_slowest_decay(v, w, pe: float, tau: float, length: float) -> float:
    """Slowest decay rate [1/s] of the open line's transport alone, each class on 32 volumes."""
    n_cls = np.size(v)
    T32, _ = _open_transport(v, w, pe, tau, 32, length, False)
    dense = T32.toarray()
    return float(min(np.min(-np.linalg.eigvals(dense[i::n_cls, i::n_cls]).real) for i in range(n_cls)))


def open_grid(v, w, pe: float, tau: float, m_cells: int, length: float, flux: bool, layer: bool) -> OpenGrid:
    """The open vessel's transport, inlet, exit and hold-up on one grid (:class:`OpenGrid`).

    One home for the steady (:func:`age_structured_open`) and the transient
    (:mod:`millflow.mill.age_transient`) age solvers; ``layer`` adds the sampled discharge's
    back-dispersion layer (:func:`_open_transport`).
    """
    TX, faces = _open_transport(v, w, pe, tau, m_cells, length, layer)
    n_cls = np.size(v)
    nx = TX.shape[0]
    n = faces.z.size * n_cls
    k0, k1 = faces.inlet, faces.outlet
    cls = np.tile(np.arange(n_cls), faces.z.size)
    u = np.repeat(faces.upstream / faces.weights, n_cls)  # share of each volume upstream of z = 1
    upstream = sp.csr_matrix((u, (cls, np.arange(n))), shape=(n_cls, nx))
    upstream.eliminate_zeros()
    if flux:
        exit_ = sp.csr_matrix(-(upstream @ TX))
    else:
        exit_ = sp.csr_matrix((np.asarray(v, float) / (tau * faces.weights[k1]),
                               (np.arange(n_cls), k1 * n_cls + np.arange(n_cls))), shape=(n_cls, nx))
    hold = upstream
    if layer:
        nl = nx - n  # the layer's states, nodes 0 .. k1 - 1
        half = 0.5 * faces.h[k1 - 1] / faces.weights[k1]  # its half volume at z = 1, on c(1)
        hold = hold + sp.csr_matrix((np.ones(nl), (np.tile(np.arange(n_cls), nl // n_cls), n + np.arange(nl))),
                                    shape=(n_cls, nx))
        hold = hold + sp.csr_matrix((np.full(n_cls, half), (np.arange(n_cls), k1 * n_cls + np.arange(n_cls))),
                                    shape=(n_cls, nx))
    return OpenGrid(TX, n, slice(k0 * n_cls, (k0 + 1) * n_cls), upstream, exit_, sp.csr_matrix(hold), faces)


def _solve_open_ages(kap, K, TX, n, y0, fsum, tau, horizon, rtol, atol, tail, kappa_weighted: bool):
    """One solve of the open vessel's age ODE on one grid.

    The state X (the masses m of the line, then the back layer's, if any), its running
    integral Q = int_0^a X and, with ``kappa_weighted``, R = int_0^a kappa m (the product of
    the flux discharge). Stops when the mass on the line is below ``tail`` of the feed;
    the rest is closed at kappa(A). Returns (Q, R or None, A, mass left, points).
    """
    nx, n_cls = y0.size, K.shape[0]
    Kb = sp.kron(sp.identity(nx // n_cls, format="csc"), sp.csc_matrix(K), format="csc")
    eye, zx = sp.identity(nx, format="csc"), sp.csc_matrix((nx, nx))
    blocks_T = [[TX, zx], [eye, zx]]
    blocks_K = [[Kb, zx], [zx, zx]]
    if kappa_weighted:
        pick = sp.identity(nx, format="csc")[:n]  # m out of X
        zr, zrx = sp.csc_matrix((n, n)), sp.csc_matrix((nx, n))
        blocks_T = [row + [zrx] for row in blocks_T] + [[sp.csc_matrix((n, nx)), sp.csc_matrix((n, nx)), zr]]
        blocks_K = [row + [zrx] for row in blocks_K] + [[pick, sp.csc_matrix((n, nx)), zr]]
    J_T = sp.bmat(blocks_T, format="csc")
    J_K = sp.bmat(blocks_K, format="csc")
    KT = np.ascontiguousarray(K.T)

    def rhs(a, y):
        x = y[:nx]
        k = kap(a)
        dx = TX @ x + k * (x.reshape(-1, n_cls) @ KT).ravel()
        return np.concatenate([dx, x, k * x[:n]]) if kappa_weighted else np.concatenate([dx, x])

    def jac(a, _y):
        return J_T + kap(a) * J_K

    def left(_a, y):
        return float(y[:n].sum()) - tail * fsum
    left.terminal, left.direction = True, -1
    at = [np.full(nx, atol * fsum), np.full(nx, atol * fsum * tau)]
    y_init = [y0, np.zeros(nx)]
    if kappa_weighted:
        at.append(np.full(n, atol * fsum * tau))
        y_init.append(np.zeros(n))
    sol = integrate(rhs, (0.0, horizon), np.concatenate(y_init), method="BDF", jac=jac, rtol=rtol,
                    atol=np.concatenate(at), events=left,
                    what="age-structured open axial mill (the ODE in the age)")
    if sol.status != 1:
        raise SolverError(f"age-structured open axial mill: {sol.y[:n, -1].sum() / fsum:.3g} of the feed is still on "
                          f"the line at age {horizon:.4g} s (the horizon); expected it below {tail:g}")
    A, y = float(sol.t[-1]), sol.y[:, -1]
    xA, Q = y[:nx], y[nx:2 * nx].copy()
    kA = kap(A)
    rest = splu(-(TX + kA * Kb).tocsc()).solve(xA)  # int_A^inf X at kappa(A)
    Q += rest
    R = y[2 * nx:] + kA * rest[:n] if kappa_weighted else None
    return Q, R, A, float(max(xA.sum(), 0.0)), int(sol.t.size)


@limit_blas_threads
def age_structured_open(kin: Kinetics, feed, transport, d=None, *, dispersion=None, discharge: str = "flux",
                        tol: float = AXIS_TOL, rtol: float | None = None, tail: float = AGE_TAIL, m_start: int = 16,
                        m_cells: int | None = None, max_state: int = AXIS_MAX_STATE, error_estimate: bool = True,
                        holdup: bool = True) -> NonlinearSteady:
    """The open axial-dispersion vessel with S_i = S_i0 kappa(a) and classification on the axis.

    The age-position balance of the module docstring on the open vessel's whole line
    (:mod:`millflow.mill.axial_open`: the mill [0, 1] in M uniform volumes and a stretched
    tail of M volumes on each side, zero flux at the upstream end, outflow at the
    downstream one), the feed entering the node of z = 0 at age 0. The tails end at
    L_t = 40 / min_i Pe_i (:func:`millflow.mill.axial_open.tail_length` without breakage,
    which holds for any kappa). On the masses m_k = tau w_k c_k of the volumes (w_k [-]
    the control volumes) dm/da = (kappa(a) Kb + T) m, integrated until the mass on the
    whole line is below ``tail`` of the feed, the rest closed at kappa(A). Discharges:

    - ``"flux"``: the net flux through z = 1 from the balance of (-inf, 1],
      p = f + K int_0^inf kappa(a) U(a) da with U(a) = sum_k u_k m_k(a) the mass upstream of
      z = 1 (u_k = ``faces.upstream`` / ``faces.weights``: the discharge node's left half);
      the running integral of kappa m is carried as extra states. Hold-up
      int_0^inf U(a) da. Mass is conserved to rounding for any v, w.
    - ``"sampled"``: p_i = v_i c_i(1) = v_i int_0^inf m_i(1, a) da / (tau w_(k1)); refused
      for unequal Peclet numbers Pe v_i / w_i (as the linear vessel). Hold-up: that upstream
      of z = 1 plus the back-dispersion layer, whose age form is the same balance on
      (-inf, 1] without source and with c^(1, a) = c(1, a) (carried as extra states; its
      integral over ages is the linear layer, so with v = w = 1 the hold-up is the
      segregated int (1 - F(t)) exp(K theta(t)) f dt with the open density's F).

    Grids refined as :func:`age_structured_axial` (Richardson on M, 2M, 4M, ...); error
    estimate = grid + ODE (tight against loose) + tail.

    Parameters
    ----------
    kin : millflow.nonlinear.Kinetics
        S_i0 [1/s], b and kappa(t), the age t in s.
    feed : (N,) feed flows (mass per unit time; the product is in the same units).
    transport : rtd.AxialDispersion with bc "open": tau = L/u [s] (``.tau``; its mean is
        tau (1 + 2/Pe)) and Pe (``.pe``).
    d : (N,) relative axial velocity d_i* > 0 [-] (None: 1).
    dispersion : (N,) relative dispersion w_i > 0 [-] (None: d, the open vessel's default).
    discharge : "flux" (net flux through z = 1) or "sampled" (v c(1)).
    tol, rtol, tail, m_start, m_cells, max_state, error_estimate, holdup : as
        :func:`age_structured_axial` (the state counts the nodes of the whole line).

    Returns
    -------
    NonlinearSteady
        As :func:`age_structured_axial`; ``info["discharge"]``, ``info["tail_length"]`` [mill
        lengths], ``info["holdup"]`` [s] with ``holdup``.
    """
    import rtd

    if not (isinstance(transport, rtd.AxialDispersion) and transport.bc == "open"):
        raise InputError(f"transport {transport!r}: age_structured_open solves rtd.AxialDispersion(bc='open')")
    tau, pe = float(transport.tau), float(transport.pe)
    feed, tau = _check(kin, feed, tau)
    if kin.age is None:
        raise InputError("age_structured_open: the kinetics have no kappa(t) (kinetics(..., kappa_t=...))")
    n_cls = kin.n
    v, w, discharge, length = open_vessel(n_cls, tau, pe, d, dispersion, discharge)
    flux = discharge == "flux"
    cell_pe = float(np.max(v / w)) * pe
    need = max(int(m_start), int(np.ceil(cell_pe))) if m_cells is None else int(m_cells)

    def state(M):  # classes x (nodes of the line + those of the sampled discharge's back layer)
        z, _, k1 = open_nodes(length, M)
        return n_cls * (z.size + (0 if flux or not holdup else k1))

    if state(need) > max_state:
        raise InputError(f"age-structured open axial mill: {n_cls} classes on the grid of {need} volumes in the mill "
                         f"(where the cell Peclet number Pe d*/dispersion h = {cell_pe:.3g} h reaches 1) and its "
                         f"tails ({state(need)} states) exceed the state limit {max_state} (AXIS_MAX_STATE); "
                         "expected fewer classes or a smaller Pe")
    start = time.perf_counter()
    K = breakage_matrix(kin.S, kin.b)
    kap, stencil = _kappa_of(kin.age, tau)
    fsum = max(float(feed.sum()), 1e-300)
    slow = open_slowest_decay(v, w, pe, tau, length)
    horizon, rtol, atol, tail_hold = _age_limits(slow, transport, tau, tol, rtol)
    solves = {}

    def solve(M, rt, at):
        g = open_grid(v, w, pe, tau, M, length, flux, not flux and holdup)
        y0 = np.zeros(g.TX.shape[0])
        y0[g.inlet] = feed  # the feed enters the volume of z = 0 at age 0
        Q, R, A, left, pts = _solve_open_ages(kap, K, g.TX, g.n, y0, fsum, tau, horizon, rt, at, tail, flux)
        # the flux product from the kappa-weighted integral (conserves mass to rounding on any
        # grid), the sampled one from the exit weights
        p = feed + K @ (g.upstream[:, :g.n] @ R) if flux else g.exit @ Q
        solves[M] = (A, left, pts)
        return p, g.hold @ Q, left

    def grid(M):
        p, hold, left = solve(M, rtol, atol)
        return None, left, np.concatenate([p, hold / tau])

    m_max = int(m_start)
    while state(2 * m_max) <= max_state:
        m_max *= 2
    both, M, order, history, grid_err, ode_err, left = _refined(
        grid, solve, tau=tau, m_cells=m_cells, cell_pe=cell_pe, tol=tol, m_start=m_start,
        m_max=max(m_max, 4 * m_start), bytes_per_cell=8.0 * 60 * 4 * n_cls, rtol=rtol, atol=atol,
        error_estimate=error_estimate)
    tail_err = left * tail_hold
    err = grid_err + ode_err + tail_err
    p = both[:n_cls]
    A, _, pts = solves[M]
    how = (f"age-structured open axial dispersion ({discharge} discharge): finite volumes on the whole line, BDF in "
           "the particle's age with the sparse Jacobian, tail closed at kappa(A), grid refined (Richardson)")
    if stencil:
        how += " (kappa = theta' by a 4th-order stencil)"
    info = {"kinetics": kin.describe(), "m_cells": M, "state_size": state(M), "order": order,
            "history": history, "grid_error": float(grid_err), "ode_error": float(ode_err),
            "tail_error": float(tail_err), "age_horizon_s": A, "mass_left_at_horizon": left / fsum,
            "ode_points": pts, "rtol": rtol, "discharge": discharge, "tail_length": length,
            "classification": "none" if d is None else "d* on the axis (relative axial velocity)"}
    if holdup:
        info.update(holdup=tau * both[n_cls:], holdup_overflow=0.0)
    return NonlinearSteady(p, 0.0, how, 0.0, float(err), float(abs(p.sum() - feed.sum())), 0,
                           time.perf_counter() - start, info)
