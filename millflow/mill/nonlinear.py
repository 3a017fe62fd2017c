"""Continuous mills with non-linear kinetics (aggregation, population-dependent rates):
the steady product of eq. 3 with R(M) of :mod:`millflow.nonlinear.kinetics` in place of
the linear K M, with classification d* at the discharge or at cell outlets (perfect
mixing, tanks in series, networks of cells; plug flow and axial dispersion without).

- perfect mixing:   0 = f - d* y + tau R(y), y = hold-up / tau (p = d* y), by Newton with the analytic Jacobian
  -I + tau dR/dM, backtracking line search, and pseudo-transient continuation
  ((I/dt - J) dM = F, dt grown by the residual ratio) if Newton stalls;
- tanks in series:  one cell at a time, cell k at tau/n fed by cell k - 1 (d* at the
  last cell, every cell or the listed ones);
- networks of cells (recirculating cells, compartment networks): the cells' linear
  exchange plus V_k R(c_k) per cell, Newton on the block system (:func:`cells`);
- plug flow:        the batch ODE in contact time, product M(tau);
- axial dispersion: the steady convection-dispersion-reaction equation with Danckwerts
  boundaries, discretised exactly as :mod:`millflow.mill.axial` (vertex-centred volumes,
  exponential fitting), all nodes solved together by Newton with the sparse block-
  tridiagonal Jacobian (block elimination, one dense LU per node);
- micromixing limits for any RTD model with ``pdf``/``cdf``: complete segregation,
  int_0^inf E(t) M_batch(t) dt, and maximum mixedness (Zwietering 1959),
  dM/dlambda = -R(M) + h(lambda) (M - f), h = E/(1 - F), integrated from large lambda
  (where M solves the same equation with dM/dlambda = 0) down to lambda = 0, product M(0).
  For first-order kinetics the two coincide (the RTD fixes the product, segregated flow
  is exact); then one linear answer is returned and the result says so. Otherwise they
  are the extremes of mixing, not bounds: Zwietering's ordering of the conversion holds
  for one species with a rate of one convexity, not class by class for a population
  whose rates couple (four tanks in series with nipping rates lie outside both).

A linear scene (nothing non-linear declared) takes the exact linear path of
:mod:`millflow.linalg` / :mod:`millflow.mill` with nothing added. A steady solve that
does not reach its tolerance raises SolverError naming the unit and the residual. Newton's
criterion is scaled: max|F| <= tol * s with s the size of the terms of F (feed, state,
breakage flux; :func:`residual_scale`), tol = :data:`NEWTON_RTOL` = 1e-11 by default, or,
at the rounding floor where no step reduces max|F|, a full Newton step below tol * s.
The state carries the aggregation overflow (mass above the top class) as component N + 1:
it leaves with the product and is reported as ``overflow_mass``.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg
import scipy.sparse
import scipy.sparse.linalg
from scipy import special
from scipy.integrate import quad_vec, solve_ivp

from millflow import checks
from millflow.errors import InputError, SolverError
from millflow.mill.well_mixed import solve_well_mixed
from millflow.mill.axial import _bernoulli, solve_axial_grid
from millflow.nonlinear.batch import batch_nonlinear
from millflow.nonlinear.kinetics import Kinetics
from millflow.threads import limit_blas_threads

__all__ = ["NonlinearSteady", "MicromixingBounds", "well_mixed", "tanks_in_series", "cells", "plug_flow",
           "axial_dispersion", "micromixing_bounds"]


#: The grid part of a non-linear steady result's error (as :func:`millflow.mill.steady_mill`):
#: the kinetics carry S_i, b_ij per class, which are the discrete model itself.
GRID_NOTE = ("none: S_i and b_ij given per class (the kinetics) are the discrete model itself; continuous "
             "forms put on a grid (and an aggregation kernel or fines size discretised on the kinetics' grid) carry "
             "the grid error their caller estimates by refining the grid (flowsheet grid check, batch.grind)")


class _SplitError:
    """The error report of a non-linear steady result: its solver part and its grid part.

    The grid part is zero: the kinetics' S_i and b_ij per class are the discrete model itself.
    """

    grid_error_estimate = 0.0
    grid_error_method = GRID_NOTE
    #: What estimated the solver part (a class's own text, or its ``method`` field).
    solver_error_method = None

    @property
    def solver_error_estimate(self) -> float:
        """The solver part of the error (``error_estimate``)."""
        return self.error_estimate

    @property
    def error_report(self) -> dict:
        """``error_estimate`` split into its solver part and its grid part, each with its method."""
        how = self.solver_error_method or getattr(self, "method", "")
        return {"solver": {"value": float(self.error_estimate), "method": how},
                "grid": {"value": 0.0, "method": GRID_NOTE}}


@dataclass(frozen=True)
class NonlinearSteady(_SplitError):
    """Steady product (mass flows per unit feed rate, sum = sum(feed) - overflow) with the
    diagnostics of the solve: ``residual`` max |F| at the answer, ``error_estimate`` the
    size of the next Newton step (or the ODE's estimate), ``iterations``."""

    product: np.ndarray
    overflow_mass: float
    method: str
    residual: float
    error_estimate: float
    mass_balance_error: float
    iterations: int
    runtime_s: float
    info: dict = field(default_factory=dict)



def _check(kin: Kinetics, feed, tau):
    if not isinstance(kin, Kinetics):
        raise InputError(f"kinetics: expected millflow.nonlinear.Kinetics, got {type(kin).__name__}")
    feed = checks.class_vector(feed, kin.n, "feed", "mass flow")
    if not (isinstance(tau, (int, float)) and math.isfinite(tau) and tau > 0):
        raise InputError(f"tau = {tau!r}: expected a mean residence time > 0 [s]")
    return feed, float(tau)


def residual_scale(kin: Kinetics, y_in, y, tau, d=None) -> float:
    """The size of the terms the steady residual F = y_in - d* y + tau R(y) is made of:
    s = max(sum|y_in|, max|y|, max|d* y|, tau sum_i S_i[M] M_i) (the feed, the state, the breakage
    flux through the cell). Rounding alone leaves |F| ~ N eps s, so the convergence test
    is relative to s: a residual of 1e-11 on a state of order 1 with tau S ~ 10 is
    converged, whatever units the feed rate is given in."""
    M = y[:-1]
    try:
        flux = float(np.abs(kin.rates(M) * M).sum())
    except SolverError:
        flux = 0.0
    out = max(np.abs(y_in).sum(), np.abs(y).max(), tau * flux, np.finfo(float).tiny)
    return float(out if d is None else max(out, np.abs(d * y).max()))


#: Relative tolerance of the non-linear Newton solves (see :func:`residual_scale`).
NEWTON_RTOL = 1e-11


@limit_blas_threads  # small dense Newton systems: one BLAS thread (millflow.threads)
def _newton_cell(kin: Kinetics, y_in, tau, y0, *, tol, max_iter, unit,
                 phases=("newton", "pseudo-transient", "newton"), d=None):
    """Solve F(y) = y_in - d* y + tau R(y) = 0 (``d`` the (N + 1,) normalised discharge,
    None for ones); returns (y, residual, step, iterations, how).

    Stated criterion: converged when max|F| <= tol * s, s = :func:`residual_scale` (the
    feed, the state and the breakage flux), or, when the line search can no longer
    reduce max|F| (the rounding floor), when the full Newton step is itself below
    tol * s. ``phases``: Newton, then (if it stalls) pseudo-transient continuation to
    residual 1e-6 s, then Newton again."""
    n1 = y_in.size
    eye = np.eye(n1)
    dd = np.ones(n1) if d is None else np.asarray(d, float)
    out_op = np.diag(dd)

    def F(y):
        return y_in - dd * y + tau * kin.rate(y)

    def safe_F(y):
        try:
            return F(y)
        except SolverError:  # e.g. Phi undefined at a trial point: a failed trial, not a failed solve
            return None

    y = y0.copy()
    f = F(y)
    res = float(np.abs(f).max())
    its = 0
    ran = []
    lu = None
    floor = False  # converged at the rounding floor (full step below tol * scale)

    def limit():
        return tol * residual_scale(kin, y_in, y, tau, d)

    for phase in phases:
        if res <= limit() or floor:
            break
        ran.append(phase)
        dt = 0.1 * tau
        stalled = False
        while res > limit() and its < max_iter:
            its += 1
            J = -out_op + tau * kin.jacobian(y)
            if phase == "newton":
                lu = scipy.linalg.lu_factor(J, check_finite=False)
                dy = scipy.linalg.lu_solve(lu, -f, check_finite=False)
                lam, accepted = 1.0, False
                while lam >= 1.0 / 256:
                    yt = y + lam * dy
                    ft = safe_F(yt)
                    if ft is not None and np.abs(ft).max() <= (1.0 - 1e-4 * lam) * res:
                        accepted = True
                        break
                    lam *= 0.5
                if not accepted:
                    stalled = True
                    floor = bool(np.isfinite(dy).all() and np.abs(dy).max() <= limit())
                    break
            else:
                dy = np.linalg.solve(eye / dt - J, f)
                yt = y + dy
                ft = safe_F(yt)
                if ft is None or not np.isfinite(ft).all():
                    dt *= 0.25
                    continue
                dt *= min(10.0, max(0.5, res / max(float(np.abs(ft).max()), 1e-300)))
                if float(np.abs(ft).max()) < 1e-6 * residual_scale(kin, y_in, yt, tau, d):
                    y, f, res = yt, ft, float(np.abs(ft).max())
                    break
            y, f, res = yt, ft, float(np.abs(ft).max())
        if res <= limit() or floor:
            break
        if phase == "newton" and not stalled and its >= max_iter:
            break
    how = " + ".join(ran) or "newton (start already converged)"
    scale = residual_scale(kin, y_in, y, tau, d)
    if not np.isfinite(res) or (res > tol * scale and not floor):
        raise SolverError(f"{unit}: the steady state did not converge: residual max|f - d* M + tau R(M)| = {res:.3g} "
                          f"> tol {tol:g} x scale {scale:.3g} after {its} iterations ({kin.describe()})")
    # one polishing Newton step at the answer: kept if it lowers max|F|; its size is the
    # error estimate (an over-estimate for the polished state: Newton converges quadratically)
    lu = scipy.linalg.lu_factor(-out_op + tau * kin.jacobian(y), check_finite=False)
    dy = scipy.linalg.lu_solve(lu, -f, check_finite=False)
    step = float(np.abs(dy).max())
    ft = safe_F(y + dy)
    if ft is not None and np.isfinite(ft).all() and float(np.abs(ft).max()) < res:
        y, res = y + dy, float(np.abs(ft).max())
    return y, res, step, its, how


def _discharge(kin: Kinetics, d):
    """(N + 1,) normalised discharge d* of the state, or None for no classification. The
    aggregation overflow (mass above the top class) leaves unclassified (d* = 1): the
    kinetics do not break it, so a grate holding it back (d* -> 0) would accumulate it
    without bound and leave no steady state; it is a grid artefact (``overflow_mass``,
    kept small by a grid top above the aggregates), not a class the mill can retain."""
    if d is None:
        return None
    d = checks.class_vector(d, kin.n, "d", "normalised discharge rate")
    if not np.all(d > 0):
        raise InputError("d: expected normalised discharge rates d_i* > 0 (d* = tau d_i)")
    return np.append(d, 1.0)


def well_mixed(kin: Kinetics, feed, tau: float, d=None, *, tol: float = NEWTON_RTOL, max_iter: int = 60,
               unit: str = "perfectly mixed mill") -> NonlinearSteady:
    """Steady product of a perfectly mixed mill with non-linear kinetics (eq. 3 + R(M)).

    ``d`` (N,): normalised discharge d_i* (classification at the discharge), None for
    d* = 1. The state is y = m / tau, m the hold-up per unit feed rate [s] (y = M, the
    hold-up mass fractions, for an unclassified mill fed at unit rate): eq. 1 with
    p_i = d_i* y_i and H R(M) for the breakage and aggregation terms gives the steady
    residual y_in - d* y + tau R(y); R acts on the hold-up, whose total exceeds the
    feed's where coarse classes are retained (d* < 1). ``info["holdup"]`` is m."""
    feed, tau = _check(kin, feed, tau)
    dx = _discharge(kin, d)
    start = time.perf_counter()
    lin = solve_well_mixed(kin.S, kin.b, feed, tau, None if dx is None else dx[:-1])
    if kin.is_linear:
        return NonlinearSteady(lin, 0.0, "exact linear (eq. 3)", 0.0, float(np.finfo(float).eps * feed.sum() * kin.n),
                               float(abs(lin.sum() - feed.sum())), 0, time.perf_counter() - start,
                               {"kinetics": "linear", "holdup": tau * (lin if dx is None else lin / dx[:-1]),
                                "holdup_overflow": 0.0})
    y_in = np.append(feed, 0.0)
    guess = np.append(np.maximum(lin if dx is None else lin / dx[:-1], 0.0), 0.0)
    y, res, step, its, how = _newton_cell(kin, y_in, tau, guess, tol=tol, max_iter=max_iter, unit=unit, d=dx)
    p = y if dx is None else dx * y
    err = step * (1.0 if dx is None else float(dx.max()))
    return NonlinearSteady(p[:-1], float(p[-1]), how, res, err, float(abs(p.sum() - feed.sum())), its,
                           time.perf_counter() - start, {"kinetics": kin.describe(), "holdup": tau * y[:-1],
                                                         "holdup_overflow": float(tau * y[-1])})


def tanks_in_series(kin: Kinetics, feed, tau: float, n: int, d=None, where="discharge", *,
                    tol: float = NEWTON_RTOL, max_iter: int = 60) -> NonlinearSteady:
    """n equal perfect mixers in series (total mean residence time tau), one cell at a time.

    ``d`` (N,) normalised discharge d_i* (None: none), acting where ``where`` says:
    "discharge" (the last cell's outflow), "cells" (every cell's outflow) or a sequence
    of 1-based cell numbers; each cell is :func:`well_mixed` at tau / n with its d*."""
    feed, tau = _check(kin, feed, tau)
    if int(n) != n or n < 1:
        raise InputError(f"n = {n!r}: expected an integer number of tanks >= 1")
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
    y = np.append(feed, 0.0)
    its, res, step, cells = 0, 0.0, 0.0, []
    for k in range(n):
        dk = dx if dx is not None and mask[k] else None
        lin = solve_well_mixed(kin.S, kin.b, y[:-1], tau / n, None if dk is None else dk[:-1])
        guess = np.append(np.maximum(lin if dk is None else lin / dk[:-1], 0.0), y[-1])
        c, r, s, i, how = _newton_cell(kin, y, tau / n, guess, tol=tol, max_iter=max_iter,
                                       unit=f"tanks in series, cell {k + 1} of {n}", d=dk)
        y = c if dk is None else dk * c
        its += i
        # the step in cell k's content, carried to the product by the cells downstream (contractive)
        res, step = max(res, r), max(step, s * (1.0 if dk is None else float(dk.max())))
        cells.append(tau / n * c)
    cells = np.array(cells)  # (n, N + 1): hold-up per unit feed rate [s], the overflow last
    return NonlinearSteady(y[:-1], float(y[-1]), f"cells ({how})", res, step, float(abs(y.sum() - feed.sum())), its,
                           time.perf_counter() - start, {"kinetics": kin.describe(), "cells": cells[:, :-1],
                                                         "cells_overflow": cells[:, -1],
                                                         "holdup": cells[:, :-1].sum(axis=0)})


def _classified(n: int, where) -> np.ndarray:
    """Cells (n,) whose outflow is classified: "discharge" the last (a chain's exit),
    "cells" all, or the listed 1-based cells."""
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


def cells(kin: Kinetics, feed, transport, d=None, where="discharge", *, tol: float = NEWTON_RTOL,
          max_iter: int = 60) -> NonlinearSteady:
    """Steady product of a network of well-mixed cells (``transport`` an rtd model with a
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
    Jacobian (the constant transport part plus the blocks V_k dR/dc, sparse LU), line
    search, pseudo-transient continuation if Newton stalls; the stated criterion of
    :func:`well_mixed` with the scale max(feed, transport flows x state, V_k breakage
    flux). Error estimate: the product's change under one more Newton step."""
    from millflow.mill.cells import _factors, network_of
    feed, _ = _check(kin, feed, 1.0)
    net = network_of(transport)
    if net is None:
        raise InputError(f"transport {transport!r}: expected a network of cells (e.g. rtd.RecirculatingCells)")
    start = time.perf_counter()
    dx = _discharge(kin, d)
    n, n1 = int(net.n), kin.n + 1
    if where not in (None, "discharge", "cells"):
        _classified(n, where)  # checks the cell numbers
    V = np.asarray(net.volumes, float)
    Fl = np.asarray(net.flows, float)
    o = np.asarray(net.outlet, float)
    beta = float(net.bypass)
    G, H = _factors(dx, n1, n, "discharge" if where is None else where)  # (n1, n)
    if kin.is_linear:
        from millflow.mill.cells import solve_cells
        sol = solve_cells(kin.S, kin.b, feed, net, None if dx is None else dx[:-1],
                          "discharge" if where is None else where)
        return NonlinearSteady(sol.product, 0.0, "exact linear (cells)", 0.0, float(np.finfo(float).eps * kin.n * n),
                               float(abs(sol.product.sum() - feed.sum())), 0, time.perf_counter() - start,
                               {"kinetics": "linear", "cell_holdup": sol.holdup, "cell_overflow": np.zeros(n)})
    # constant transport operator on the stacked state c (n cells x n1 components)
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
    Tabs = abs(T)
    src = ((1.0 - beta) * np.asarray(net.inlet, float)[:, None] * np.append(feed, 0.0)[None, :]).ravel()
    feed_size = float(np.abs(feed).sum())

    def F(c):
        C = c.reshape(n, n1)
        R = np.array([kin.rate(C[k]) for k in range(n)])
        return src + T @ c + (V[:, None] * R).ravel()

    def safe_F(c):
        try:
            return F(c)
        except SolverError:
            return None

    def jac(c):
        C = c.reshape(n, n1)
        blocks = scipy.sparse.block_diag([V[k] * kin.jacobian(C[k]) for k in range(n)], format="csr")
        return (T + blocks).tocsc()

    def scale(c):
        C = c.reshape(n, n1)
        try:
            flux = max(float(V[k] * np.abs(kin.rates(C[k, :-1]) * C[k, :-1]).sum()) for k in range(n))
        except SolverError:
            flux = 0.0
        return float(max(feed_size, float((Tabs @ np.abs(c)).max()), flux, np.finfo(float).tiny))

    def factor(A):
        try:
            return scipy.sparse.linalg.splu(A.tocsc())
        except RuntimeError as exc:  # "Factor is exactly singular"
            raise SolverError(f"recirculating cells: the Newton matrix is singular ({exc}; {kin.describe()})") from exc

    from millflow.mill.cells import solve_cells
    lin = solve_cells(kin.S, kin.b, feed, net, None if dx is None else dx[:-1],
                      "discharge" if where is None else where)
    c = np.concatenate([np.maximum(lin.holdup / V[:, None], 0.0), np.zeros((n, 1))], axis=1).ravel()
    f = F(c)
    res = float(np.abs(f).max())
    its, floor, ran = 0, False, []
    mass = scipy.sparse.diags(np.repeat(V, n1))
    for phase in ("newton", "pseudo-transient", "newton"):
        if res <= tol * scale(c) or floor:
            break
        ran.append(phase)
        dt = 0.1 * float(V.sum())
        while res > tol * scale(c) and its < max_iter:
            its += 1
            J = jac(c)
            if phase == "newton":
                dc = factor(J).solve(-f)
                lam, ft = 1.0, None
                while lam >= 1.0 / 256:
                    trial = safe_F(c + lam * dc)
                    if trial is not None and np.abs(trial).max() <= (1.0 - 1e-4 * lam) * res:
                        ft = trial
                        break
                    lam *= 0.5
                if ft is None:
                    floor = bool(np.isfinite(dc).all() and np.abs(dc).max() <= tol * scale(c))
                    break
                c, f, res = c + lam * dc, ft, float(np.abs(ft).max())
            else:
                dc = factor(mass / dt - J).solve(f)
                ft = safe_F(c + dc)
                if ft is None or not np.isfinite(ft).all():
                    dt *= 0.25
                    continue
                dt *= min(10.0, max(0.5, res / max(float(np.abs(ft).max()), 1e-300)))
                c, f, res = c + dc, ft, float(np.abs(ft).max())
                if res < 1e-6 * scale(c):
                    break
    if not np.isfinite(res) or (res > tol * scale(c) and not floor):
        raise SolverError(f"recirculating cells: the steady state did not converge: residual {res:.3g} > tol "
                          f"{tol:g} x scale {scale(c):.3g} after {its} iterations on {n} cells ({kin.describe()})")

    def product(c):
        C = c.reshape(n, n1)
        return beta * np.append(feed, 0.0) + (H * o[None, :] * C.T).sum(axis=1)

    # one polishing step: kept if it lowers max|F|; the product's change is the error estimate
    dc = factor(jac(c)).solve(-f)
    err = float(np.abs(product(c + dc) - product(c)).max())
    ft = safe_F(c + dc)
    if ft is not None and np.isfinite(ft).all() and float(np.abs(ft).max()) < res:
        c, res = c + dc, float(np.abs(ft).max())
    p = product(c)
    return NonlinearSteady(p[:-1], float(p[-1]), "cells, Newton on all cells (" + (" + ".join(ran) or "start") + ")",
                           res, err, float(abs(p.sum() - feed.sum())), its, time.perf_counter() - start,
                           {"kinetics": kin.describe(), "cell_holdup": V[:, None] * c.reshape(n, n1)[:, :-1],
                            "cell_overflow": V * c.reshape(n, n1)[:, -1]})


def plug_flow(kin: Kinetics, feed, tau: float, *, rtol: float = 1e-8, atol: float = 1e-12) -> NonlinearSteady:
    """Plug flow: the batch solve in contact time, product M(tau) (eq. 4 with t -> t*)."""
    feed, tau = _check(kin, feed, tau)
    res = batch_nonlinear(kin, feed, [tau], rtol=rtol, atol=atol)
    return NonlinearSteady(res.M[0], float(res.overflow_mass[0]), f"plug flow ({res.method})", 0.0,
                           res.error_estimate, res.mass_balance_error, int(res.info.get("nfev", 0)), res.runtime_s,
                           {"kinetics": res.info["kinetics"]})


def axial_dispersion(kin: Kinetics, feed, tau: float, pe: float, *, m_cells: int = 64, tol: float = NEWTON_RTOL,
                     max_iter: int = 40) -> NonlinearSteady:
    """Axial dispersion (Peclet ``pe``), closed vessel, on ``m_cells`` volumes; Newton on
    all nodes. The discretisation error is estimated against the grid of m_cells / 2."""
    feed, tau = _check(kin, feed, tau)
    if not (math.isfinite(pe) and pe > 0):
        raise InputError(f"pe = {pe!r}: expected a Peclet number > 0")
    if int(m_cells) != m_cells or m_cells < 4 or m_cells % 2:
        raise InputError(f"m_cells = {m_cells!r}: expected an even integer >= 4")
    start = time.perf_counter()
    if kin.is_linear:
        _, _, p = solve_axial_grid(kin.S, kin.b, feed, tau, pe, int(m_cells))
        _, _, p2 = solve_axial_grid(kin.S, kin.b, feed, tau, pe, int(m_cells) // 2)
        return NonlinearSteady(p, 0.0, "exact linear (axial grid)", 0.0, float(np.abs(p - p2).max()),
                               float(abs(p.sum() - feed.sum())), 0, time.perf_counter() - start, {"kinetics": "linear"})
    p, over, res, its = _axial_newton(kin, feed, tau, pe, int(m_cells), tol, max_iter)
    p2, over2, _, _ = _axial_newton(kin, feed, tau, pe, int(m_cells) // 2, tol, max_iter)
    err = float(max(np.abs(p - p2).max(), abs(over - over2)))
    return NonlinearSteady(p, over, f"axial dispersion, {int(m_cells)} volumes, Newton", res, err,
                           float(abs(p.sum() + over - feed.sum())), its, time.perf_counter() - start,
                           {"kinetics": kin.describe(), "error": "|p(M) - p(M/2)|"})


@limit_blas_threads
def _axial_newton(kin, feed, tau, pe, m, tol, max_iter):
    n1 = kin.n + 1
    h = 1.0 / m
    wts = np.full(m + 1, h)
    wts[[0, -1]] = 0.5 * h
    D = 1.0 / pe
    P = h / D
    a = D / h * float(_bernoulli(np.array([-P]))[0])  # F_{k+1/2} = a c_k - bt c_{k+1}
    bt = D / h * float(_bernoulli(np.array([P]))[0])
    # linear transport part T (block tridiagonal with scalar blocks, same for every component)
    main = np.full(m + 1, -(a + bt))
    main[0] = -a
    main[-1] = -bt - 1.0
    T = scipy.sparse.diags([np.full(m, bt), main, np.full(m, a)], [1, 0, -1], format="csr")
    Tbig = scipy.sparse.kron(T, scipy.sparse.identity(n1), format="csr")  # residual only
    src = np.zeros((m + 1, n1))
    src[0, :-1] = feed
    src = src.ravel()
    _, c_lin, _ = solve_axial_grid(kin.S, kin.b, feed, tau, pe, m)
    C = np.concatenate([np.maximum(c_lin, 0.0), np.zeros((m + 1, 1))], axis=1)

    def F(C):
        R = np.array([kin.rate(c) for c in C])
        return Tbig @ C.ravel() + src + tau * (wts[:, None] * R).ravel()

    def scale(C):  # the terms F is made of: feed, transport (a + bt + 1) C, tau w_k S M
        try:
            flux = max(float(wts[k] * np.abs(kin.rates(C[k, :-1]) * C[k, :-1]).sum()) for k in range(m + 1))
        except SolverError:
            flux = 0.0
        return float(max(np.abs(feed).sum(), (a + bt + 1.0) * np.abs(C).max(), tau * flux))

    f = F(C)
    res = float(np.abs(f).max())
    its = 0
    floor = False  # the rounding floor: no decrease possible, full step below tol * scale
    while res > tol * scale(C) and its < max_iter:
        its += 1
        D = np.array([tau * wts[k] * kin.jacobian(C[k]) for k in range(m + 1)])
        D[:, np.arange(n1), np.arange(n1)] += main[:, None]
        dC = _block_thomas(D, a, bt, -f.reshape(m + 1, n1))
        lam, ft = 1.0, None
        while lam >= 1.0 / 256:
            try:
                trial = F(C + lam * dC)
                if np.abs(trial).max() <= (1.0 - 1e-4 * lam) * res:
                    ft = trial
                    break
            except SolverError:
                pass
            lam *= 0.5
        if ft is None:
            floor = bool(np.isfinite(dC).all() and np.abs(dC).max() <= tol * scale(C))
            break
        C, f, res = C + lam * dC, ft, float(np.abs(ft).max())
    if not np.isfinite(res) or (res > tol * scale(C) and not floor):
        raise SolverError(f"axial dispersion mill: Newton did not converge: residual {res:.3g} > tol {tol:g} x "
                          f"scale {scale(C):.3g} after {its} iterations on {m} volumes ({kin.describe()})")
    out = C[-1]  # product = v c(1) with v = 1
    return out[:-1].copy(), float(out[-1]), res, its


def _block_thomas(D, lower: float, upper: float, rhs):
    """Solve the block-tridiagonal system lower x_{k-1} + D_k x_k + upper x_{k+1} = rhs_k
    (scalar off-diagonal blocks, the transport) by block elimination: one dense LU per node,
    O(m n^3) instead of the fill-in of a general sparse LU."""
    m1, n1 = rhs.shape
    lus, r = [], rhs.copy()
    Dk = D[0]
    for k in range(m1):
        if k:
            Dk = D[k] - (lower * upper) * scipy.linalg.lu_solve(lus[-1], np.eye(n1), check_finite=False)
            r[k] = r[k] - lower * scipy.linalg.lu_solve(lus[-1], r[k - 1], check_finite=False)
        lus.append(scipy.linalg.lu_factor(Dk, check_finite=False))
    x = np.empty_like(r)
    x[-1] = scipy.linalg.lu_solve(lus[-1], r[-1], check_finite=False)
    for k in range(m1 - 2, -1, -1):
        x[k] = scipy.linalg.lu_solve(lus[k], r[k] - upper * x[k + 1], check_finite=False)
    return x


# ------------------------------------------------------------------ micromixing
@dataclass(frozen=True)
class MicromixingBounds(_SplitError):
    """Products of the two micromixing limits for one RTD: ``segregated`` and
    ``max_mixedness`` (N,), ``spread`` max |difference|, ``coincide`` True for linear
    kinetics (then both are the one exact answer), ``note`` what the user should know."""

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
    """h(lambda) = E / (1 - F) on [0, lam_max]. Analytic for perfect mixing and tanks in
    series; otherwise the survival is integrated from the tail, S(t) = (1 - F(lam_max)) +
    int_t^lam_max E (cumulative Simpson on ``nodes`` points, accurate in relative terms
    where 1 - F(t) would cancel), and h interpolated by a cubic spline: a smooth forcing
    for the implicit integrator. Returns (h, interpolation error estimate of h relative
    to its maximum: the spline against the half grid)."""
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


def micromixing_bounds(kin: Kinetics, feed, model, *, rtol: float = 1e-9, atol: float = 1e-13) -> MicromixingBounds:
    """Both micromixing limits for the RTD ``model`` (an rtd model with pdf and cdf)."""
    feed, _ = _check(kin, feed, float(getattr(model, "mean", 1.0)))
    start = time.perf_counter()
    if type(model).__name__ == "PlugFlow":
        res = batch_nonlinear(kin, feed, [model.mean], rtol=rtol, atol=atol)
        return MicromixingBounds(res.M[0], res.M[0], 0.0, True, "plug flow: no mixing at all, the two limits are "
                                 "the same batch grind", res.error_estimate, time.perf_counter() - start)
    if kin.is_linear:
        from millflow.mill.segregated import segregated
        p, _, err, _ = segregated(kin.S, kin.b, feed, model, holdup=False)
        return MicromixingBounds(p, p, 0.0, True, "linear (first-order) kinetics: segregation and maximum mixedness "
                                 "coincide, the RTD alone fixes the product; one exact answer is given",
                                 float(err), time.perf_counter() - start)
    t_max = _horizon(model)
    y0 = np.append(feed, 0.0)
    sol = solve_ivp(lambda _t, y: kin.rate(y), (0.0, t_max), y0, method="BDF", jac=lambda _t, y: kin.jacobian(y),
                    rtol=rtol, atol=atol, dense_output=True)
    if not sol.success:
        raise SolverError(f"micromixing (segregation): the batch solve failed: {sol.message}")
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

    zw = solve_ivp(rhs, (0.0, lam_max), ys, method="BDF", jac=jac, rtol=rtol, atol=atol)
    if not zw.success:
        raise SolverError(f"micromixing (maximum mixedness): the Zwietering solve failed: {zw.message}")
    mm = zw.y[:, -1]
    spread = float(np.abs(seg[:-1] - mm[:-1]).max())
    # integrator tolerances, the quadrature's estimate, and the hazard interpolation
    # (a relative error in h moves the product by at most about as much, times |M - f|)
    err = float(seg_err + rtol * np.abs(mm).max() * 10 + atol + h_err * np.abs(mm - y0).max())
    return MicromixingBounds(seg[:-1], mm[:-1], spread, False,
                             "non-linear kinetics: the product depends on micromixing, which the RTD cannot tell; "
                             "these are the two extremes of mixing, not bounds: a mill of intermediate mixing (e.g. "
                             "tanks in series) can lie outside them class by class (Zwietering's ordering holds only "
                             "for one species with a rate of one convexity)", err, time.perf_counter() - start,
                             {"overflow": (float(seg[-1]), float(mm[-1])), "lambda_max_s": lam_max,
                              "kinetics": kin.describe(), "hazard_interpolation_error": h_err})
