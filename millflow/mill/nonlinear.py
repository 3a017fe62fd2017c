"""Continuous mills with non-linear kinetics: the steady product of eq. 1 with R(M).

Continuous mills with non-linear kinetics (aggregation, population-dependent rates,
slowing-down kappa(fines) or kappa(t)): the steady product of eq. 1 with R(M) of
:mod:`millflow.nonlinear.kinetics` in place of the linear K M, for every transport of
the linear mill, with classification d* where the linear mill takes it.

- perfect mixing:   0 = f - d* y + tau R(y), y = hold-up / tau (p = d* y), by Newton
  (:mod:`millflow.mill.newton`: factors kept while the chord iteration contracts,
  pseudo-transient continuation if Newton stalls);
- tanks in series:  one cell at a time, cell k at tau/n fed by cell k - 1 (d* at the last
  cell, every cell or the listed ones), each cell's Newton started from the previous
  cell's factors (a warm start: the cells differ little);
- networks of cells (recirculating cells, compartment networks): the cells' linear
  exchange plus V_k R(c_k) per cell, Newton on the block system (sparse LU) (:func:`cells`);
- plug flow:        the ODE in the position along the mill, dF/dz = tau R(F / d*) (the
  batch grind in contact time without classification; class i travelling at d_i* u with
  it), product F(1) (:func:`plug_flow`);
- axial dispersion: the steady convection-dispersion-reaction equation discretised
  exactly as :mod:`millflow.mill.axial` (closed vessel) and :mod:`millflow.mill.axial_open`
  (open vessel, sampled or flux discharge), Newton on all nodes, grids refined until the
  Richardson estimate meets the tolerance (:mod:`millflow.mill.nonlinear_axial`);
- series and parallel compositions (``rtd.Series``, ``rtd.Parallel``): each part's product
  feeds the next / the feed split by the weights, each part by its own solver
  (:func:`solve_transport`);
- slowing-down in the material's age (kappa(t), :class:`~millflow.nonlinear.kinetics.AgeSlowing`):
  without classification the product is exactly segregated flow, int E(t) exp(K theta(t)) f dt
  (:func:`age_slowing`); with classification d* in cells (perfect mixing, tanks in series,
  recirculating cells, compartment networks) no one E(t) applies (a particle's exit depends
  on the class it is in, which changes as it breaks) and the age-structured balance of
  :mod:`millflow.mill.age_cells` is solved, one linear ODE in the age; with classification on
  the axis of the closed or open axial-dispersion vessel age and position are not tied and
  the age-position balance of :mod:`millflow.mill.age_axis` is solved (finite volumes in z,
  on the open vessel's whole line with its flux or sampled discharge, one sparse linear ODE
  in the age), and for plug flow the limit of upwind cells extrapolated in 1/M (Romberg);
- micromixing limits for any RTD model with ``pdf``/``cdf``: complete segregation,
  int_0^inf E(t) M_batch(t) dt, and maximum mixedness (Zwietering 1959),
  dM/dlambda = -R(M) + h(lambda) (M - f), h = E/(1 - F), integrated from large lambda
  (where M solves the same equation with dM/dlambda = 0) down to lambda = 0, product M(0).
  For first-order kinetics the two coincide (the RTD fixes the product, segregated flow
  is exact); then one linear answer is returned and the result says so. Otherwise they
  are the two limits of mixing, not bounds on the product: Zwietering's ordering of the
  conversion holds for one species with a rate of one convexity (e.g. a single class
  breaking at a rate falling with its own amount), not class by class for a population
  whose rates couple (four tanks in series with nipping or cushioning rates lie outside both).

A linear scene (nothing non-linear declared) takes the exact linear path of
:mod:`millflow.linalg` / :mod:`millflow.mill` with nothing added. A steady solve that
does not reach its tolerance raises SolverError naming the unit and the residual. Newton's
criterion is scaled: max|F| <= tol * s with s the size of the terms of F (feed, state,
breakage flux; :func:`residual_scale`), tol = :data:`NEWTON_RTOL` = 1e-11 by default, or,
at the rounding floor where no step reduces max|F|, a full Newton step below tol * s.
The state carries the aggregation overflow (mass above the top class) as component N + 1:
it leaves with the product and is reported as ``overflow_mass``.

The feed is used as given: non-linear rates depend on the amount of material, so the
state is in the feed's units (give it as flows per unit nominal feed rate, e.g. mass
fractions of a unit feed, for which the cell state is the hold-up mass fraction).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from scipy import special

from millflow.errors import InputError, SolverError
from millflow.mill.age_cells import AXIS_REFUSED, age_structured
from millflow.mill.newton import MAX_ITER, PTC_ITER, ChainFactor, SparseFactor, newton
from millflow.mill.nonlinear_axial import axial_dispersion, axial_open
from millflow.mill.nonlinear_cell import (GRID_NOTE, NEWTON_RTOL, NonlinearSteady, _blas, _cell_guess, _check,  # noqa: F401
                                          _discharge, _FirstOrder, _newton_cell, _no_age, _solve_cell, _SplitError,
                                          residual_scale, well_mixed)
from millflow.mill.well_mixed import solve_well_mixed
from millflow.nonlinear.kinetics import Kinetics
from millflow.ode import integrate
from millflow.threads import limit_blas_threads

__all__ = ["NonlinearSteady", "MicromixingLimits", "MicromixingBounds", "well_mixed", "tanks_in_series", "cells",
           "plug_flow", "axial_dispersion", "axial_open", "solve_transport", "age_slowing", "micromixing_limits",
           "micromixing_bounds", "NEWTON_RTOL"]

def tanks_in_series(kin: Kinetics, feed, tau: float, n: int, d=None, where="discharge", *,
                    tol: float = NEWTON_RTOL, max_iter: int = MAX_ITER, ptc_iter: int = PTC_ITER) -> NonlinearSteady:
    """Non-linear kinetics in n equal perfect mixers in series (total mean residence time tau).

    ``d`` (N,) normalised discharge d_i* (None: none), acting where ``where`` says:
    "discharge" (the last cell's outflow), "cells" (every cell's outflow) or a sequence
    of 1-based cell numbers; each cell is :func:`well_mixed` at tau / n with its d*.
    All cells are solved together by Newton (the Jacobian of the chain is block lower
    bidiagonal: one LU per cell and a forward substitution; the rates of all cells in one
    vectorised call), started from the first-order cells with the rates frozen at the
    previous cell's content; error estimate: the last cell's outflow under the next chord
    step (:mod:`millflow.mill.newton`). If that does not converge, the cells are solved
    one at a time, each with pseudo-transient continuation (:func:`_one_by_one`).
    """
    feed, tau = _check(kin, feed, tau)
    if int(n) != n or n < 1:
        raise InputError(f"n = {n!r}: expected an integer number of tanks >= 1")
    _no_age(kin, "tanks in series")
    n = int(n)
    dx = _discharge(kin, d)
    mask = _classified(n, where)
    start = time.perf_counter()
    if kin.is_linear:
        p, held = feed, []
        for k in range(n):
            dk = dx[:-1] if dx is not None and mask[k] else None
            p = solve_well_mixed(kin.S, kin.b, p, tau / n, dk)
            held.append(tau / n * (p if dk is None else p / dk))
        return NonlinearSteady(p, 0.0, "exact linear (cells)", 0.0, float(np.finfo(float).eps * kin.n * n),
                               float(abs(p.sum() - feed.sum())), 0, time.perf_counter() - start,
                               {"kinetics": "linear", "cells": np.array(held), "cells_overflow": np.zeros(n),
                                "holdup": np.sum(held, axis=0)})
    y_in = np.append(feed, 0.0)
    Dm = np.ones((n, kin.n + 1)) if dx is None else np.where(mask[:, None], dx[None, :], 1.0)
    with _blas():
        try:
            Y, r = _chain(kin, y_in, tau / n, Dm, tol=tol, max_iter=max_iter)
            its, nfac, res, how = r.iterations, r.factorizations, r.residual, "Newton on the chain of cells"
            err = float(np.abs(Dm[-1] * r.correction.reshape(n, -1)[-1]).max()) / (1.0 - r.rho)
            herr = tau / n * float(np.abs(r.correction.reshape(n, -1)[:, :-1]).sum(axis=0).max()) / (1.0 - r.rho)
        except SolverError as exc:  # the robust path: cell by cell, each with its pseudo-transient fallback
            Y, its, nfac, res, err, how = _one_by_one(kin, y_in, tau / n, Dm, tol, max_iter, ptc_iter)
            herr = tau * err / float(Dm.min())  # each cell's content error is at most its outflow's / d*
            how += f" (the chain did not converge: {exc})"
    out = Dm[-1] * Y[-1]
    cells = tau / n * Y  # (n, N + 1): hold-up per unit feed rate [s], the overflow last
    return NonlinearSteady(out[:-1], float(out[-1]), f"cells, {how}", res, err, float(abs(out.sum() - feed.sum())),
                           its, time.perf_counter() - start,
                           {"kinetics": kin.describe(), "cells": cells[:, :-1], "cells_overflow": cells[:, -1],
                            "holdup": cells[:, :-1].sum(axis=0), "holdup_error_estimate": herr,
                            "factorizations": nfac})


def _chain_guess(kin: Kinetics, y_in, tau, Dm):
    """A start for the chain: first-order cells with frozen rates.

    First-order cells in turn, each with the rates frozen at the previous cell's content
    (a Picard start carrying the population and fines terms), the overflow passing.
    """
    n = Dm.shape[0]
    Y = np.empty((n, y_in.size))
    state, inflow, first = None, y_in, _FirstOrder(kin.b)
    for k in range(n):
        dk = None if np.all(Dm[k] == 1.0) else Dm[k]
        Y[k] = _cell_guess(kin, inflow, tau, dk, state, passes=3, first=first)  # 3: measured 5 % faster
        state, inflow = Y[k, :-1], Dm[k] * Y[k]
    return Y


def _chain(kin: Kinetics, y_in, tau, Dm, *, tol, max_iter):
    """All cells of a chain together by Newton with a block bidiagonal Jacobian.

    All cells of a chain together: F_k = D_(k-1) y_(k-1) - D_k y_k + tau R(y_k) (y_(-1) D = the
    feed), Newton with the block lower bidiagonal Jacobian (forward substitution, one LU
    per cell, kept while the chord iteration contracts): the rates of all cells in one
    vectorised evaluation.
    """
    n, n1 = Dm.shape
    diag = np.arange(n1)
    feed_size = float(np.abs(y_in).sum())

    def F(v):
        Y = v.reshape(n, n1)
        out = tau * kin.rate_many(Y) - Dm * Y
        out[0] += y_in
        out[1:] += Dm[:-1] * Y[:-1]
        return out.ravel()

    def factor(v, shift):
        def blocks():
            for s0, J in kin.jacobian_chunks(v.reshape(n, n1)):
                for i, Jk in enumerate(J):
                    A = tau * Jk
                    A[diag, diag] -= Dm[s0 + i] + shift
                    yield A
        return ChainFactor(blocks(), Dm[:-1])

    def scale(v):
        Y = v.reshape(n, n1)
        try:
            flux = float(np.abs(kin.rates(Y[:, :-1]) * Y[:, :-1]).sum(axis=1).max())
        except SolverError:
            flux = 0.0
        return float(max(feed_size, np.abs(Y).max(), np.abs(Dm * Y).max(), tau * flux))

    r = newton(F, factor, _chain_guess(kin, y_in, tau, Dm).ravel(), scale, tol=tol, max_iter=max_iter,
               unit=f"tanks in series ({n} cells together)", what=kin.describe(), phases=("newton",))
    return r.y.reshape(n, n1), r


def _one_by_one(kin: Kinetics, y_in, tau, Dm, tol, max_iter, ptc_iter):
    """The cells of a chain one at a time, each by Newton with pseudo-transient continuation.

    Started from the previous cell's factors. Error estimate: the sum over the cells of each
    cell's estimate in the 1-norm (an error in a cell's outflow passes through the cells
    downstream, maps whose columns sum to ~1: mass is conserved).
    """
    n = Dm.shape[0]
    Y = np.empty((n, y_in.size))
    y, warm, state = y_in, None, None
    its = nfac = 0
    res = err = 0.0
    for k in range(n):
        dk = None if np.all(Dm[k] == 1.0) else Dm[k]
        r = _solve_cell(kin, y, tau, _cell_guess(kin, y, tau, dk, state), tol=tol, max_iter=max_iter,
                        ptc_iter=ptc_iter, unit=f"tanks in series, cell {k + 1} of {n}", d=dk, warm=warm)
        Y[k] = r.y
        warm, state, y = r.factor, r.y[:-1], Dm[k] * r.y
        its, nfac, res = its + r.iterations, nfac + r.factorizations, max(res, r.residual)
        err += float(np.abs(r.correction * Dm[k]).sum()) / (1.0 - r.rho)
    return Y, its, nfac, res, err, "cell by cell"


def _classified(n: int, where) -> np.ndarray:
    """The cells whose outflow is classified.

    Cells (n,) whose outflow is classified: "discharge" the last (a chain's exit),
    "cells" all, or the listed 1-based cells.
    """
    if where in (None, "discharge"):
        mask = np.zeros(n, dtype=bool)
        mask[-1] = True
        return mask
    if where == "cells":
        return np.ones(n, dtype=bool)
    if isinstance(where, str):
        raise InputError(f"where = {where!r}: expected 'discharge', 'cells' or 1-based cell numbers")
    idx = np.asarray(list(where), dtype=int)
    if idx.size == 0 or idx.min() < 1 or idx.max() > n:
        raise InputError(f"where = {list(where)!r}: expected cell numbers in 1..{n}")
    mask = np.zeros(n, dtype=bool)
    mask[idx - 1] = True
    return mask


def network_operator(net, dx, where, n1: int):
    """The cells' linear exchange on the stacked state.

    The cells' linear exchange on the stacked state c (cells x n1 components, c_k the
    content of cell k per unit volume): (T sparse (n n1, n n1), inlet (n,) the share of the
    feed entering each cell, (1 - beta) u_k, out (n1, n) the product per unit content, H_l o_l),
    with the classification factors G (inter-cell flows), H (exit flows) of ``where``
    (:mod:`millflow.mill.cells`): (T c)_k = sum_(l != k) G_l F[k, l] c_l - (G_k sum_(j != k) F[j, k] + H_k o_k) c_k.
    """
    import scipy.sparse

    from millflow.mill.cells import _factors

    n = int(net.n)
    Fl = np.asarray(net.flows, float)
    o = np.asarray(net.outlet, float)
    G, H = _factors(dx, n1, n, where)  # (n1, n)
    rows, cols, vals = [], [], []
    idx = np.arange(n1)
    for k in range(n):
        for l in range(n):
            if k != l and Fl[k, l] != 0.0:
                rows.append(k * n1 + idx); cols.append(l * n1 + idx); vals.append(G[:, l] * Fl[k, l])  # noqa: E702
        rows.append(k * n1 + idx); cols.append(k * n1 + idx)  # noqa: E702
        vals.append(-(G[:, k] * Fl[:, k].sum() - G[:, k] * Fl[k, k] + H[:, k] * o[k]))
    T = scipy.sparse.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                                shape=(n * n1, n * n1))
    return T, (1.0 - float(net.bypass)) * np.asarray(net.inlet, float), H * o[None, :]


def cells(kin: Kinetics, feed, transport, d=None, where="discharge", *, tol: float = NEWTON_RTOL,
          max_iter: int = MAX_ITER, ptc_iter: int = PTC_ITER) -> NonlinearSteady:
    """Steady product of a network of well-mixed cells with non-linear kinetics.

    Steady product of a network of well-mixed cells (``transport`` an rtd model with a
    ``network()``, e.g. :class:`rtd.RecirculatingCells`, or an
    :class:`rtd.CompartmentNetwork`) with non-linear kinetics and classification.

    Cell k (volume V_k in time x feed flow, flows F[k, l] from l to k, exit flow o_k,
    inlet fraction u_k, bypass beta) holds c_k = m_k / V_k per unit feed rate (the
    state of :func:`well_mixed` for one cell). The steady balance of eq. 1 per cell,
    with the transport of :mod:`millflow.mill.cells` and R per cell:

        0 = (1 - beta) u_k f + sum_{l != k} G_l F[k, l] c_l
            - (G_k sum_j F[j, k] + H_k o_k) c_k + V_k R(c_k),

    G, H the classification factors on inter-cell and exit flows (d* or 1, by
    ``where``: "discharge", "cells" or 1-based cell numbers). Product
    p = beta f + sum_l H_l o_l c_l. Newton on all cells together with the analytic
    Jacobian (the constant transport part plus the blocks V_k dR/dc, sparse LU, kept
    while the chord iteration contracts), line search, pseudo-transient continuation if
    Newton stalls (its own budget ``ptc_iter``); the stated criterion of
    :func:`well_mixed` with the scale max(feed, transport flows x state, V_k breakage
    flux). Error estimate: the product's change under the next (chord) step at the
    answer, divided by 1 - rho (:mod:`millflow.mill.newton`).
    """
    import scipy.sparse

    from millflow.mill.cells import network_of, solve_cells
    feed, _ = _check(kin, feed, 1.0)
    _no_age(kin, "recirculating cells")
    net = network_of(transport)
    if net is None:
        raise InputError(f"transport {transport!r}: expected a network of cells (e.g. rtd.RecirculatingCells)")
    start = time.perf_counter()
    dx = _discharge(kin, d)
    n, n1 = int(net.n), kin.n + 1
    if where not in (None, "discharge", "cells"):
        _classified(n, where)  # checks the cell numbers
    where = "discharge" if where is None else where
    V = np.asarray(net.volumes, float)
    beta = float(net.bypass)
    lin = solve_cells(kin.S, kin.b, feed, net, None if dx is None else dx[:-1], where)
    if kin.is_linear:
        return NonlinearSteady(lin.product, 0.0, "exact linear (cells)", 0.0, float(np.finfo(float).eps * kin.n * n),
                               float(abs(lin.product.sum() - feed.sum())), 0, time.perf_counter() - start,
                               {"kinetics": "linear", "cell_holdup": lin.holdup, "cell_overflow": np.zeros(n)})
    T, inlet, out = network_operator(net, dx, where, n1)
    Tabs = abs(T)
    src = np.outer(inlet, np.append(feed, 0.0)).ravel()
    feed_size = float(np.abs(feed).sum())
    mass = np.repeat(V, n1)

    def F(c):
        return src + T @ c + (V[:, None] * kin.rate_many(c.reshape(n, n1))).ravel()

    def jacobian(c):
        blocks = V[:, None, None] * kin.jacobian_many(c.reshape(n, n1))
        B = scipy.sparse.bsr_matrix((blocks, np.arange(n), np.arange(n + 1)), shape=(n * n1, n * n1))
        return (T + B).tocsc()

    def factor(c, shift):
        A = jacobian(c)
        if shift:
            A = A - scipy.sparse.diags(shift * mass, format="csc")
        try:
            return SparseFactor(A)
        except SolverError as exc:
            raise SolverError(f"recirculating cells: {exc} ({kin.describe()})") from None

    def scale(c):
        C = c.reshape(n, n1)
        try:
            flux = float((V * np.abs(kin.rates(C[:, :-1]) * C[:, :-1]).sum(axis=1)).max())
        except SolverError:
            flux = 0.0
        return float(max(feed_size, float((Tabs @ np.abs(c)).max()), flux, np.finfo(float).tiny))

    c0 = np.concatenate([np.maximum(lin.holdup / V[:, None], 0.0), np.zeros((n, 1))], axis=1).ravel()
    with _blas():
        r = newton(F, factor, c0, scale, tol=tol, max_iter=max_iter, ptc_iter=ptc_iter,
                   unit=f"recirculating cells ({n} cells)", what=kin.describe(), dt0=0.1 * float(V.sum()),
                   dynamics=(mass, jacobian))
    C = r.y.reshape(n, n1)
    p = beta * np.append(feed, 0.0) + (out * C.T).sum(axis=1)
    dC = np.abs(r.correction.reshape(n, n1))
    err = float((np.abs(out) * dC.T).sum(axis=1).max()) / (1.0 - r.rho)
    herr = float((V[:, None] * dC[:, :-1]).sum(axis=0).max()) / (1.0 - r.rho)
    return NonlinearSteady(p[:-1], float(p[-1]), f"cells, Newton on all cells ({r.how})", r.residual, err,
                           float(abs(p.sum() - feed.sum())), r.iterations, time.perf_counter() - start,
                           {"kinetics": kin.describe(), "cell_holdup": V[:, None] * C[:, :-1],
                            "cell_overflow": V * C[:, -1], "holdup_error_estimate": herr,
                            "factorizations": r.factorizations})


# ----------------------------------------------------------------------- plug flow
#: Tolerances of the plug-flow ODE (the looser of the two solves; the returned one is 10x tighter).
PLUG_RTOL, PLUG_ATOL = 1e-8, 1e-12


def _plug_ode(kin: Kinetics, y0, tau, v, z, rtol, atol, holdup: bool):
    """Integrate the plug-flow ODE in the fractional position z.

    Integrate dF/dz = tau R(F / v) (and dQ/dz = F / v, the hold-up, when asked) from
    F(0) = y0 to the positions z; returns (T, n1) fluxes and (T, n1) or None hold-ups.
    """
    n1 = y0.size
    iv = 1.0 / v

    if holdup:
        def rhs(_z, u):
            F = u[:n1]
            return np.concatenate([tau * kin.rate(F * iv), F * iv])

        def jac(_z, u):
            J = np.zeros((2 * n1, 2 * n1))
            J[:n1, :n1] = tau * kin.jacobian(u[:n1] * iv) * iv[None, :]
            J[np.arange(n1, 2 * n1), np.arange(n1)] = iv
            return J
        u0 = np.concatenate([y0, np.zeros(n1)])
    else:
        def rhs(_z, u):
            return tau * kin.rate(u * iv)

        def jac(_z, u):
            return tau * kin.jacobian(u * iv) * iv[None, :]
        u0 = y0
    z = np.asarray(z, float)
    out = np.empty((z.size, u0.size))
    at0 = z == 0.0
    out[at0] = u0
    if (~at0).any():
        sol = integrate(rhs, (0.0, float(z.max())), u0, method="LSODA", t_eval=np.unique(z[~at0]), jac=jac,
                        rtol=rtol, atol=atol, what="plug flow with non-linear kinetics")
        out[~at0] = sol.y.T[np.searchsorted(np.unique(z[~at0]), z[~at0])]
    return out[:, :n1], (tau * out[:, n1:] if holdup else None)


@limit_blas_threads
def plug_flow(kin: Kinetics, feed, tau: float, d=None, *, rtol: float = PLUG_RTOL, atol: float = PLUG_ATOL,
              holdup: bool = True, positions=None) -> NonlinearSteady:
    """Plug flow with non-linear kinetics: the ODE in the fractional position z along the mill.

    The flux F obeys::

        dF/dz = tau R(c),   c = F / d*,   F(0) = f,   product p = F(1),

    F the flux of each class and c its hold-up density (class i travels at d_i* u:
    classification along the axis, ``d`` None for d* = 1, then F = c is the batch grind in
    contact time, eq. 4 with t -> tau z). Hold-up per unit feed rate [s]: tau int_0^1 c dz.
    Solved by LSODA with the analytic Jacobian at (rtol, atol) and at tolerances 10x
    tighter; the tighter solution is returned, the largest difference of product and
    hold-up / tau between the two is the error estimate (measured, not the tolerance).
    ``positions`` (fractions of the length): ``info["profile"]`` tau c at them [s].
    """
    feed, tau = _check(kin, feed, tau)
    start = time.perf_counter()
    dx = _discharge(kin, d)
    if kin.age is not None:  # d* in the velocity: the age-position balance (millflow.mill.age_axis)
        return age_slowing(kin, feed, _rtd().PlugFlow(tau), None if dx is None else dx[:-1])
    v = np.ones(kin.n + 1) if dx is None else dx
    y0 = np.append(feed, 0.0)
    z = np.array([1.0] if positions is None else np.append(np.asarray(positions, float), 1.0))
    F1, Q1 = _plug_ode(kin, y0, tau, v, z, rtol, atol, holdup)
    F2, Q2 = _plug_ode(kin, y0, tau, v, z, 0.1 * rtol, 0.1 * atol, holdup)
    err = float(np.abs(F2 - F1).max())
    if holdup:
        err = max(err, float(np.abs(Q2[-1] - Q1[-1]).max()) / tau)
    p = F2[-1]
    if p[:-1].min() < -(atol + err):
        i = int(np.argmin(p[:-1]))
        raise SolverError(f"plug flow with non-linear kinetics: class {i + 1} leaves at {p[i]:.3g} < 0 beyond the "
                          "error estimate; tighten rtol/atol")
    info = {"kinetics": kin.describe(), "rtol": 0.1 * rtol}
    if holdup:
        info.update(holdup=Q2[-1, :-1], holdup_overflow=float(Q2[-1, -1]))
    if positions is not None:
        info["profile"] = tau * F2[:-1, :-1] / v[None, :-1]
    how = "plug flow, LSODA in the position" + (" (d* in the velocity)" if dx is not None else " (contact time)")
    return NonlinearSteady(p[:-1], float(p[-1]), how, 0.0, err, float(abs(p.sum() - feed.sum())), 0,
                           time.perf_counter() - start, info)


def _rtd():
    import rtd

    return rtd


# ---------------------------------------------------------------- slowing-down in age
#: The refusal that remains: classification on the axis of a transport without one (cells are solved by
#: :mod:`millflow.mill.age_cells`, plug flow and both axial vessels by :mod:`millflow.mill.age_axis`).
_AGE_CLASSIFIED = AXIS_REFUSED


def age_slowing(kin: Kinetics, feed, transport, d=None, where="discharge", *, tol: float = 1e-10,
                holdup: bool = True, error_estimate: bool = True) -> NonlinearSteady:
    """A continuous mill with slowing-down in the material's age, S_i = S_i0 kappa(t).

    Here t is the time a particle has spent in the mill; without classification, in
    segregated flow::

        product = a f + int_0^inf E(t) exp(K theta(t)) f dt,   hold-up = int_0^inf (1 - F(t)) exp(K theta(t)) f dt,

    theta(t) = int_0^t kappa, exact for any micromixing (each particle breaks at the rate
    of its own age, independently of the others; the exit-age density E of ``transport``
    is all that matters). Plug flow: the batch grind at theta(tau). Adaptive quadrature
    (:func:`millflow.mill.segregated.segregated_quadrature`), whose estimate is the error
    estimate.

    With classification ``d`` (N,) normalised discharge d_i*, placed by ``where``
    ("discharge", "cells", 1-based cell numbers) as the linear cells place it, a cell
    transport is solved by the age-structured balance
    (:func:`millflow.mill.age_cells.age_structured`, to ``tol`` of the feed;
    ``error_estimate=False`` skips its second, tighter solve), the closed axial-dispersion
    vessel with ``d`` the relative axial velocities by the age-position balance
    (:func:`millflow.mill.age_axis.age_structured_axial`, to max(``tol``, AXIS_TOL): its grid
    in z), plug flow with ``d`` by its upwind cells extrapolated to plug flow
    (:func:`~millflow.mill.age_axis.age_structured_plug`), the open vessel by the same
    balance on its whole line with the sampled discharge (the linear open vessel's default,
    and what segregated flow with its exit-age density E is;
    :func:`~millflow.mill.age_axis.age_structured_open`).
    """
    feed, _ = _check(kin, feed, float(getattr(transport, "mean", 1.0)))
    if kin.age is None:
        raise InputError("age_slowing: the kinetics have no kappa(t) (kinetics(..., kappa_t=...))")
    if d is not None and isinstance(transport, _rtd().AxialDispersion):  # closed; open: sampled discharge
        from millflow.mill.age_axis import AXIS_TOL, age_structured_axial

        return age_structured_axial(kin, feed, transport, d, tol=max(tol, AXIS_TOL), holdup=holdup,
                                    error_estimate=error_estimate)
    if d is not None and isinstance(transport, _rtd().PlugFlow):
        from millflow.mill.age_axis import AXIS_TOL, age_structured_plug

        return age_structured_plug(kin, feed, transport, d, tol=max(tol, AXIS_TOL), holdup=holdup,
                                   error_estimate=error_estimate)
    if d is not None:
        return age_structured(kin, feed, transport, d, where or "discharge", rtol=max(tol, 1e-13), holdup=holdup,
                              error_estimate=error_estimate)
    start = time.perf_counter()
    age = kin.age
    rtd = _rtd()
    if isinstance(transport, rtd.PlugFlow):
        from millflow.batch import batch_solve
        from scipy.integrate import quad_vec

        tau = float(transport.mean)
        res = batch_solve(kin.S, kin.b, feed, age.theta_at([tau]))
        p, err = res.M[0], float(res.error_estimate)
        info = {"kinetics": kin.describe(), "theta_s": float(age.theta_at([tau])[0])}
        if holdup:
            hold, herr = quad_vec(lambda t: batch_solve(kin.S, kin.b, feed, age.theta_at([t])).M[0], 0.0, tau,
                                  epsabs=tol * max(float(feed.sum()), 1e-300) * tau, epsrel=0.0, norm="max")
            info["holdup"] = hold
            err = max(err, float(herr) / tau)
        return NonlinearSteady(p, 0.0, "plug flow: the batch grind at theta(tau) (kappa(t))", 0.0, err,
                               float(abs(p.sum() - feed.sum())), 0, time.perf_counter() - start, info)
    if not (hasattr(transport, "pdf") and hasattr(transport, "cdf")):
        raise InputError(f"transport {transport!r}: kappa(t) in a continuous mill needs the exit-age density E(t) "
                         "(an rtd model with pdf and cdf)")
    from millflow.mill.segregated import segregated_quadrature

    p, h, err, info = segregated_quadrature(kin.S, kin.b, feed, transport, holdup=holdup, tol=tol,
                                            theta=lambda t: age.theta_at([t])[0])
    out = {"kinetics": kin.describe(), **{k: v for k, v in info.items() if k != "blocks"}}
    if holdup:
        out["holdup"] = h
    return NonlinearSteady(p, 0.0, "segregated flow over the exit ages, batch grinds at theta(t) (kappa(t))", 0.0,
                           float(err), float(abs(p.sum() - feed.sum())), 0, time.perf_counter() - start, out)


# ------------------------------------------------------------- any transport, composed
_NEEDS_STRUCTURE = ("non-linear kinetics depend on how the mill mixes, which a residence time distribution alone does "
                    "not fix; expected a transport with its mixing structure (rtd.PerfectMixing, rtd.TanksInSeries "
                    "with integer n, rtd.RecirculatingCells, a CompartmentNetwork, rtd.PlugFlow, rtd.AxialDispersion, "
                    "or rtd.Series / rtd.Parallel of them), or the two micromixing limits of the RTD "
                    "(micromixing_limits)")


def solve_transport(kin: Kinetics, feed, transport, d=None, *, where=None, dispersion=None, discharge=None,
                    tol: float = 1e-8, holdup: bool = True, positions=None, m_cells: int | None = None
                    ) -> NonlinearSteady:
    """Steady product of a mill with non-linear kinetics and any transport.

    Steady product of a mill with non-linear kinetics and any transport of the linear
    mill (``rtd`` model, tau in s), classification ``d`` placed by ``where`` as in
    :func:`millflow.mill.steady_mill` ("discharge"/"cells"/cell numbers for cells, "axis"
    for plug flow and axial dispersion), ``dispersion`` and ``discharge`` of the axial
    transports. ``tol``: the accuracy the discretised paths (axial grids, the plug-flow ODE)
    refine to, relative to the feed; ``m_cells``: axial grids of that many volumes instead
    (checked against half as many). ``info["holdup"]`` (N,) is the hold-up per unit feed
    rate [s] (with ``holdup``); cells add ``info["cell_holdup"]`` (cells, N).

    Series: each part grinds the previous part's product (the aggregation overflow of a
    part leaves with its product and passes the later parts unchanged: it is above the
    grid, where the kinetics neither break nor aggregate it); errors add. Parallel: each
    branch receives its weight of the feed in its own volume, so its contents have the
    concentrations of a branch fed the whole feed: the branch is solved for the feed and
    its product and hold-up scaled by its weight.
    """
    from millflow.mill.scene import _scene

    if not isinstance(kin, Kinetics):
        raise InputError(f"kinetics: expected millflow.nonlinear.Kinetics, got {type(kin).__name__}")
    sc = _scene(kin.S, kin.b, transport, d, where, dispersion, discharge=discharge)
    feed, _ = _check(kin, feed, 1.0)
    if kin.age is not None:
        if sc.kind == "axial" and (sc.d is not None or sc.dispersion is not None):
            from millflow.mill.age_axis import age_structured_axial

            return age_structured_axial(kin, feed, transport, sc.d, dispersion=sc.dispersion, tol=tol,
                                        holdup=holdup, m_cells=m_cells)
        if sc.kind == "axial_open" and (sc.d is not None or sc.dispersion is not None or sc.discharge == "flux"):
            from millflow.mill.age_axis import age_structured_open

            return age_structured_open(kin, feed, transport, sc.d, dispersion=sc.dispersion,
                                       discharge=sc.discharge or "sampled", tol=tol, holdup=holdup, m_cells=m_cells)
        if sc.kind == "plug" and sc.d is not None:
            from millflow.mill.age_axis import age_structured_plug

            return age_structured_plug(kin, feed, transport, sc.d, tol=tol, holdup=holdup)
        if sc.dispersion is not None or (sc.d is not None and sc.kind not in ("perfect_mixing", "network")):
            raise InputError(_AGE_CLASSIFIED)
        if sc.kind in ("series", "parallel"):
            return _composed(kin, feed, transport, tol, holdup)
        return age_slowing(kin, feed, transport, sc.d, sc.where or "discharge", tol=min(tol, 1e-10), holdup=holdup)
    tau = float(transport.mean)
    kind = sc.kind
    if kind == "perfect_mixing":
        r = well_mixed(kin, feed, tau, sc.d)
    elif kind == "network":
        if isinstance(transport, _rtd().TanksInSeries):
            r = tanks_in_series(kin, feed, tau, int(round(transport.n)), sc.d, sc.where or "discharge")
        else:
            r = cells(kin, feed, transport, sc.d, sc.where or "discharge")
        if holdup and "holdup" not in r.info:
            r.info["holdup"] = r.info["cell_holdup"].sum(axis=0)
            r.info["holdup_overflow"] = float(r.info["cell_overflow"].sum())
        if "cells" in r.info:
            r.info.setdefault("cell_holdup", r.info["cells"])
    elif kind == "plug":
        r = plug_flow(kin, feed, tau, sc.d, rtol=min(PLUG_RTOL, max(tol, 1e-12)), holdup=holdup,
                      positions=positions)
    elif kind == "axial":  # tau = L / u (the open vessel's mean residence time is tau (1 + 2/Pe))
        r = axial_dispersion(kin, feed, float(transport.tau), float(transport.pe), sc.d, dispersion=sc.dispersion,
                             tol=tol, positions=positions, m_cells=m_cells)
    elif kind == "axial_open":
        r = axial_open(kin, feed, float(transport.tau), float(transport.pe), sc.d, dispersion=sc.dispersion,
                       discharge=sc.discharge or "sampled", tol=tol, positions=positions, m_cells=m_cells)
    elif kind in ("series", "parallel"):
        r = _composed(kin, feed, transport, tol, holdup, m_cells)
    elif isinstance(transport, _rtd().TanksInSeries):
        raise InputError(f"transport {transport!r}: non-linear kinetics solve tanks in series cell by cell; expected "
                         "an integer number of tanks")
    else:
        raise InputError(f"transport {transport!r}: {_NEEDS_STRUCTURE}")
    return r


def _composed(kin: Kinetics, feed, transport, tol: float, holdup: bool, m_cells=None) -> NonlinearSteady:
    start = time.perf_counter()
    parts = transport.parts
    weights = getattr(transport, "weights", None)
    stream, over = feed, 0.0
    product, over_p, hold, err, its, methods, res = 0.0, 0.0, 0.0, 0.0, 0, [], 0.0
    for k, part in enumerate(parts):
        r = solve_transport(kin, stream if weights is None else feed, part, tol=tol / len(parts), holdup=holdup,
                            m_cells=m_cells)
        methods.append(r.method)
        its += r.iterations
        res = max(res, r.residual)
        w = 1.0 if weights is None else float(weights[k])
        err += w * r.error_estimate
        if holdup:
            hold = hold + w * r.info["holdup"]
        if weights is None:
            stream, over = r.product, over + r.overflow_mass
        else:
            product, over_p = product + w * r.product, over_p + w * r.overflow_mass
    p, o = (stream, over) if weights is None else (product, over_p)
    info = {"kinetics": kin.describe(), "parts": "; ".join(methods)}
    if holdup:
        info["holdup"] = hold
    name = "series" if weights is None else "parallel"
    return NonlinearSteady(p, float(o), f"{name} of {len(parts)} parts, each by its own solver", res, err,
                           float(abs(np.sum(p) + o - feed.sum())), its, time.perf_counter() - start, info)


# ------------------------------------------------------------------ micromixing
@dataclass(frozen=True)
class MicromixingLimits(_SplitError):
    """Products of the two micromixing limits for one RTD.

    ``segregated`` and ``max_mixedness`` (N,), ``spread`` max |difference|, ``coincide``
    True for linear kinetics (then both are the one exact answer), ``note`` what the user
    should know.

    They are the two extremes of micromixing, not bounds on a real mill's product: with
    coupled non-linear rates a mill of intermediate mixing can lie outside both, class by
    class (module docstring).
    """

    segregated: np.ndarray
    max_mixedness: np.ndarray
    spread: float
    coincide: bool
    note: str
    error_estimate: float
    runtime_s: float
    info: dict = field(default_factory=dict)

    solver_error_method = "the solves of the two limits"


def _survival(model, t):
    if type(model).__name__ == "TanksInSeries":
        return special.gammaincc(model.n, model.n * np.maximum(t, 0) / model.tau)
    if type(model).__name__ == "PerfectMixing":
        return np.exp(-np.maximum(t, 0) / model.tau)
    return 1.0 - np.asarray(model.cdf(t), float)


def _hazard(model, lam_max, nodes: int = 8001):
    """h(lambda) = E / (1 - F) on [0, lam_max].

    Analytic for perfect mixing and tanks in series; otherwise the survival is integrated
    from the tail, S(t) = (1 - F(lam_max)) + int_t^lam_max E (cumulative Simpson on
    ``nodes`` points, accurate in relative terms where 1 - F(t) would cancel), and h
    interpolated by a cubic spline: a smooth forcing for the implicit integrator. Returns
    (h, interpolation error estimate of h relative to its maximum: the spline against the
    half grid).
    """
    from scipy.integrate import cumulative_simpson
    from scipy.interpolate import CubicSpline

    if type(model).__name__ in ("PerfectMixing", "TanksInSeries"):
        return (lambda lam: float(model.pdf(lam)) / float(_survival(model, lam))), 0.0
    t = np.linspace(0.0, lam_max, nodes)
    E = np.asarray(model.pdf(t), float)
    tail = max(float(1.0 - model.cdf(lam_max)), 0.0)
    S = tail + cumulative_simpson(E[::-1], dx=t[1], initial=0.0)[::-1]
    if np.any(S <= 0) or not np.all(np.isfinite(E)):
        raise SolverError(f"micromixing: the survival of {model!r} is not positive on [0, {lam_max:g}] s")
    h = E / S
    spline = CubicSpline(t, h)
    coarse = CubicSpline(t[::2], h[::2])
    err = float(np.abs(coarse(t[1::2]) - h[1::2]).max() / max(np.abs(h).max(), 1e-300))
    return (lambda lam: float(spline(lam))), err


def _horizon(model, eps=1e-13):
    t = float(model.mean)
    while float(np.asarray(_survival(model, t)).ravel()[0]) > eps:
        t *= 1.5
        if t > 1e6 * model.mean:
            raise InputError(f"RTD {model!r}: the survival 1 - F(t) does not fall below {eps:g} by 1e6 mean times")
    return t


def micromixing_limits(kin: Kinetics, feed, model, *, rtol: float = 1e-9, atol: float = 1e-13) -> MicromixingLimits:
    """Both micromixing limits (segregation, maximum mixedness) for an RTD.

    Both micromixing limits for the RTD ``model`` (an rtd model with pdf and cdf):
    complete segregation and maximum mixedness (module docstring). Limits, not bounds:
    Zwietering's ordering (segregation above maximum mixedness in conversion for a rate
    of order > 1, below for order < 1) holds for one species with a rate of one
    convexity; for a population whose rates couple, a real mill's product can lie outside
    both class by class (``note`` says so).
    """
    from scipy.integrate import quad_vec

    from millflow.nonlinear.batch import batch_nonlinear

    feed, _ = _check(kin, feed, float(getattr(model, "mean", 1.0)))
    _no_age(kin, "micromixing limits")
    start = time.perf_counter()
    if type(model).__name__ == "PlugFlow":
        res = batch_nonlinear(kin, feed, [model.mean], rtol=rtol, atol=atol)
        return MicromixingLimits(res.M[0], res.M[0], 0.0, True, "plug flow: no mixing at all, the two limits are "
                                 "the same batch grind", res.error_estimate, time.perf_counter() - start)
    if kin.is_linear:
        from millflow.mill.segregated import segregated
        p, _, err, _ = segregated(kin.S, kin.b, feed, model, holdup=False)
        return MicromixingLimits(p, p, 0.0, True, "linear (first-order) kinetics: segregation and maximum mixedness "
                                 "coincide, the RTD alone fixes the product; one exact answer is given",
                                 float(err), time.perf_counter() - start)
    t_max = _horizon(model)
    y0 = np.append(feed, 0.0)
    sol = integrate(lambda _t, y: kin.rate(y), (0.0, t_max), y0, method="BDF", jac=lambda _t, y: kin.jacobian(y),
                    rtol=rtol, atol=atol, dense_output=True, what="micromixing (segregation): the batch grind")
    seg, seg_err = quad_vec(lambda t: sol.sol(t) * float(model.pdf(t)), 0.0, t_max, epsabs=atol, epsrel=rtol,
                            limit=400)
    seg = seg + y0 * float(getattr(model, "atom_at_zero", 0.0) or 0.0)

    # start: M solving 0 = -R(M) + h(lam_max) (M - f), a perfect mixer at 1/h
    lam_max = _horizon(model, 1e-12)
    hazard, h_err = _hazard(model, lam_max)
    h_inf = hazard(lam_max)
    start_cell = well_mixed(kin, feed, 1.0 / h_inf, unit="maximum mixedness (start at large lambda)")
    ys = np.append(start_cell.product, start_cell.overflow_mass)

    def rhs(s, y):  # s = lam_max - lambda
        return kin.rate(y) - hazard(lam_max - s) * (y - y0)

    def jac(s, y):
        return kin.jacobian(y) - hazard(lam_max - s) * np.eye(y.size)

    zw = integrate(rhs, (0.0, lam_max), ys, method="BDF", jac=jac, rtol=rtol, atol=atol,
                   what="micromixing (maximum mixedness): Zwietering's equation")
    mm = zw.y[:, -1]
    spread = float(np.abs(seg[:-1] - mm[:-1]).max())
    # integrator tolerances, the quadrature's estimate, and the hazard interpolation
    # (a relative error in h moves the product by at most about as much, times |M - f|)
    err = float(seg_err + rtol * np.abs(mm).max() * 10 + atol + h_err * np.abs(mm - y0).max())
    return MicromixingLimits(seg[:-1], mm[:-1], spread, False,
                             "non-linear kinetics: the product depends on micromixing, which the RTD cannot tell; "
                             "these are the two limits of mixing, not bounds: a mill of intermediate mixing (e.g. "
                             "tanks in series) can lie outside them class by class (Zwietering's ordering holds only "
                             "for one species with a rate of one convexity)", err, time.perf_counter() - start,
                             {"overflow": (float(seg[-1]), float(mm[-1])), "lambda_max_s": lam_max,
                              "kinetics": kin.describe(), "hazard_interpolation_error": h_err})


#: Earlier names (kept so existing scripts run): the limits are not bounds.
MicromixingBounds = MicromixingLimits
micromixing_bounds = micromixing_limits

