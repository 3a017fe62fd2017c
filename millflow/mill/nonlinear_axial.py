"""Axial-dispersion mills with non-linear kinetics: the closed and the open vessel.

With classification along the axis (class i at velocity d_i* u) and size-dependent
dispersion.

The steady convection-dispersion-reaction equation of every class,

    d/dz [ v_i c_i - (w_i/Pe) dc_i/dz ] = tau R_i(c),

is discretised exactly as the linear mills do (vertex-centred finite volumes with
exponentially fitted fluxes, the reaction lumped at the nodes): the closed vessel on
[0, 1] with Danckwerts boundaries (:mod:`millflow.mill.axial`), the open vessel on the
whole line with its sampled (v c(1)) or flux discharge (:mod:`millflow.mill.axial_open`).
The aggregation overflow travels unclassified (v = w = 1). Node k's balance,

    F_(k-1/2) - F_(k+1/2) + tau w_k R(c_k) (+ f at the feed node, - v c at the outflow node) = 0,

F_(k+1/2) = alpha c_k - beta c_(k+1) per class, is solved for all nodes together by
Newton (:mod:`millflow.mill.newton`): the Jacobian is block tridiagonal, with the dense
blocks tau w_k dR/dc at the nodes (built for all nodes in one vectorised call) and the
diagonal transport blocks between them; block elimination inverts each node's Schur
complement once per factorisation, and the chord iteration keeps the factors while they
contract.

Grids: M, 2M, 4M, ... volumes (:func:`millflow.mill.axial.refine_grids`: Richardson
extrapolation where the observed order is 2 and stable, else the finest grid with the
estimate |p_2M - p_M| / (2^q - 1)), until the error estimate of the product, of the
overflow and of the hold-up / tau is below the tolerance; each grid starts from the
previous grid's solution interpolated onto it (grid sequencing: one or two chord steps
per grid). The Newton error of each grid (far below the tolerance) is added. With
``m_cells`` one grid of that many volumes is solved with the grid of half as many, and
|p_M - p_M/2| is the estimate (over-estimates a second-order error by about 3x).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from millflow.errors import InputError, SolverError
from millflow.mill.axial import PE_MIXED, refine_grids, solve_axial_grid
from millflow.mill.axial_open import check_discharge, solve_axial_open_grid, tail_length
from millflow.mill.finite_volume import AxialFaces, closed_faces, node_losses, open_faces, tridiagonal
from millflow.mill.newton import BlockTridiagonalFactor, newton
from millflow.mill.nonlinear_cell import NEWTON_RTOL, NonlinearSteady, _check, _discharge, _no_age, well_mixed
from millflow.nonlinear.kinetics import Kinetics
from millflow.threads import limit_blas_threads

__all__ = ["axial_dispersion", "axial_open", "M_MAX"]

#: Largest grid of the refinement (volumes in the mill).
M_MAX = 4096


@dataclass(frozen=True)
class _Line:
    """One grid of the axial line: nodes, control volumes and node-balance coefficients.

    One grid: nodes z, control volumes ``weights``, the node-balance coefficients
    (lower (m - 1, n1): of c_(k-1) in equation k; diag (m, n1); upper (m - 1, n1): of
    c_(k+1)), the feed node, and the weights of the hold-up.
    """

    z: np.ndarray
    weights: np.ndarray
    lower: np.ndarray
    diag: np.ndarray
    upper: np.ndarray
    feed_node: int
    out_node: int
    holdup_weights: np.ndarray
    v: np.ndarray
    h: np.ndarray
    w: np.ndarray
    pe: float
    open: bool
    flux: bool


def _closed_line(pe, m, v, w) -> _Line:
    return _from_faces(closed_faces(pe, m, v, w), v, w, pe, False, False)


def _open_line(kin, tau, pe, m, v, w, flux=False):
    faces = open_faces(pe, m, v, w, tail_length(np.zeros(v.size), tau, pe, v, w))
    return _from_faces(faces, v, w, pe, True, flux)


def _from_faces(faces: AxialFaces, v, w, pe, open_vessel, flux) -> _Line:
    """Node-balance coefficients (node-major) of the grid ``faces``: minus its tridiagonal matrices."""
    # outflow at the downstream end; node-major (node, class) like the concentrations
    lower, diag, upper = (np.ascontiguousarray(-a.T) for a in tridiagonal(faces, node_losses(faces, v)))
    return _Line(faces.z, faces.weights, lower, diag, upper, faces.inlet, faces.outlet, faces.upstream,
                 v, faces.h, w, pe, open_vessel, flux)


def _scale_terms(line):
    return np.abs(line.diag).copy() + np.vstack([np.abs(line.upper), np.zeros((1, line.v.size))]) + np.vstack(
        [np.zeros((1, line.v.size)), np.abs(line.lower)])


def _newton_line(kin: Kinetics, line: _Line, tau, src, C0, *, tol, unit, fixed=None, warm=None):
    """Newton on the node balances of ``line``.

    Newton on the node balances of ``line`` with source ``src`` (m, n1); ``fixed`` (n1,):
    the last node's value held fixed (the back-dispersion layer), the system on the
    other nodes. Returns (C (m, n1), NewtonResult).
    """
    m, n1 = src.shape
    lo, dg, up, wts = line.lower, line.diag, line.upper, line.weights
    if fixed is not None:  # drop the last node: its flux into the previous node is a source
        m -= 1
        lo, up, wts = lo[:m - 1], up[:m - 1], wts[:m]
        dg = dg[:m].copy()
        src = src[:m].copy()
        src[-1] += line.upper[m - 1] * fixed
    terms = _scale_terms(line)[:m]
    feed_size = float(np.abs(src).sum())
    diag_idx = np.arange(n1)

    def F(y):
        C = y.reshape(m, n1)
        out = dg * C + src + tau * wts[:, None] * kin.rate_many(C)
        out[1:] += lo * C[:-1]
        out[:-1] += up * C[1:]
        return out.ravel()

    def factor(y, shift):
        def blocks():
            for s0, J in kin.jacobian_chunks(y.reshape(m, n1)):
                for i, Jk in enumerate(J):
                    k = s0 + i
                    D = (tau * wts[k]) * Jk
                    D[diag_idx, diag_idx] += dg[k] - shift * tau * wts[k]
                    yield D
        return BlockTridiagonalFactor(blocks(), lo, up)

    def scale(y):
        C = y.reshape(m, n1)
        try:
            flux = float((tau * wts * np.abs(kin.rates(C[:, :-1]) * C[:, :-1]).sum(axis=1)).max())
        except SolverError:
            flux = 0.0
        return float(max(feed_size, float((terms * np.abs(C)).max()), flux, np.finfo(float).tiny))

    def jacobian(y):
        import scipy.sparse as sp

        blocks = (tau * wts)[:, None, None] * kin.jacobian_many(y.reshape(m, n1))
        blocks[:, diag_idx, diag_idx] += dg
        B = sp.bsr_matrix((blocks, np.arange(m), np.arange(m + 1)), shape=(m * n1, m * n1))
        k = np.arange(m - 1)[:, None] * n1 + diag_idx[None, :]
        rows = np.concatenate([(k + n1).ravel(), k.ravel()])
        cols = np.concatenate([k.ravel(), (k + n1).ravel()])
        off = sp.csr_matrix((np.concatenate([lo.ravel(), up.ravel()]), (rows, cols)), shape=(m * n1, m * n1))
        return (B + off).tocsc()

    r = newton(F, factor, np.asarray(C0, float)[:m].ravel(), scale, tol=tol, unit=unit, what=kin.describe(),
               dt0=0.1 * tau, warm=warm, dynamics=(np.repeat(tau * wts, n1), jacobian))
    return r.y.reshape(m, n1), r


def _linear_start(kin, line, tau, feed):
    """The first-order solution on ``line``: the start of Newton on the first grid.

    The first-order solution on ``line`` (the linear mill's solvers on the same nodes), the
    overflow zero: the start of Newton on the first grid.
    """
    v, w = line.v[:-1], line.w[:-1]
    if line.open:
        m = line.out_node - line.feed_node
        _, c, _, _ = solve_axial_open_grid(kin.S, kin.b, feed, tau, line.pe, m, v, w,
                                           "flux" if line.flux else "sampled", tail=float(-line.z[0]))
    else:
        _, c, _ = solve_axial_grid(kin.S, kin.b, feed, tau, line.pe, line.z.size - 1, v, w)
    return np.concatenate([np.maximum(c, 0.0), np.zeros((c.shape[0], 1))], axis=1)


def _solve_line_steady(kin, line, tau, feed, C0=None, unit=None):
    """The steady node concentrations on ``line`` by Newton.

    The steady node concentrations (m, n1) on ``line`` by Newton (from ``C0`` or the
    first-order solution); returns C, or (C, NewtonResult) when ``unit`` is given.
    """
    n1 = kin.n + 1
    if C0 is None:
        C0 = _linear_start(kin, line, tau, feed)
    src = np.zeros((line.z.size, n1))
    src[line.feed_node] = np.append(feed, 0.0)
    C, r = _newton_line(kin, line, tau, src, C0, tol=NEWTON_RTOL,
                        unit=unit or f"axial dispersion mill ({line.z.size - 1} volumes)")
    return (C, r) if unit is not None else C


def back_layer(kin, line, tau, C):
    """Hold-up of the open vessel's back-dispersion layer.

    tau int_(-inf)^1 c^ dz of the open vessel's sampled discharge: c^ solves the
    source-free node balances upstream of z = 1 with c^(1) = c(1) (Newton), plus the half
    volume at z = 1 (:mod:`millflow.mill.axial_open`); (n1,) [s].
    """
    k1 = line.out_node
    n1 = C.shape[1]
    if k1 == 0:
        return tau * 0.5 * line.h[0] * C[k1]
    sub = _Line(line.z[:k1 + 1], line.weights[:k1 + 1], line.lower[:k1], line.diag[:k1 + 1], line.upper[:k1], 0, k1,
                line.weights[:k1 + 1], line.v, line.h[:k1], line.w, line.pe, line.open, line.flux)
    Cb, _ = _newton_line(kin, sub, tau, np.zeros((k1 + 1, n1)), np.maximum(C[:k1 + 1], 0.0), tol=NEWTON_RTOL,
                         unit="open axial dispersion mill, back-dispersion layer", fixed=C[k1])
    return tau * (line.weights[:k1, None] * Cb).sum(axis=0) + tau * 0.5 * line.h[k1 - 1] * C[k1]


def _grid_solver(kin: Kinetics, feed, tau, pe, v, w, open_vessel: bool, discharge: str, tol: float):
    """The solver of one grid for :func:`refine_grids`, with grid sequencing.

    solve(M) -> (z, C, reported vector, extras) for :func:`refine_grids`; grids solved in
    increasing M start from the previous grid's solution (grid sequencing).
    """
    n1 = kin.n + 1
    last = {}
    y_feed = np.append(feed, 0.0)
    flux = open_vessel and discharge == "flux"

    def solve(M):
        line = _open_line(kin, tau, pe, M, v, w, flux) if open_vessel else _closed_line(pe, M, v, w)
        C0 = None
        if "z" in last:  # interpolate the previous grid's solution
            C0 = np.stack([np.interp(line.z, last["z"], last["C"][:, i]) for i in range(n1)], axis=1)
        unit = f"axial dispersion mill ({'open' if open_vessel else 'closed'} vessel, {M} volumes)"
        C, r = _solve_line_steady(kin, line, tau, feed, C0, unit=unit)
        last.update(z=line.z, C=C)
        k1 = line.out_node
        dC = r.correction.reshape(C.shape)  # the next step: the Newton error of C, mapped to what is reported
        if flux:
            hw = line.holdup_weights
            p = y_feed + tau * (hw[:, None] * kin.rate_many(C)).sum(axis=0)
            up = hw > 0
            dp = tau * np.einsum("k,kij,kj->i", hw[up], kin.jacobian_many(C[up]), dC[up])
        else:
            p = v * C[k1]
            dp = v * dC[k1]
        hold = tau * (line.holdup_weights[:, None] * C).sum(axis=0)
        dh = (line.holdup_weights[:, None] * dC).sum(axis=0)
        newton_err = float(max(np.abs(dp).max(), np.abs(dh).max())) / (1.0 - r.rho)
        if open_vessel and discharge == "sampled":  # the back-dispersion layer of c(1)
            hold = hold + back_layer(kin, line, tau, C)
        reported = np.concatenate([p, hold / tau])
        return line.z, C, reported, {"newton_error": newton_err, "iterations": r.iterations, "residual": r.residual,
                                     "volumes": M}

    return solve


def _check_axial(kin, feed, tau, pe, d, dispersion, m_cells):
    feed, tau = _check(kin, feed, tau)
    _no_age(kin, "axial dispersion mill")
    if not (isinstance(pe, (int, float, np.floating)) and math.isfinite(pe) and pe > 0):
        raise InputError(f"pe = {pe!r}: expected a Peclet number > 0")
    if m_cells is not None and (int(m_cells) != m_cells or m_cells < 4 or m_cells % 2):
        raise InputError(f"m_cells = {m_cells!r}: expected an even integer >= 4")
    dx = _discharge(kin, d)
    v = np.ones(kin.n + 1) if dx is None else dx
    if dispersion is None:
        w = None
    else:
        from millflow import checks

        w = np.append(checks.class_vector(dispersion, kin.n, "dispersion", "relative dispersion", positive=True), 1.0)
    return feed, float(tau), float(pe), dx, v, w


@limit_blas_threads
def _solve(kin, feed, tau, pe, v, w, open_vessel, discharge, tol, m_cells, m_start, m_max, positions, start, what):
    n = kin.n
    solve = _grid_solver(kin, feed, tau, pe, v, w, open_vessel, discharge, tol)
    if m_cells is not None:
        coarse = solve(int(m_cells) // 2)
        fine = solve(int(m_cells))
        both = fine[2]
        est = float(np.abs(fine[2] - coarse[2]).max())
        history, order, final = [(int(m_cells) // 2, float("nan")), (int(m_cells), est)], float("nan"), fine
        newton_err = max(fine[3]["newton_error"], coarse[3]["newton_error"])
        note = f"|p(M) - p(M/2)|, M = {int(m_cells)}"
    else:
        extras = []

        def grid(M):
            out = solve(M)
            extras.append(out[3])
            return out

        both, est, order, history, final, _, _ = refine_grids(grid, float((v / w).max()) * pe, tol=tol,
                                                              m_start=m_start, m_max=m_max)
        newton_err = max(e["newton_error"] for e in extras[-3:])
        note = "Richardson estimate over doubled grids (axial.refine_grids)"
    z, C, _, ex = final
    p, over = both[:n], float(both[n])
    hold = tau * both[n + 1:2 * n + 1]
    err = est + newton_err
    info = {"kinetics": kin.describe(), "error": note, "order": order, "history": history,
            "control_volumes": int(ex["volumes"]),
            "holdup": hold, "holdup_overflow": float(tau * both[2 * n + 1]), "z": z, "density": tau * C}
    if positions is not None:
        pos = np.atleast_1d(np.asarray(positions, float))
        info["profile"] = tau * np.stack([np.interp(pos, z, C[:, i]) for i in range(n)], axis=1)
    return NonlinearSteady(p, over, what, ex["residual"], err, float(abs(p.sum() + over - feed.sum())),
                           ex["iterations"], time.perf_counter() - start, info)


def axial_dispersion(kin: Kinetics, feed, tau: float, pe: float, d=None, *, dispersion=None, tol: float = 1e-8,
                     m_cells: int | None = None, m_start: int = 16, m_max: int = M_MAX,
                     positions=None) -> NonlinearSteady:
    """Closed-vessel axial-dispersion mill with non-linear kinetics.

    Closed-vessel axial-dispersion mill (Peclet ``pe``) with non-linear kinetics (module
    docstring): ``d`` (N,) the relative axial velocity d_i* (classification along the
    axis), ``dispersion`` (N,) the relative dispersion (default 1). Grids refined until
    the error estimate of product, overflow and hold-up / tau is below ``tol`` (relative
    to the feed), or one grid of ``m_cells`` volumes checked against half of it.
    ``info``: ``holdup`` [s], ``z`` and ``density`` (tau c, finest grid), ``profile`` at
    ``positions``.
    """
    start = time.perf_counter()
    feed, tau, pe, dx, v, w = _check_axial(kin, feed, tau, pe, d, dispersion, m_cells)
    w = np.ones(kin.n + 1) if w is None else w
    if kin.is_linear and dx is None and dispersion is None and m_cells is not None:
        _, _, p = solve_axial_grid(kin.S, kin.b, feed, tau, pe, int(m_cells))
        _, _, p2 = solve_axial_grid(kin.S, kin.b, feed, tau, pe, int(m_cells) // 2)
        return NonlinearSteady(p, 0.0, "exact linear (axial grid)", 0.0, float(np.abs(p - p2).max()),
                               float(abs(p.sum() - feed.sum())), 0, time.perf_counter() - start, {"kinetics": "linear"})
    if pe * float(np.min(v / w)) < PE_MIXED:  # the Pe -> 0 limit: a perfect mixer with rates S / v
        r = well_mixed(kin, feed, tau, None if dx is None else dx[:-1], unit="axial dispersion mill (Pe -> 0)")
        return NonlinearSteady(r.product, r.overflow_mass, "axial dispersion, Pe -> 0: the perfectly mixed limit",
                               r.residual, r.error_estimate, r.mass_balance_error, r.iterations, r.runtime_s, r.info)
    how = f"axial dispersion (closed vessel{', d* in the velocity' if dx is not None else ''}), Newton on all nodes"
    return _solve(kin, feed, tau, pe, v, w, False, "", tol, m_cells, m_start, m_max, positions, start, how)


def axial_open(kin: Kinetics, feed, tau: float, pe: float, d=None, *, dispersion=None, discharge: str = "sampled",
               tol: float = 1e-8, m_cells: int | None = None, m_start: int = 16, m_max: int = M_MAX,
               positions=None) -> NonlinearSteady:
    """Open-vessel axial-dispersion mill with non-linear kinetics.

    Open-vessel axial-dispersion mill with non-linear kinetics (the whole line, feed at
    z = 0, discharge at z = 1, :mod:`millflow.mill.axial_open`): ``discharge`` "sampled"
    (p = v c(1); needs one Peclet number Pe d*/dispersion for all classes; hold-up with the
    back-dispersion layer of c(1), solved by Newton on the source-free equations upstream
    of z = 1) or "flux" (the net flux through z = 1, p = f + tau int_(-inf)^1 R(c) dz,
    hold-up tau int_(-inf)^1 c dz). Default dispersion = d (one Peclet number). Grids and
    estimate as :func:`axial_dispersion`.
    """
    start = time.perf_counter()
    feed, tau, pe, dx, v, w = _check_axial(kin, feed, tau, pe, d, dispersion, m_cells)
    w = v.copy() if w is None else w
    discharge = check_discharge(discharge, v[:-1], w[:-1])
    if discharge == "sampled" and abs(v[-1] / w[-1] - v[0] / w[0]) > 1e-9 * v[0] / w[0]:
        w = w.copy()
        w[-1] = v[-1] * w[0] / v[0]  # the overflow at the classes' Peclet number (mass conservation of sampling)
    how = (f"axial dispersion (open vessel, {discharge} discharge{', d* in the velocity' if dx is not None else ''}), "
           "Newton on all nodes")
    return _solve(kin, feed, tau, pe, v, w, True, discharge, tol, m_cells, m_start, m_max, positions, start, how)
