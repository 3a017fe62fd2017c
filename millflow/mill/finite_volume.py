"""Finite volumes of axial dispersion: the grid and its exponentially fitted fluxes.

One class i moving along the axis at relative velocity v_i with dispersion D_i = w_i / Pe
(z = y/L, time in units of tau = L/u). Vertex-centred finite volumes: nodes z_k, faces
between neighbouring nodes at distance h_k = z_(k+1) - z_k, the control volume of a node
reaching half-way to each neighbour. The flux through the face between nodes k and k + 1
is fitted to the exponential solutions (Scharfetter-Gummel / Il'in-Allen-Southwell),

    F_(k+1/2) = (D/h) [B(-P) c_k - B(P) c_(k+1)] = alpha_k c_k - beta_k c_(k+1),
    P = v h / D (the cell Peclet number),   B(x) = x / (exp(x) - 1).

What is exact: for convection-dispersion without breakage, every solution c = A +
B exp(v z / D) of (v c - D c')' = 0 gives F_(k+1/2) = v A, its exact flux, on every face,
at any cell Peclet number and on non-uniform grids alike, so the node balances reproduce
it at the nodes to rounding. alpha > 0 and beta >= 0, so each class's matrix is a
column-diagonally dominant M-matrix (concentrations stay non-negative for every Pe), and
the fluxes cancel between neighbouring volumes, so mass is conserved exactly: the column
sums of the node balances are what leaves the system (:func:`tridiagonal`). Not exact:
the reactions (breakage) are lumped at the nodes (trapezoidal rule, O(h^2) while the cell
Peclet number is small, tending to first order where it is large). The closed vessel
(:mod:`millflow.mill.axial`) is [0, 1] in M uniform volumes; the open vessel
(:mod:`millflow.mill.axial_open`) is the whole line, the mill in M uniform volumes and a
stretched tail of M volumes on each side.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["AxialFaces", "bernoulli", "closed_faces", "open_faces", "open_nodes", "node_losses", "tridiagonal"]


@dataclass(frozen=True)
class AxialFaces:
    """Nodes, control volumes and exponentially fitted face coefficients of one grid.

    Attributes
    ----------
    z : (n,) ndarray
        Node positions [fraction of the mill length].
    h : (n - 1,) ndarray
        Distances z_(k+1) - z_k between neighbouring nodes [fraction of the mill length]
        (1/M on the closed grid).
    weights : (n,) ndarray
        Control volumes of the nodes [fraction of the mill length]; they sum to the length
        of the grid.
    upstream : (n,) ndarray
        Control volumes of the part of the line up to the discharge plane z = 1: the
        discharge node keeps its left half volume, nodes beyond it none (the closed vessel:
        ``weights``).
    cell_peclet : (N, n - 1) ndarray
        P = v_i h_k / D_i of each class and face [-].
    alpha, beta : (N, n - 1) ndarray
        The flux through the face between nodes k and k + 1 is alpha_ik c_ik - beta_ik
        c_i(k+1) [velocity, in units of u]. On the uniform closed grid these (and
        ``cell_peclet``) are read-only views of one value per class.
    inlet, outlet : int
        Nodes of the feed plane z = 0 and of the discharge plane z = 1.
    """

    z: np.ndarray
    h: np.ndarray
    weights: np.ndarray
    upstream: np.ndarray
    cell_peclet: np.ndarray
    alpha: np.ndarray
    beta: np.ndarray
    inlet: int
    outlet: int


def bernoulli(x) -> np.ndarray:
    """The Bernoulli function B(x) = x / (exp(x) - 1), without overflow or cancellation.

    Parameters
    ----------
    x : array_like
        Arguments [-].

    Returns
    -------
    ndarray
        B(x), with B(0) = 1: 1 - x/2 for |x| < 1e-8 and x exp(-x) above 700.
    """
    x = np.asarray(x, dtype=float)
    small = np.abs(x) < 1e-8
    big = x > 700.0
    if not (small.any() or big.any()):  # the usual case, without the masked copies
        return x / np.expm1(x)
    out = np.ones_like(x)
    mid = ~small & ~big
    out[mid] = x[mid] / np.expm1(x[mid])
    out[small] = 1.0 - 0.5 * x[small]
    out[big] = x[big] * np.exp(-x[big])
    return out


def _fitted(D, v, h):
    """Cell Peclet numbers P = v h / D and the face coefficients (D/h) B(-P), (D/h) B(P)."""
    P = v * h / D
    return P, D / h * bernoulli(-P), D / h * bernoulli(P)


def _repeated(column: np.ndarray, n_faces: int) -> np.ndarray:
    """A read-only (N, n_faces) view of one value per class: no copy, and cheaper than broadcast_to."""
    column = np.ascontiguousarray(column, dtype=float)
    view = np.ndarray((column.size, n_faces), float, column, strides=(column.itemsize, 0))
    view.flags.writeable = False
    return view


def closed_faces(pe: float, m_cells: int, v, w) -> AxialFaces:
    """The closed vessel [0, 1] in ``m_cells`` uniform volumes.

    Parameters
    ----------
    pe : float
        Peclet number u L / D [-].
    m_cells : int
        Number of volumes M: nodes z_k = k/M, k = 0..M, volumes 1/M (1/(2M) at the two
        ends).
    v, w : (N,) array_like
        Relative axial velocity and relative dispersion of each class [-].

    Returns
    -------
    AxialFaces
        Inlet node 0, outlet node M; the face coefficients are one value per class.
    """
    M = int(m_cells)
    h = 1.0 / M
    z = np.linspace(0.0, 1.0, M + 1)
    weights = np.full(M + 1, h)
    weights[[0, -1]] = 0.5 * h
    D = np.asarray(w, dtype=float) / pe
    P, alpha, beta = (_repeated(a, M) for a in _fitted(D, np.asarray(v, dtype=float), h))
    return AxialFaces(z, np.full(M, h), weights, weights, P, alpha, beta, 0, M)


def _tail(length: float, m: int) -> np.ndarray:
    """Node distances (m,) from the mill's end.

    Uniform 1/m up to ``length`` <= 1, else geometric with the first volume 1/m and the
    last node at ``length``.
    """
    if length <= 1.0:
        k = max(1, math.ceil(length * m - 1e-9))
        return np.arange(1, k + 1) / m
    # (e^beta - 1) / beta = length: first volume length beta / (m (e^beta - 1)) ~ 1/m
    from scipy import optimize  # here: scipy.optimize is a large share of start-up

    beta = optimize.brentq(lambda x: math.expm1(x) / x - length, 1e-9, 700.0, xtol=1e-14)
    j = np.arange(1, m + 1)
    return length * np.expm1(beta * j / m) / math.expm1(beta)


def open_nodes(tail: float, m_cells: int) -> tuple[np.ndarray, int, int]:
    """Nodes of the open vessel's whole line.

    Parameters
    ----------
    tail : float
        Length of each tail [fraction of the mill length].
    m_cells : int
        Volumes in the mill [0, 1] (uniform) and in each tail (uniform 1/M up to a tail
        of length 1, else stretched geometrically from a first volume of 1/M).

    Returns
    -------
    z : ndarray
        Nodes from -tail to 1 + tail.
    inlet, outlet : int
        Indices of z = 0 (feed) and z = 1 (discharge).
    """
    M = int(m_cells)
    side = _tail(tail, M)
    z = np.concatenate([-side[::-1], np.linspace(0.0, 1.0, M + 1), 1.0 + side])
    return z, side.size, side.size + M


def open_faces(pe: float, m_cells: int, v, w, tail: float) -> AxialFaces:
    """The open vessel's whole line: the mill in ``m_cells`` volumes and two tails.

    Parameters
    ----------
    pe : float
        Peclet number u L / D [-].
    m_cells : int
        Volumes in the mill and in each tail (:func:`open_nodes`).
    v, w : (N,) array_like
        Relative axial velocity and relative dispersion of each class [-].
    tail : float
        Length of each tail [fraction of the mill length].

    Returns
    -------
    AxialFaces
        Inlet the node of z = 0, outlet the node of z = 1; face coefficients per class
        and face (the widths vary along the tails).
    """
    z, inlet, outlet = open_nodes(tail, m_cells)
    h = np.diff(z)
    weights = np.zeros(z.size)
    weights[:-1] += 0.5 * h
    weights[1:] += 0.5 * h
    upstream = weights.copy()
    upstream[outlet] = 0.5 * h[outlet - 1]
    upstream[outlet + 1:] = 0.0
    D = (np.asarray(w, dtype=float) / pe)[:, np.newaxis]
    P, alpha, beta = _fitted(D, np.asarray(v, dtype=float)[:, np.newaxis], h[np.newaxis, :])
    return AxialFaces(z, h, weights, upstream, P, alpha, beta, inlet, outlet)


def node_losses(faces: AxialFaces, v, rates=None) -> np.ndarray:
    """What leaves each class at each node per unit concentration: the column sums.

    Parameters
    ----------
    faces : AxialFaces
        The grid.
    v : (N,) array_like
        Relative axial velocities: the outflow v_i c_i at the downstream end of the grid
        (its last node) [-].
    rates : (N,) array_like, optional
        Loss rates in units of 1/tau (tau S_i for breakage) [-], acting on each control
        volume; None: none.

    Returns
    -------
    (N, n) ndarray
        rates_i w_k, plus v_i at the last node.
    """
    n_cls = np.size(v)
    if rates is None:
        loss = np.zeros((n_cls, faces.z.size))
    else:
        loss = np.asarray(rates, dtype=float)[:, np.newaxis] * faces.weights[np.newaxis, :]
    loss[:, -1] += v
    return loss


def tridiagonal(faces: AxialFaces, loss: np.ndarray, *, overwrite_loss: bool = False):
    """Each class's tridiagonal M-matrix A of the node balances, with column sums ``loss``.

    (A c)_k = F_(k+1/2) - F_(k-1/2) + loss_k c_k: what leaves the control volume of node k
    (no flux through the grid's two ends). The fluxes cancel between volumes, so column k
    of A sums to loss_k (mass conservation).

    Parameters
    ----------
    faces : AxialFaces
        The grid and its face coefficients.
    loss : (N, n) ndarray
        Column sums, e.g. :func:`node_losses` [velocity, in units of u].
    overwrite_loss : bool
        Build ``diag`` in the memory of ``loss`` (one (N, n) array less where ``loss`` is
        not needed afterwards).

    Returns
    -------
    lower : (N, n - 1) ndarray
        A[k + 1, k] = -alpha_k (read-only views of one value per class where ``faces``
        has them).
    diag : (N, n) ndarray
        A[k, k] = loss_k + alpha_k (k < n - 1) + beta_(k-1) (k > 0).
    upper : (N, n - 1) ndarray
        A[k, k + 1] = -beta_k (as ``lower``).
    """
    diag = loss if overwrite_loss else np.array(loss, dtype=float)
    diag[:, :-1] += faces.alpha
    diag[:, 1:] += faces.beta
    return _negative(faces.alpha), diag, _negative(faces.beta)


def _negative(a: np.ndarray) -> np.ndarray:
    """-a; a view of one value per class stays one (no (N, n - 1) array on the hot path)."""
    if a.shape[1] and a.strides[1] == 0:
        return _repeated(-a[:, 0], a.shape[1])
    return -a
