"""Well-mixed cells with breakage: perfect mixing (eq. 3) and networks of cells.

Every cell k of a compartment network (:class:`rtd.CompartmentNetwork`: volumes V,
flows F[k, l] from cell l to cell k, inlet fractions u, exit flows o, bypass beta) is
well mixed. With hold-up m_ik of class i in cell k per unit solids feed rate [s],
the steady balance of eq. (1) written per cell is

    0 = (1 - beta) u_k f_i + sum_l T^i_kl m_il - S_i m_ik + sum_{j<i} b_ij S_j m_jk,

with the transport matrix of class i

    T^i_kl = g_i F[k, l] / V_l  (k != l),   T^i_ll = -(g_i sum_k F[k, l] + h_i o_l) / V_l,

h_i = d_i* the normalised discharge rate at the exit (grate, screen, diaphragm) and
g_i = d_i* when classification acts at every cell outlet (``where="cells"``), g_i = 1
when it acts only at the discharge (``where="discharge"``); ``where`` may also list
the (1-based) cells whose every outlet flow is classified (g and h then depend on the
cell l: g_il = h_il = d_i* there, 1 elsewhere). The product is
p_i = beta f_i + h_i sum_l (o_l / V_l) m_il. With one cell (perfect mixing) this is
eq. (3) and hold-up m_i = tau p_i / d_i*.

The classes couple only downward (b is strictly lower triangular), so the block system
is solved exactly class by class: N solves with the banded n x n matrix
S_i I - T^i, a column-diagonally dominant M-matrix (no pivoting happens, the solution
stays non-negative). A chain of cells without back-mixing (tanks in series) is solved
cell by cell instead: each cell is eq. (3) with tau_k = V_k / Q, one lower-triangular
solve per cell (:func:`millflow.mill.well_mixed.solve_well_mixed`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

from scipy.linalg import lapack

from millflow import compiled
from millflow.errors import SolverError
from millflow.linalg import breakage_matrix

_gtsv = lapack.get_lapack_funcs("gtsv", dtype=np.float64)
_trtrs = lapack.get_lapack_funcs("trtrs", dtype=np.float64)

__all__ = ["CellSolution", "solve_cells", "solve_cells_population", "network_of", "is_chain", "cell_operators"]


@dataclass(frozen=True)
class CellSolution:
    """Steady state of a network of well-mixed cells with breakage.

    Attributes
    ----------
    product : (N,) or (N, m) discharge flows (same unit as the feed).
    holdup : (n, N) or (n, N, m) hold-up of each class in each cell per unit feed
        rate [s] (mass in the cell / feed mass rate).
    method : "cells_chain" (cell by cell triangular solves) or "cells_block"
        (class by class banded solves).
    kernel : which ran the class loop of "cells_block": "compiled" (rows of cells,
        millflow/_cells.c) or "numpy"; "lapack" for "cells_chain".
    """

    product: np.ndarray
    holdup: np.ndarray
    method: str
    kernel: str = "lapack"


def network_of(transport):
    """The :class:`rtd.CompartmentNetwork` of a transport model, or None."""
    if hasattr(transport, "system_matrix") and hasattr(transport, "volumes"):
        return transport
    net = getattr(transport, "network", None)
    if net is None:
        return None
    try:
        return net()
    except Exception:  # e.g. TanksInSeries with non-integer n: no network
        return None


def is_chain(net) -> bool:
    """True for cells in a row fed at cell 0, leaving from the last, no back-mixing."""
    n = net.n
    F = np.asarray(net.flows)
    sub = np.zeros_like(F)
    idx = np.arange(n - 1)
    sub[idx + 1, idx] = F[idx + 1, idx]
    return (
        np.array_equal(F, sub)
        and np.all(F[idx + 1, idx] > 0)
        and net.inlet[0] == 1.0
        and np.all(net.outlet[:-1] == 0)
        and net.outlet[-1] > 0
    )


def classified_cells(n: int, where) -> np.ndarray:
    """Boolean (n,): cells whose every outlet flow is classified (``where`` "cells" or
    a sequence of 1-based cell numbers); "discharge" gives none (exit flows only)."""
    if where == "cells":
        return np.ones(n, dtype=bool)
    mask = np.zeros(n, dtype=bool)
    if where not in (None, "discharge"):
        mask[np.asarray(list(where), dtype=int) - 1] = True
    return mask


def _factors(d, n_cls: int, n: int, where):
    """Scale factors (G on inter-cell flows, H on exit flows) per class and cell, (N, n)."""
    ones = np.ones((n_cls, n))
    if d is None:
        return ones, ones
    d = np.asarray(d, dtype=float)[:, np.newaxis]
    mask = classified_cells(n, where)
    G = np.where(mask[np.newaxis, :], d, 1.0)
    H = G.copy() if where not in (None, "discharge") else np.broadcast_to(d, (n_cls, n)).copy()
    return G, H


def _solve_chain(S, b, feed, net, d, where) -> CellSolution:
    """Tanks in a row: cell k is eq. (3) with tau_k = V_k / Q_k, fed by cell k - 1.

    Cells with the same tau_k and classification share one triangular matrix
    I - tau_k K diag(1/d*) (tanks in series: one matrix, or two with a grate)."""
    n = net.n
    q_through = np.append(np.diag(net.flows, -1), net.outlet[-1])  # flow leaving cell k
    tau_k = net.volumes / q_through
    feed = np.asarray(feed, dtype=float)
    stream = (1.0 - net.bypass) * feed
    holdup = np.empty((n,) + feed.shape)
    K = breakage_matrix(S, b)
    eye = np.eye(S.size)
    cache = {}
    mask = classified_cells(n, where)
    for k in range(n):
        classified = d is not None and (mask[k] or (k == n - 1 and where in (None, "discharge")))
        key = (float(tau_k[k]), classified)
        if key not in cache:
            scale = tau_k[k] / d if classified else np.full(S.size, tau_k[k])
            # Fortran order once: LAPACK would otherwise copy the matrix on every cell
            cache[key] = (np.asfortranarray(eye - K * scale[np.newaxis, :]), scale)
        M, scale = cache[key]
        stream, info = _trtrs(M, stream, lower=1)
        if info != 0:
            raise SolverError(f"cells: singular triangular system in cell {k + 1} (info {info})")
        holdup[k] = stream * (scale if feed.ndim == 1 else scale[:, np.newaxis])
    return CellSolution(stream + net.bypass * feed, holdup, "cells_chain")


def cell_operators(net, d, where, n_cls: int):
    """Transport pieces of the network: (offdiag (n, n) [1/s] = F[k, l] / V_l,
    drain (n,) [1/s] inter-cell outflow rate, exit (n,) [1/s] exit rate,
    G (N, n) and H (N, n) classification factors on inter-cell and exit flows)."""
    V = np.asarray(net.volumes, dtype=float)
    F = np.asarray(net.flows, dtype=float)
    offdiag = F / V[np.newaxis, :]
    drain = F.sum(axis=0) / V
    exit_rate = np.asarray(net.outlet, dtype=float) / V
    G, H = _factors(d, n_cls, net.n, where)
    return offdiag, drain, exit_rate, G, H


def _solve_block(S, b, feed, net, d, where, kernel=None) -> CellSolution:
    """Class by class: (S_i I - T^i) m_i = (1 - beta) u f_i + sum_{j<i} b_ij S_j m_j.

    Tridiagonal networks (cells in a row with back-mixing) run the compiled class loop
    (millflow/_cells.c: Thomas elimination, no pivoting needed for this M-matrix) or,
    without it, LAPACK gtsv per class; other networks a dense solve per class."""
    n_cls = S.size
    n = net.n
    feed = np.asarray(feed, dtype=float)
    cols = feed.shape[1:]  # () or (m,)
    offdiag, drain, exit_rate, G, H = cell_operators(net, d, where, n_cls)
    F = np.asarray(net.flows)
    rows, cls_ = np.nonzero(F)
    tridiagonal = n > 2 and (rows.size == 0 or np.abs(rows - cls_).max() <= 1)
    inlet = (1.0 - net.bypass) * np.asarray(net.inlet, dtype=float)
    source = np.array(inlet.reshape((1, n) + (1,) * len(cols)) * feed[:, np.newaxis], dtype=float)
    diag_all = S[:, np.newaxis] + G * drain + H * exit_rate  # (N, n)
    sub, sup = np.diag(offdiag, -1), np.diag(offdiag, 1)  # flows l -> l+1 and l+1 -> l
    lower_all, upper_all = -G[:, :-1] * sub, -G[:, 1:] * sup  # (N, n - 1) each
    bS = b * S[np.newaxis, :]  # bS[i, j]: rate at which class j breaks into class i
    # Strong back-mixing (r >> 1): the inter-cell flows dwarf what leaves a cell (breakage
    # and exit) and Thomas/LAPACK pivots cancel, losing mass like eps * r (3e-8 at r = 1e8).
    # The subtraction-free factors from the column sums S_i + H exit (what leaves a cell)
    # keep every pivot accurate.
    loss_all = S[:, np.newaxis] + H * exit_rate
    gth = tridiagonal and float(np.max(drain)) > 1e3 * max(float(np.max(exit_rate)), 1e-300)
    module = compiled.kernel("cells", kernel) if tridiagonal and not gth else None
    if gth:
        holdup = _gth_class_loop(loss_all, -lower_all, -upper_all, bS, source, cols)
        kernel = "numpy_gth"
    elif module is not None:
        holdup = np.empty((n_cls, n) + cols)
        bad = module.tridiagonal_classes(lower_all, diag_all, upper_all, bS, source, holdup,
                                            n_cls, n, int(np.prod(cols, dtype=int)))
        if bad:
            raise SolverError(f"cells: zero or non-finite pivot for class {bad} (the cell system is singular)")
        kernel = "compiled"
    else:
        holdup = _class_loop(diag_all, lower_all, upper_all, bS, source, offdiag, G, tridiagonal, cols)
        kernel = "numpy"
    weights = H * exit_rate  # (N, n): classified exit rate of each class from each cell
    product = np.einsum("il,il...->i...", weights, holdup) + net.bypass * feed
    if tridiagonal and not gth:
        # strongly retained classes (d* << 1 at the exit) make the exit loss tiny beside
        # the inter-cell flows, and the ordinary pivots cancel as with strong back-mixing:
        # a mass balance off by more than rounding is solved again with the accurate factors
        lost = np.abs(product.sum(axis=0) - feed.sum(axis=0)).max(initial=0.0)
        if lost > 1e-11 * max(float(np.abs(feed).sum(axis=0).max(initial=0.0)), 1e-300):
            holdup = _gth_class_loop(loss_all, -lower_all, -upper_all, bS, source, cols)
            kernel = "numpy_gth"
            product = np.einsum("il,il...->i...", weights, holdup) + net.bypass * feed
    return CellSolution(product, np.moveaxis(holdup, 1, 0), "cells_block", kernel)


def _gth_class_loop(loss, alpha, beta, bS, source, cols):
    """Hold-up (N, n, *cols) of rows of cells from the subtraction-free LU factors
    (:func:`millflow.mill.axial._gth_factors`): alpha (N, n - 1) the flow rate from cell k
    to k + 1, beta (N, n - 1) from k + 1 to k, loss (N, n) the column sums."""
    from millflow.mill.axial import _gth_factors, _gttrs

    n_cls, n = loss.shape
    piv = _gth_factors(alpha, beta, loss)
    holdup = np.empty((n_cls, n) + cols)
    flat = holdup.reshape(n_cls, -1)
    du2 = np.zeros(max(n - 2, 0))
    ipiv = np.arange(1, n + 1, dtype=np.int32)  # no row exchanges (M-matrix factors)
    for i in range(n_cls):
        rhs = source[i] + (bS[i, :i] @ flat[:i]).reshape(source[i].shape) if i else source[i]
        m_i, info = _gttrs(-alpha[i] / piv[i, :-1], piv[i], -beta[i], du2, ipiv,
                           rhs if cols else rhs[:, np.newaxis])
        if info != 0 or not np.all(np.isfinite(m_i)):
            raise SolverError(f"cells: singular tridiagonal system for class {i + 1} (info {info})")
        holdup[i] = m_i if cols else m_i[:, 0]
    return holdup


def _class_loop(diag_all, lower_all, upper_all, bS, source, offdiag, G, tridiagonal: bool, cols):
    """Hold-up (N, n, *cols) class by class in numpy: LAPACK gtsv for rows of cells
    (the reference and the fallback of millflow/_cells.c), a dense solve otherwise."""
    n_cls, n = diag_all.shape
    holdup = np.empty((n_cls, n) + cols)
    flat = holdup.reshape(n_cls, -1)  # (N, n m): class i's source is bS[i, :i] @ flat[:i]
    for i in range(n_cls):
        rhs = source[i] + (bS[i, :i] @ flat[:i]).reshape(source[i].shape) if i else source[i]
        if tridiagonal:  # gtsv copies its inputs (no overwrite flags): rows can be passed as they are
            _, _, _, m_i, info = _gtsv(lower_all[i], diag_all[i], upper_all[i], rhs if cols else rhs[:, np.newaxis])
            if info != 0:
                raise SolverError(f"cells: singular tridiagonal system for class {i + 1} (info {info})")
            m_i = m_i if cols else m_i[:, 0]
        else:
            M = np.diag(diag_all[i]) - offdiag * G[i][np.newaxis, :]
            m_i = scipy.linalg.solve(M, rhs, check_finite=False)
        holdup[i] = m_i
    return holdup


def solve_cells(S, b, feed, net, d=None, where: str = "discharge", *, kernel: str | None = None) -> CellSolution:
    """Steady product and hold-up of a cell network with breakage (module doc).

    Parameters
    ----------
    S : (N,) rates [1/s]; b : (N, N) fractional breakage distribution.
    feed : (N,) or (N, m) solids feed flows (any mass-rate unit; hold-up is per
        unit of it, in s).
    net : rtd.CompartmentNetwork (volumes in units of time x feed flow).
    d : (N,) normalised discharge rates d_i* or None.
    where : "discharge" (exit flows only), "cells" (every cell outlet) or a sequence
        of 1-based cell numbers whose outlets are classified.
    kernel : who runs the class loop of rows of cells: None (the environment's
        choice, :func:`millflow.compiled.kernel`), "compiled" or "numpy".
    """
    S = np.asarray(S, dtype=float)
    b = np.asarray(b, dtype=float)
    if is_chain(net):
        return _solve_chain(S, b, feed, net, d, where)
    return _solve_block(S, b, feed, net, d, where, kernel)


def solve_cells_population(S, b, feed, nets, d=None, where="discharge"):
    """The block solve of :func:`solve_cells` for many members (and conditions) at once.

    S : (*L, N) rates [1/s]; b : (*Lb, N, N) broadcasting against L; feed : (*Lf, N);
    nets : an array (shape L, dtype object) of rtd.CompartmentNetwork, one per member
    and condition (they may differ: fitted tau or recirculation ratio); d : (*L, N) or
    None; where : "discharge" or "cells".

    Class by class, (S_i I - T^i) m_i = (1 - beta) u f_i + sum_{j<i} b_ij S_j m_j for
    every member at once (a batched dense n x n solve per class), then the product
    p_i = sum_l H_il (o_l/V_l) m_il + beta f_i. Returns (product (*L, N), hold-up
    (*L, n, N) per unit feed rate [s]). The same equations as :func:`solve_cells`, to
    rounding (tests/millflow/fitting/test_fit_mill.py).
    """
    S = np.asarray(S, dtype=float)
    lead, n_cls = S.shape[:-1], S.shape[-1]
    nets = np.asarray(nets, dtype=object).reshape(lead)
    flat_nets = nets.ravel()
    n = flat_nets[0].n
    if any(net.n != n for net in flat_nets):
        raise SolverError("cells population: every member needs the same number of cells")
    L = int(np.prod(lead, dtype=int))
    V = np.array([np.asarray(net.volumes, float) for net in flat_nets])  # (L, n)
    F = np.array([np.asarray(net.flows, float) for net in flat_nets])  # (L, n, n)
    offdiag = F / V[:, np.newaxis, :]
    drain = F.sum(axis=1) / V
    exit_rate = np.array([np.asarray(net.outlet, float) for net in flat_nets]) / V
    bypass = np.array([float(net.bypass) for net in flat_nets])
    inlet = (1.0 - bypass)[:, np.newaxis] * np.array([np.asarray(net.inlet, float) for net in flat_nets])
    Sf = S.reshape(L, n_cls)
    bf = np.broadcast_to(np.asarray(b, dtype=float), lead + (n_cls, n_cls)).reshape(L, n_cls, n_cls)
    ff = np.broadcast_to(np.asarray(feed, dtype=float), lead + (n_cls,)).reshape(L, n_cls)
    if d is None:
        G = H = np.ones((L, n_cls, 1))
    else:
        dd = np.broadcast_to(np.asarray(d, dtype=float), lead + (n_cls,)).reshape(L, n_cls, 1)
        mask = classified_cells(n, where)
        G = np.where(mask[np.newaxis, np.newaxis, :], dd, 1.0)
        H = G if where not in (None, "discharge") else np.broadcast_to(dd, (L, n_cls, n))
    G, H = np.broadcast_to(G, (L, n_cls, n)), np.broadcast_to(H, (L, n_cls, n))
    holdup = np.empty((L, n_cls, n))
    q = np.zeros((L, n_cls, n))  # S_j m_j: breakage flow out of class j in each cell
    eye = np.eye(n)
    with np.errstate(over="ignore", invalid="ignore"):
        for i in range(n_cls):
            rhs = inlet * ff[:, i, np.newaxis]
            if i:
                rhs = rhs + np.einsum("lj,ljc->lc", bf[:, i, :i], q[:, :i])
            diag = Sf[:, i, np.newaxis] + G[:, i] * drain + H[:, i] * exit_rate
            M = eye * diag[:, :, np.newaxis] - offdiag * G[:, i, np.newaxis, :]
            holdup[:, i] = np.linalg.solve(M, rhs[:, :, np.newaxis])[:, :, 0]
            q[:, i] = Sf[:, i, np.newaxis] * holdup[:, i]
    product = np.einsum("lic,lic->li", H * exit_rate[:, np.newaxis, :], holdup) + bypass[:, np.newaxis] * ff
    return product.reshape(lead + (n_cls,)), np.moveaxis(holdup, 1, 2).reshape(lead + (n, n_cls))
