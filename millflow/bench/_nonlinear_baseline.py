"""The non-linear steady mills as the code at commit 43330ce solved them: the baseline
rows of ``millflow bench model-error`` (a faithful copy, kept only for measuring: full
Newton with a fresh Jacobian and LU at every iteration, one cell at a time; axial
dispersion with a Python loop over the nodes for the rates, the Jacobians, one LU and one
inverse per node in the block elimination; the Jacobian of the population term by an
N^3 matrix product, as :class:`millflow.nonlinear.Kinetics` built it then). Same
equations and tolerances (absolute 1e-12 on max|F|) as then; the rate R(M) is the
current one (unchanged since)."""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg
import scipy.sparse

from millflow.errors import InputError, SolverError
from millflow.mill.axial import _bernoulli, solve_axial_grid
from millflow.mill.nonlinear import _check
from millflow.mill.well_mixed import solve_well_mixed
from millflow.nonlinear.kinetics import Kinetics

__all__ = ["well_mixed", "tanks_in_series", "axial_dispersion"]


@dataclass(frozen=True)
class _Result:
    product: np.ndarray
    overflow_mass: float
    method: str
    residual: float
    error_estimate: float
    mass_balance_error: float
    iterations: int
    runtime_s: float
    info: dict = field(default_factory=dict)


def _jacobian_43330ce(self, y) -> np.ndarray:
    """dR/dy, (N + 1, N + 1) dense [1/s]."""
    n = self.n
    M = y[:n]
    Jm = np.zeros((n + 1, n + 1))
    Bm = self.b - np.eye(n)
    if self.population is None and self.fines is None:
        Jm[:n, :n] = Bm * self.S[None, :]
    else:
        S, dS = self.S.copy(), np.zeros((n, n))
        if self.population is not None:
            phi, base = self.population.phi(M)
            # dS_i/dM_m = k_i lambda base_i^(lambda-1) w_im
            dS = (self.S * self.population.lam * base ** (self.population.lam - 1.0))[:, None] * self.population.w
            S = S * phi
        if self.fines is not None:
            k, dk = self.fines.values(M)
            # product rule: d(S_i kappa(F))/dM_m = dS_i/dM_m kappa + S_i kappa'(F) mask_m
            dS = dS * k + dk * S[:, None] * self.fines.mask[None, :]
            S = S * k
        Jm[:n, :n] = Bm * S[None, :] + Bm @ (M[:, None] * dS)
    if self.aggregation is not None:
        Jm[:, :n] += _aggregation_jacobian_43330ce(self.aggregation, M)
    return Jm


_CSR = {}


def _csr(op):
    """The operator's matrices compressed by rows, as they were stored then."""
    if id(op) not in _CSR:
        _CSR.clear()
        _CSR[id(op)] = (op.G.tocsr(), op.G_half.tocsr(), op)
    return _CSR[id(op)]


def _aggregation_jacobian_43330ce(op, M):
    n = op.n
    N = M / op.v
    Jm = 2.0 * (_csr(op)[0] @ N).reshape(n + 1, n)
    Jm[:n] -= M[:, None] * op.beta
    Jm /= op.v[None, :]
    Jm[np.arange(n), np.arange(n)] -= op.beta @ N
    return Jm


def _rate_43330ce(kin, y):
    n = kin.n
    M = y[:n]
    flux = kin.rates(M) * M
    out = np.empty(n + 1)
    out[:n] = kin.b @ flux - flux
    out[n] = 0.0
    if kin.aggregation is not None:
        op = kin.aggregation
        N = M / op.v
        birth = (_csr(op)[1] @ N).reshape(n + 1, n) @ N
        birth[:n] -= M * (op.beta @ N)
        out += birth
    return out




def _newton_cell(kin: Kinetics, y_in, tau, y0, *, tol, max_iter, unit,
                 phases=("newton", "pseudo-transient", "newton")):
    """Solve F(y) = y_in - y + tau R(y) = 0; returns (y, residual, step, iterations, how).
    ``phases``: Newton, then (if it stalls) pseudo-transient continuation to residual
    1e-6, then Newton again."""
    n1 = y_in.size
    eye = np.eye(n1)

    def F(y):
        return y_in - y + tau * _rate_43330ce(kin, y)

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
    for phase in phases:
        if res <= tol:
            break
        ran.append(phase)
        dt = 0.1 * tau
        stalled = False
        while res > tol and its < max_iter:
            its += 1
            J = -eye + tau * _jacobian_43330ce(kin, y)
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
                    break
            else:
                dy = np.linalg.solve(eye / dt - J, f)
                yt = y + dy
                ft = safe_F(yt)
                if ft is None or not np.isfinite(ft).all():
                    dt *= 0.25
                    continue
                dt *= min(10.0, max(0.5, res / max(float(np.abs(ft).max()), 1e-300)))
                if float(np.abs(ft).max()) < 1e-6:
                    y, f, res = yt, ft, float(np.abs(ft).max())
                    break
            y, f, res = yt, ft, float(np.abs(ft).max())
        if res <= tol:
            break
        if phase == "newton" and not stalled and its >= max_iter:
            break
    how = " + ".join(ran) or "newton (start already converged)"
    if res > tol or not np.isfinite(res):
        raise SolverError(f"{unit}: the steady state did not converge: residual max|f - M + tau R(M)| = {res:.3g} "
                          f"> tol {tol:g} after {its} iterations ({kin.describe()})")
    if lu is None:
        lu = scipy.linalg.lu_factor(-eye + tau * _jacobian_43330ce(kin, y), check_finite=False)
    step = float(np.abs(scipy.linalg.lu_solve(lu, -f, check_finite=False)).max())
    return y, res, step, its, how


def well_mixed(kin: Kinetics, feed, tau: float, *, tol: float = 1e-12, max_iter: int = 60,
               unit: str = "perfectly mixed mill"):
    """Steady product of a perfectly mixed mill with non-linear kinetics (eq. 3 + R(M))."""
    feed, tau = _check(kin, feed, tau)
    start = time.perf_counter()
    lin = solve_well_mixed(kin.S, kin.b, feed, tau)
    if kin.is_linear:
        return _Result(lin, 0.0, "exact linear (eq. 3)", 0.0, float(np.finfo(float).eps * feed.sum() * kin.n),
                               float(abs(lin.sum() - feed.sum())), 0, time.perf_counter() - start,
                               {"kinetics": "linear"})
    y_in = np.append(feed, 0.0)
    y, res, step, its, how = _newton_cell(kin, y_in, tau, np.append(np.maximum(lin, 0.0), 0.0), tol=tol,
                                          max_iter=max_iter, unit=unit)
    return _Result(y[:-1], float(y[-1]), how, res, step, float(abs(y.sum() - feed.sum())), its,
                           time.perf_counter() - start, {"kinetics": kin.describe()})


def tanks_in_series(kin: Kinetics, feed, tau: float, n: int, *, tol: float = 1e-12, max_iter: int = 60
                    ):
    """n equal perfect mixers in series (total mean residence time tau), one cell at a time."""
    feed, tau = _check(kin, feed, tau)
    if int(n) != n or n < 1:
        raise InputError(f"n = {n!r}: expected an integer number of tanks >= 1")
    start = time.perf_counter()
    if kin.is_linear:
        p = feed
        for _ in range(int(n)):
            p = solve_well_mixed(kin.S, kin.b, p, tau / n)
        return _Result(p, 0.0, "exact linear (cells)", 0.0, float(np.finfo(float).eps * kin.n * n),
                               float(abs(p.sum() - feed.sum())), 0, time.perf_counter() - start,
                               {"kinetics": "linear"})
    y = np.append(feed, 0.0)
    its, res, step, cells = 0, 0.0, 0.0, []
    for k in range(int(n)):
        guess = np.append(np.maximum(solve_well_mixed(kin.S, kin.b, y[:-1], tau / n), 0.0), y[-1])
        y, r, s, i, how = _newton_cell(kin, y, tau / n, guess, tol=tol, max_iter=max_iter,
                                       unit=f"tanks in series, cell {k + 1} of {int(n)}")
        its += i
        res, step = max(res, r), max(step, s)
        cells.append(y[:-1].copy())
    return _Result(y[:-1], float(y[-1]), f"cells ({how})", res, step, float(abs(y.sum() - feed.sum())), its,
                           time.perf_counter() - start, {"kinetics": kin.describe(), "cells": np.array(cells)})


def axial_dispersion(kin: Kinetics, feed, tau: float, pe: float, *, m_cells: int = 64, tol: float = 1e-12,
                     max_iter: int = 40):
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
        return _Result(p, 0.0, "exact linear (axial grid)", 0.0, float(np.abs(p - p2).max()),
                               float(abs(p.sum() - feed.sum())), 0, time.perf_counter() - start, {"kinetics": "linear"})
    p, over, res, its = _axial_newton(kin, feed, tau, pe, int(m_cells), tol, max_iter)
    p2, over2, _, _ = _axial_newton(kin, feed, tau, pe, int(m_cells) // 2, tol, max_iter)
    err = float(max(np.abs(p - p2).max(), abs(over - over2)))
    return _Result(p, over, f"axial dispersion, {int(m_cells)} volumes, Newton", res, err,
                           float(abs(p.sum() + over - feed.sum())), its, time.perf_counter() - start,
                           {"kinetics": kin.describe(), "error": "|p(M) - p(M/2)|"})


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
        R = np.array([_rate_43330ce(kin, c) for c in C])
        return Tbig @ C.ravel() + src + tau * (wts[:, None] * R).ravel()

    f = F(C)
    res = float(np.abs(f).max())
    its = 0
    while res > tol and its < max_iter:
        its += 1
        D = np.array([tau * wts[k] * _jacobian_43330ce(kin, C[k]) for k in range(m + 1)])
        D[:, np.arange(n1), np.arange(n1)] += main[:, None]
        dC = _block_thomas(D, a, bt, -f.reshape(m + 1, n1))
        lam = 1.0
        while True:
            try:
                ft = F(C + lam * dC)
                if np.abs(ft).max() <= (1.0 - 1e-4 * lam) * res or lam < 1.0 / 256:
                    break
            except SolverError:
                pass
            lam *= 0.5
            if lam < 1.0 / 256:
                ft = None
                break
        if ft is None:
            break
        C, f, res = C + lam * dC, ft, float(np.abs(ft).max())
    if res > tol:
        raise SolverError(f"axial dispersion mill: Newton did not converge: residual {res:.3g} > tol {tol:g} "
                          f"after {its} iterations on {m} volumes ({kin.describe()})")
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


