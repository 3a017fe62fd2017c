"""Steady products of a population of mills (parameter sets) at once, for every transport.

A fit, a Monte Carlo propagation or a sweep solves the same mill for thousands of rate
vectors S. :func:`steady_population` takes them as one (P, N) array and returns the
(P, N) products, each the product :func:`~millflow.mill.steady.steady_mill` gives (to
rounding), by the cheapest exact route for the transport, vectorised over the members:

- ``rtd.PerfectMixing`` (classification d at the discharge or the cell outlet) and
  ``rtd.TanksInSeries`` with integer n and no classification: n well-mixed cells of
  tau/n in turn, eq. 3 by forward substitution, p_i = (p^prev_i + sum_{j<i} b_ij s_j
  p_j) / (1 + s_i) with s = tau S / (n d*). With a shared b the compiled kernel
  (``population_chains`` of millflow/_cells.c) runs all cells of a class in one pass
  over blocks of 8 members (b's row read once for the block); else numpy
  (:func:`~millflow.mill.well_mixed.well_mixed_population`) vectorised over the members;
- compartment networks (tanks in series with classification, ``rtd.RecirculatingCells``,
  any ``rtd.CompartmentNetwork``): the class-by-class block solve of
  :func:`~millflow.mill.cells.solve_cells_population`, every member at once;
- transports solved by segregated flow (plug flow, with classification along its axis
  as rates S/d*; axial dispersion, closed or open vessel, without classification; tanks
  in series with non-integer n; any other ``rtd`` model; series and parallel
  compositions): product = X diag(E_hat(S)) X^-1 f, X the unit lower-triangular
  eigenvectors of (I - b) diag(S) (:func:`millflow.linalg.eigenvectors_distinct_population`:
  the compiled row recurrence member by member), E_hat the transport's Laplace
  transform (exp(-s tau) for plug flow). Members with two rates within 1e-3 of each
  other, or whose cancellation estimate eps |X| |X^-1 f| exceeds 1e-13, are solved by
  ``steady_mill`` (its clustered eigenbasis, or finite volumes for axial dispersion);
- anything else (axial dispersion with classification or size-dependent dispersion,
  cells named by number, b per member with a network): ``steady_mill`` member by member.

Nothing is validated per member beyond shapes: rates must be finite and >= 0 (checked
once for the whole array).
"""
from __future__ import annotations

import numpy as np

from millflow.errors import InputError
from millflow.mill.well_mixed import well_mixed_population

__all__ = ["steady_population", "tanks_in_series_population"]

#: Rates closer than this (relative) send a member to steady_mill's clustered eigenbasis.
CLUSTER_GAP = 1e-3
#: Largest cancellation estimate eps |X| |X^-1 f| (relative to the feed) of the plain
#: eigenbasis; above it steady_mill takes the member (SpectralBlocks' own target).
CANCELLATION_TARGET = 1e-13


def tanks_in_series_population(S, b, feed, tau: float, n: int, *, kernel: str | None = None) -> np.ndarray:
    """Products (P, N) of n equal well-mixed tanks in series (mean residence time tau [s]
    in all, tau/n each) for rates S (P, N), breakage b (N, N) or (P, N, N), feed (N,) or
    (P, N): each tank's product the next one's feed (``kernel`` as
    :func:`millflow.compiled.kernel`)."""
    S = np.atleast_2d(np.asarray(S, dtype=float))
    return _chains(S, float(tau) / int(n), np.asarray(b, dtype=float), np.asarray(feed, dtype=float), int(n),
                   kernel)


def _chains(s, scale: float, b, f, n: int, kernel=None) -> np.ndarray:
    """n cells of eq. 3 in turn with rates scale * s (P, N) (tau/n S/d*)."""
    from millflow import compiled

    P, N = s.shape
    module = compiled.kernel("cells", kernel)
    if module is not None and b.ndim == 2:
        f2 = np.ascontiguousarray(f if f.ndim == 2 else f[np.newaxis])
        out = np.empty((P, N))
        module.population_chains(np.ascontiguousarray(s), float(scale), np.ascontiguousarray(b), f2, out, P, N, n,
                                 f2.shape[0])
        return out
    p = f
    for _ in range(n):
        p = well_mixed_population(s, b, p, scale)
    return np.broadcast_to(p, (P, N)).copy()


def steady_population(S, b, feed, transport, d=None, *, where=None, kernel: str | None = None) -> np.ndarray:
    """Steady products (P, N) of P mills that differ in their rates S (P, N).

    Parameters
    ----------
    S : (P, N) specific breakage rates [1/s] of the members, S_N = 0.
    b : (N, N) fractional breakage shared by the members, or (P, N, N) one each.
    feed : (N,) feed flows shared by the members, or (P, N).
    transport : an rtd model with tau in s (as for :func:`steady_mill`).
    d : (N,) or (P, N) normalised discharge rates d_i*, or None.
    where : where d acts, as for :func:`steady_mill`.
    kernel : None (the environment's choice), "compiled" or "numpy"
        (:func:`millflow.compiled.kernel`), for the cell chains and the eigenvectors.

    Returns
    -------
    numpy.ndarray (P, N): the product flows of each member, in the feed's unit.

    Examples
    --------
    >>> import numpy as np, rtd
    >>> S = np.array([[1.0, 0.0], [2.0, 0.0]])
    >>> p = steady_population(S, [[0, 0], [1, 0]], [1.0, 0.0], rtd.PerfectMixing(1.0))
    >>> np.round(p[:, 0], 6).tolist()  # 1 / (1 + tau S)
    [0.5, 0.333333]
    """
    import rtd

    from millflow.mill.cells import network_of
    from millflow.mill.scene import _kind

    S = np.asarray(S, dtype=float)
    if S.ndim != 2 or S.shape[1] < 1:
        raise InputError(f"S has shape {S.shape}; expected (members, classes)")
    if S.size and not (S.min() >= 0 and S.max() < np.inf):  # two passes without temporaries; NaN fails
        raise InputError("S: expected finite rates >= 0 [1/s] for every member")
    n_members, n = S.shape
    b = np.asarray(b, dtype=float)
    f = np.asarray(feed, dtype=float)
    if b.shape not in ((n, n), (n_members, n, n)):
        raise InputError(f"b has shape {b.shape}; expected ({n}, {n}) or ({n_members}, {n}, {n})")
    if f.shape not in ((n,), (n_members, n)):
        raise InputError(f"feed has shape {f.shape}; expected ({n},) or ({n_members}, {n})")
    if d is not None:
        d = np.asarray(d, dtype=float)
        if d.shape not in ((n,), (n_members, n)):
            raise InputError(f"d has shape {d.shape}; expected ({n},) or ({n_members}, {n})")
    kind = _kind(transport)
    if kind == "perfect_mixing" and where in (None, "discharge", "cells"):
        return _chains(S if d is None else S / d, float(transport.tau), b, f, 1, kernel)
    tis_n = getattr(transport, "n", None)
    if (isinstance(transport, rtd.TanksInSeries) and d is None and where is None
            and float(tis_n).is_integer()):
        return tanks_in_series_population(S, b, f, transport.tau, int(tis_n), kernel=kernel)
    if kind == "network" and where in (None, "discharge", "cells"):
        from millflow.mill.cells import solve_cells_population

        nets = np.empty(n_members, dtype=object)
        nets[:] = [network_of(transport)] * n_members
        return solve_cells_population(S, b, f, nets, d, where or "discharge")[0]
    if kind == "plug" and where in (None, "axis"):
        return _segregated(S if d is None else S / d, b, f, transport, kernel,
                           lambda k: _member(S, b, f, transport, d, where, k))
    if kind in ("rtd", "series", "parallel", "axial", "axial_open") and d is None and where is None:
        return _segregated(S, b, f, transport, kernel, lambda k: _member(S, b, f, transport, d, where, k))
    return np.array([_member(S, b, f, transport, d, where, k) for k in range(n_members)]).reshape(n_members, n)


def _member(S, b, f, transport, d, where, k: int) -> np.ndarray:
    """Member k by :func:`steady_mill` (its exact method for the scene)."""
    from millflow.mill.steady import steady_mill

    return steady_mill(S[k], b if b.ndim == 2 else b[k], f if f.ndim == 1 else f[k], transport,
                       None if d is None else (d if d.ndim == 1 else d[k]), where=where)["product"].values


def _segregated(rates, b, f, transport, kernel, member) -> np.ndarray:
    """Segregated flow, product = X diag(E_hat(rates)) X^-1 f, for every member; the
    members the plain eigenbasis does not serve exactly by ``member(k)``."""
    from millflow import compiled

    P, N = rates.shape
    out = np.empty((P, N))
    s_sorted = np.sort(rates, axis=1)
    close = (np.diff(s_sorted, axis=1) <= CLUSTER_GAP * s_sorted[:, 1:]).any(axis=1)
    fast = np.flatnonzero(~close)
    slow = [int(k) for k in np.flatnonzero(close)]
    F = np.broadcast_to(f, (P, N))
    E = np.asarray(transport.laplace(rates[fast]), dtype=float)
    module = compiled.kernel("eigenbasis", kernel)
    if module is None:  # numpy: the recurrence vectorised over the members
        X, w = _eigen_numpy(rates[fast], b if b.ndim == 2 else b[fast], F[fast])
        members = ((X[k], w[k]) for k in range(fast.size))
    else:  # compiled: member by member, every array of a member in cache (N = 100: 80 kB)
        members = _eigen_compiled(module, rates, b, F, fast)
    eps = np.finfo(float).eps
    with np.errstate(invalid="ignore", over="ignore"):
        for k, (Xk, wk), Ek in zip(fast, members, E):
            scale = float(np.abs(F[k]).sum())
            cancel = eps * float((np.abs(Xk) @ np.abs(wk)).max()) / max(scale, 1e-300)
            if not cancel <= CANCELLATION_TARGET:  # NaN too
                slow.append(int(k))
                continue
            prod = Xk @ (Ek * wk)
            # as steady_mill's segregated path (on the feed scaled to a unit total): values of
            # true value ~0 rounded below zero by at most the error estimate are 0
            err = scale * (4.0 * cancel + 8 * eps)
            out[k] = np.where((prod < 0) & (prod >= -err), 0.0, prod)
    for k in sorted(slow):
        out[k] = member(k)
    return out


def _eigen_compiled(module, rates, b, F, fast):
    """(X, X^-1 f) of each member in ``fast``, by the compiled row recurrence."""
    from scipy.linalg.lapack import dtrtrs

    N = rates.shape[1]
    A = np.empty((N, N))
    diag = np.arange(N)
    for k in fast:
        np.multiply(b if b.ndim == 2 else b[k], -rates[k], out=A)
        A[diag, diag] = rates[k]  # A = (I - b) diag(S) = -K
        X = np.eye(N)
        module.distinct(A, np.ascontiguousarray(rates[k]), X)
        yield X, dtrtrs(X, F[k], lower=1, unitdiag=1)[0]


def _eigen_numpy(rates, b, F):
    """(X, X^-1 f) of every member at once (the numpy recurrence; the reference)."""
    from millflow.linalg import eigenvectors_distinct_population

    P, N = rates.shape
    A = np.broadcast_to(b, (P, N, N)) * -rates[:, np.newaxis, :]
    A[:, np.arange(N), np.arange(N)] = rates
    X = eigenvectors_distinct_population(A, rates, "numpy")
    return X, _unit_lower_solve(X, F)


def _unit_lower_solve(X, f) -> np.ndarray:
    """w = X^-1 f for unit lower-triangular X (P, N, N), f (P, N): forward substitution,
    row i of every member at once."""
    P, N = f.shape
    w = np.empty((P, N))
    w[:, 0] = f[:, 0]
    for i in range(1, N):
        w[:, i] = f[:, i] - np.einsum("pj,pj->p", X[:, i, :i], w[:, :i])
    return w
