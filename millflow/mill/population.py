"""Steady products of a population of mills (parameter sets) at once, for every transport.

A fit, a Monte Carlo propagation or a sweep solves the same mill for thousands of rate
vectors S. :func:`steady_population` takes them as one (P, N) array and returns the
(P, N) products, by the cheapest exact route for the transport:

- ``rtd.PerfectMixing``: eq. 3 by forward substitution vectorised over the population
  (:func:`~millflow.mill.well_mixed.well_mixed_population`);
- ``rtd.TanksInSeries`` with integer n and no classification: n well-mixed cells of
  tau/n in turn, each the same vectorised triangular solve (the product of one cell is
  the next one's feed, exactly as :mod:`millflow.mill.cells` solves a chain), so the
  cost is n substitutions over the population, O(n N^2 P) in numpy;
- any other transport (plug flow, axial dispersion, recirculating cells, networks,
  series, classification on cells): :func:`~millflow.mill.steady.steady_mill`'s exact
  solver for each member in turn (the same numbers, at the single-mill cost).

Nothing is validated per member beyond shapes: rates must be finite and >= 0 (checked
once for the whole array). The products agree with :func:`steady_mill` to rounding.
"""
from __future__ import annotations

import numpy as np

from millflow.errors import InputError
from millflow.mill.well_mixed import well_mixed_population

__all__ = ["steady_population", "tanks_in_series_population"]


def tanks_in_series_population(S, b, feed, tau: float, n: int) -> np.ndarray:
    """Products (P, N) of n equal well-mixed tanks in series (mean residence time tau [s]
    in all, tau/n each) for rates S (P, N), breakage b (N, N) or (P, N, N), feed (N,) or
    (P, N): n vectorised triangular solves, each tank's product the next one's feed."""
    p = np.asarray(feed, dtype=float)
    for _ in range(int(n)):
        p = well_mixed_population(S, b, p, tau / n)
    return p


def steady_population(S, b, feed, transport, d=None, *, where=None) -> np.ndarray:
    """Steady products (P, N) of P mills that differ in their rates S (P, N).

    Parameters
    ----------
    S : (P, N) specific breakage rates [1/s] of the members, S_N = 0.
    b : (N, N) fractional breakage shared by the members, or (P, N, N) one each.
    feed : (N,) feed flows shared by the members, or (P, N).
    transport : an rtd model with tau in s (as for :func:`steady_mill`).
    d : (N,) or (P, N) normalised discharge rates d_i*, or None.
    where : where d acts, as for :func:`steady_mill`.

    Returns
    -------
    numpy.ndarray (P, N): the product flows of each member, in the feed's unit.
    """
    import rtd

    S = np.asarray(S, dtype=float)
    if S.ndim != 2 or S.shape[1] < 1:
        raise InputError(f"S has shape {S.shape}; expected (members, classes)")
    if not np.all(np.isfinite(S)) or np.any(S < 0):
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
    if isinstance(transport, rtd.PerfectMixing) and where in (None, "discharge", "cells"):
        return np.broadcast_to(well_mixed_population(S, b, f, transport.tau, d), (n_members, n)).copy()
    tis_n = getattr(transport, "n", None)
    if (isinstance(transport, rtd.TanksInSeries) and d is None and float(tis_n).is_integer()
            and where is None):
        return np.broadcast_to(tanks_in_series_population(S, b, f, transport.tau, int(tis_n)),
                               (n_members, n)).copy()
    from millflow.mill.steady import steady_mill

    out = np.empty((n_members, n))
    for k in range(n_members):
        out[k] = steady_mill(S[k], b if b.ndim == 2 else b[k], f if f.ndim == 1 else f[k], transport,
                             None if d is None else (d if d.ndim == 1 else d[k]), where=where)["product"].values
    return out
