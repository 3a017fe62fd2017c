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
when it acts only at the discharge (``where="discharge"``). The product is
p_i = beta f_i + h_i sum_l (o_l / V_l) m_il. With one cell (perfect mixing) this is
eq. (3) and hold-up m_i = tau p_i / d_i*.

The classes couple only downward (b is strictly lower triangular), so the block system
is solved exactly class by class: N solves with the banded n x n matrix
S_i I - T^i, a column-diagonally dominant M-matrix (no pivoting happens, the solution
stays non-negative). A chain of cells without back-mixing (tanks in series) is solved
cell by cell instead: each cell is eq. (3) with tau_k = V_k / Q, one lower-triangular
solve per cell (:func:`millflow.linalg.solve_well_mixed`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

from millflow.linalg import solve_well_mixed

__all__ = ["CellSolution", "solve_cells", "network_of", "is_chain", "cell_operators"]


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
    """

    product: np.ndarray
    holdup: np.ndarray
    method: str


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


def _d_factors(d, n_cls: int, where: str):
    """Scale factors (g on inter-cell flows, h on exit flows) per class, (N,) each."""
    if d is None:
        ones = np.ones(n_cls)
        return ones, ones
    h = np.asarray(d, dtype=float)
    g = h if where == "cells" else np.ones(n_cls)
    return g, h


def _solve_chain(S, b, feed, net, d, where) -> CellSolution:
    """Tanks in a row: cell k is eq. (3) with tau_k = V_k / Q_k, fed by cell k - 1."""
    n = net.n
    q_through = np.append(np.diag(net.flows, -1), net.outlet[-1])  # flow leaving cell k
    tau_k = net.volumes / q_through
    feed = np.asarray(feed, dtype=float)
    stream = (1.0 - net.bypass) * feed
    holdup = np.empty((n,) + feed.shape)
    for k in range(n):
        d_k = None if d is None or (where == "discharge" and k < n - 1) else d
        stream = solve_well_mixed(S, b, stream, tau_k[k], d_k)
        dd = 1.0 if d_k is None else (d_k if feed.ndim == 1 else d_k[:, np.newaxis])
        holdup[k] = tau_k[k] * stream / dd
    return CellSolution(stream + net.bypass * feed, holdup, "cells_chain")


def cell_operators(net, d, where: str, n_cls: int):
    """Per-class transport pieces of the network: (offdiag (n, n) [1/s], drain (n,)
    [1/s] inter-cell outflow rate, exit (n,) [1/s] exit rate, g (N,), h (N,))."""
    V = np.asarray(net.volumes, dtype=float)
    F = np.asarray(net.flows, dtype=float)
    offdiag = F / V[np.newaxis, :]
    drain = F.sum(axis=0) / V
    exit_rate = np.asarray(net.outlet, dtype=float) / V
    g, h = _d_factors(d, n_cls, where)
    return offdiag, drain, exit_rate, g, h


def _bandwidths(F: np.ndarray) -> tuple[int, int]:
    rows, cols = np.nonzero(F)
    if rows.size == 0:
        return 0, 0
    return int(max(0, (rows - cols).max())), int(max(0, (cols - rows).max()))


def _solve_block(S, b, feed, net, d, where) -> CellSolution:
    """Class by class: (S_i I - T^i) m_i = (1 - beta) u f_i + sum_{j<i} b_ij S_j m_j."""
    n_cls = S.size
    n = net.n
    feed = np.asarray(feed, dtype=float)
    cols = feed.shape[1:]  # () or (m,)
    offdiag, drain, exit_rate, g, h = cell_operators(net, d, where, n_cls)
    lower, upper = _bandwidths(np.asarray(net.flows))
    banded = lower + upper + 1 < n
    inlet = (1.0 - net.bypass) * np.asarray(net.inlet, dtype=float)
    # source[i] = (1 - beta) u f_i plus breakage inflow accumulated from coarser classes
    source = inlet[np.newaxis, :].reshape((1, n) + (1,) * len(cols)) * feed[:, np.newaxis]
    source = np.array(source, dtype=float)
    holdup = np.empty((n_cls, n) + cols)
    eye = np.eye(n)
    for i in range(n_cls):
        M = (S[i] * eye - g[i] * offdiag) + np.diag(g[i] * drain + h[i] * exit_rate)
        if banded:
            ab = np.zeros((lower + upper + 1, n))
            for k in range(-lower, upper + 1):  # k = col - row offset
                diag = np.diagonal(M, k)
                if k >= 0:
                    ab[upper - k, k:] = diag
                else:
                    ab[upper - k, : n + k] = diag
            m_i = scipy.linalg.solve_banded((lower, upper), ab, source[i], check_finite=False)
        else:
            m_i = scipy.linalg.solve(M, source[i], check_finite=False)
        holdup[i] = m_i
        if i + 1 < n_cls and S[i] > 0:
            w = b[i + 1:, i] * S[i]
            source[i + 1:] += w.reshape((-1,) + (1,) * (1 + len(cols))) * m_i[np.newaxis]
    out = np.tensordot(exit_rate, holdup, axes=([0], [1]))  # (N,) + cols
    hh = h.reshape((-1,) + (1,) * len(cols))
    product = hh * out + net.bypass * feed
    return CellSolution(product, np.moveaxis(holdup, 1, 0), "cells_block")


def solve_cells(S, b, feed, net, d=None, where: str = "discharge") -> CellSolution:
    """Steady product and hold-up of a cell network with breakage (module doc).

    Parameters
    ----------
    S : (N,) rates [1/s]; b : (N, N) fractional breakage distribution.
    feed : (N,) or (N, m) solids feed flows (any mass-rate unit; hold-up is per
        unit of it, in s).
    net : rtd.CompartmentNetwork (volumes in units of time x feed flow).
    d : (N,) normalised discharge rates d_i* or None.
    where : "discharge" (exit flows only) or "cells" (every cell outlet).
    """
    S = np.asarray(S, dtype=float)
    b = np.asarray(b, dtype=float)
    if is_chain(net) and (d is None or where in ("discharge", "cells")):
        return _solve_chain(S, b, feed, net, d, where)
    return _solve_block(S, b, feed, net, d, where)
