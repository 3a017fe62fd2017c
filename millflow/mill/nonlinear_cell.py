"""The non-linear steady mill's common parts and its one cell.

The result (:class:`NonlinearSteady`), the input checks, Newton's scaled criterion
(:func:`residual_scale`, :data:`NEWTON_RTOL`), the Newton solve of one well-mixed cell with
classification (``_solve_cell``: 0 = y_in - d* y + tau R(y)), its first-order start, and the
perfectly mixed mill (:func:`well_mixed`). :mod:`millflow.mill.nonlinear` (cells, chains,
plug flow, compositions) and :mod:`millflow.mill.nonlinear_axial` build on it.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from millflow import checks
from millflow.errors import InputError, SolverError
from millflow.mill.newton import MAX_ITER, PTC_ITER, DenseFactor, newton
from millflow.mill.well_mixed import solve_well_mixed
from millflow.nonlinear.kinetics import Kinetics
from millflow.threads import limit_blas_threads

__all__ = ["NonlinearSteady", "GRID_NOTE", "NEWTON_RTOL", "residual_scale", "well_mixed"]


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
    """Steady product of a non-linear mill with the diagnostics of the solve.

    Steady product (mass flows per unit feed rate, sum = sum(feed) - overflow) with the
    diagnostics of the solve: ``residual`` max |F| at the answer, ``error_estimate`` the
    size of the next Newton step (or the ODE's estimate), ``iterations``.
    """

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
    if not (isinstance(tau, (int, float, np.floating)) and math.isfinite(tau) and tau > 0):
        raise InputError(f"tau = {tau!r}: expected a mean residence time > 0 [s]")
    return feed, float(tau)


def _no_age(kin: Kinetics, where: str):
    if kin.age is not None:
        raise InputError(f"{where}: kinetics with kappa(t) (slowing-down in the material's age) are solved by "
                         "segregated flow over the exit ages, or with classification in cells by the age-structured "
                         "balance (solve_transport, steady_mill)")


def residual_scale(kin: Kinetics, y_in, y, tau, d=None) -> float:
    """The size of the terms of the steady residual (Newton's scale).

    The size of the terms the steady residual F = y_in - d* y + tau R(y) is made of:
    s = max(sum|y_in|, max|y|, max|d* y|, tau sum_i S_i[M] M_i) (the feed, the state, the breakage
    flux through the cell). Rounding alone leaves |F| ~ N eps s, so the convergence test
    is relative to s: a residual of 1e-11 on a state of order 1 with tau S ~ 10 is
    converged, whatever units the feed rate is given in.
    """
    M = y[:-1]
    try:
        flux = float(np.abs(kin.rates(M) * M).sum())
    except SolverError:
        flux = 0.0
    out = max(np.abs(y_in).sum(), np.abs(y).max(), tau * flux, np.finfo(float).tiny)
    return float(out if d is None else max(out, np.abs(d * y).max()))


#: Relative tolerance of the non-linear Newton solves (see :func:`residual_scale`).
NEWTON_RTOL = 1e-11


def _solve_cell(kin: Kinetics, y_in, tau, y0, *, tol, max_iter, ptc_iter, unit, phases=("newton",
                "pseudo-transient", "newton"), d=None, warm=None):
    """Newton on one cell's steady balance.

    Newton on F(y) = y_in - d* y + tau R(y) (``d`` the (N + 1,) normalised discharge, None
    for ones): a :class:`~millflow.mill.newton.NewtonResult`.
    """
    dd = np.ones(y_in.size) if d is None else np.asarray(d, float)
    diag = np.arange(y_in.size)

    def F(y):
        return y_in - dd * y + tau * kin.rate(y)

    def jacobian(y):
        A = tau * kin.jacobian(y)
        A[diag, diag] -= dd
        return A

    def factor(y, shift):
        A = jacobian(y)
        A[diag, diag] -= shift
        return DenseFactor(A)

    return newton(F, factor, y0, lambda y: residual_scale(kin, y_in, y, tau, d), tol=tol, max_iter=max_iter,
                  ptc_iter=ptc_iter, unit=unit, what=kin.describe(), dt0=0.1 * tau, warm=warm, phases=phases,
                  dynamics=(np.full(y_in.size, tau), jacobian))


@limit_blas_threads  # small dense Newton systems: one BLAS thread (millflow.threads)
def _newton_cell(kin: Kinetics, y_in, tau, y0, *, tol, max_iter, unit,
                 phases=("newton", "pseudo-transient", "newton"), d=None, ptc_iter: int = PTC_ITER):
    """Solve one cell's steady balance F(y) = 0.

    Solve F(y) = y_in - d* y + tau R(y) = 0 (``d`` the (N + 1,) normalised discharge,
    None for ones); returns (y, residual, error estimate of y, iterations, how).

    Stated criterion: converged when max|F| <= tol * s, s = :func:`residual_scale` (the
    feed, the state and the breakage flux), or, when the line search can no longer
    reduce max|F| (the rounding floor), when the full Newton step is itself below
    tol * s. ``phases``: Newton, then (if it stalls) pseudo-transient continuation to
    residual 1e-6 s (its own budget ``ptc_iter``), then Newton again.
    """
    r = _solve_cell(kin, y_in, tau, y0, tol=tol, max_iter=max_iter, ptc_iter=ptc_iter, unit=unit, phases=phases,
                    d=d)
    return r.y, r.residual, r.step, r.iterations, r.how


def _discharge(kin: Kinetics, d):
    """(N + 1,) normalised discharge d* of the state, or None for no classification.

    The aggregation overflow (mass above the top class) leaves unclassified (d* = 1): the
    kinetics do not break it, so a grate holding it back (d* -> 0) would accumulate it
    without bound and leave no steady state; it is a grid artefact (``overflow_mass``, kept
    small by a grid top above the aggregates), not a class the mill can retain.
    """
    if d is None:
        return None
    d = checks.class_vector(d, kin.n, "d", "normalised discharge rate")
    if not np.all(d > 0):
        raise InputError("d: expected normalised discharge rates d_i* > 0 (d* = tau d_i)")
    return np.append(d, 1.0)


class _FirstOrder:
    """Eq. 3 for one cell with given rates by one triangular solve on a kept matrix.

    Eq. 3 for one cell with given rates, (diag(1 + s) - b diag(s)) x = f, s = tau S / d*, by
    one triangular solve on a kept matrix: with q = s' x (s' = s, or 1 where s = 0) it is
    (diag((1 + s) / s') - b Z) q = f, Z zeroing the columns of s = 0, so only the diagonal
    changes from one solve to the next (a guess for Newton; no full matrix built per solve).
    """

    def __init__(self, b):
        from scipy.linalg.lapack import dtrtrs

        self.b, self.pos, self.trtrs = b, None, dtrtrs

    def solve(self, S, f, tau, d=None):
        s = tau * (S if d is None else S / d)
        pos = s > 1e-12
        if self.pos is None or (pos != self.pos).any():
            self.W = np.ascontiguousarray(-self.b * pos[None, :])
            self.pos = pos
        sp = np.where(pos, s, 1.0)
        self.W.flat[:: s.size + 1] = (1.0 + s) / sp
        q, info = self.trtrs(self.W.T, f, lower=0, trans=1)  # W.T: LAPACK's column order, no copy
        x = q / sp
        return x if info == 0 and np.isfinite(x).all() else None


def _cell_guess(kin: Kinetics, y_in, tau, dk, state=None, passes: int = 2, first=None):
    """Start of a cell's Newton: the first-order cell with frozen rates.

    Start of a cell's Newton: the first-order cell (eq. 3, one triangular solve) with the
    rates S_i[M] frozen at ``state`` (the previous cell's content; without one the
    first-order cell's), repeated ``passes`` times with the rates at the last answer
    (Picard steps, each a triangular solve, that carry the population and fines terms:
    measured ~8x closer per pass, which saves the Newton iterations that cost a rate
    evaluation each); the overflow passes through. ``first``: a kept :class:`_FirstOrder`.
    """
    first = _FirstOrder(kin.b) if first is None else first
    d = None if dk is None else dk[:-1]

    def first_order(S):  # the cell's content (product / d*) with rates S
        p = first.solve(S, y_in[:-1], tau, d)
        if p is None:
            p = solve_well_mixed(kin.S, kin.b, y_in[:-1], tau, d)
        return np.maximum(p if d is None else p / d, 0.0)

    if kin.population is None and kin.fines is None:
        return np.append(first_order(kin.S), y_in[-1])
    if state is None:  # no previous cell: the first-order cell's content
        state = first_order(kin.S)
    for _ in range(passes):
        try:
            state = first_order(kin.rates(state))
        except SolverError:
            break
    return np.append(state, y_in[-1])


def well_mixed(kin: Kinetics, feed, tau: float, d=None, *, tol: float = NEWTON_RTOL, max_iter: int = MAX_ITER,
               ptc_iter: int = PTC_ITER, unit: str = "perfectly mixed mill") -> NonlinearSteady:
    """Steady product of a perfectly mixed mill with non-linear kinetics (eq. 3 + R(M)).

    ``d`` (N,): normalised discharge d_i* (classification at the discharge), None for
    d* = 1. The state is y = m / tau, m the hold-up per unit feed rate [s] (y = M, the
    hold-up mass fractions, for an unclassified mill fed at unit rate): eq. 1 with
    p_i = d_i* y_i and H R(M) for the breakage and aggregation terms gives the steady
    residual y_in - d* y + tau R(y); R acts on the hold-up, whose total exceeds the
    feed's where coarse classes are retained (d* < 1). ``info["holdup"]`` is m.
    Error estimate: the product's change under the next (chord) step, d* dy / (1 - rho)
    (:mod:`millflow.mill.newton`).
    ``max_iter`` Newton iterations per Newton phase, ``ptc_iter`` pseudo-transient steps.
    """
    feed, tau = _check(kin, feed, tau)
    _no_age(kin, unit)
    dx = _discharge(kin, d)
    start = time.perf_counter()
    if kin.is_linear:
        lin = solve_well_mixed(kin.S, kin.b, feed, tau, None if dx is None else dx[:-1])
        return NonlinearSteady(lin, 0.0, "exact linear (eq. 3)", 0.0, float(np.finfo(float).eps * feed.sum() * kin.n),
                               float(abs(lin.sum() - feed.sum())), 0, time.perf_counter() - start,
                               {"kinetics": "linear", "holdup": tau * (lin if dx is None else lin / dx[:-1]),
                                "holdup_overflow": 0.0})
    y_in = np.append(feed, 0.0)
    with _blas():
        r = _solve_cell(kin, y_in, tau, _cell_guess(kin, y_in, tau, dx), tol=tol, max_iter=max_iter,
                        ptc_iter=ptc_iter, unit=unit, d=dx)
    y = r.y
    p = y if dx is None else dx * y
    err = float(np.abs(r.correction if dx is None else dx * r.correction).max()) / (1.0 - r.rho)
    return NonlinearSteady(p[:-1], float(p[-1]), r.how, r.residual, err, float(abs(p.sum() - feed.sum())),
                           r.iterations, time.perf_counter() - start,
                           {"kinetics": kin.describe(), "holdup": tau * y[:-1], "holdup_overflow": float(tau * y[-1]),
                            "holdup_error_estimate": tau * float(np.abs(r.correction).max()) / (1.0 - r.rho),
                            "factorizations": r.factorizations})


def _blas():
    from millflow.threads import single_threaded_blas

    return single_threaded_blas()
