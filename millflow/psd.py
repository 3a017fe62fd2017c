"""Particle size distributions on a :class:`~millflow.grid.SizeGrid`, and moving them.

A PSD is held as mass fractions per class (coarse -> fine, the sink last, summing to
1) or, equivalently, as cumulative passing P(x_i) at the upper class edges x_i [m]
(Austin's convention: P(x_i) is the mass in classes i..N, so P(x_1) = 1).
This module converts between the two, computes percentile sizes (P80, P50), reduces a
fine numerical grid to measured sieve sizes and puts a measured sieve PSD onto a fine
grid (Principle IV). Between known edges, cumulative passing is interpolated with
scipy's PCHIP (:class:`scipy.interpolate.PchipInterpolator`) in log size: it passes
through the data and, unlike a cubic spline, never overshoots, so the interpolated P
stays monotone and inside [0, 1] and no class ever receives negative mass. Edges that
coincide with known edges (relative difference < 1e-9) take the known value exactly.
Every transfer builds the new fractions as differences of one cumulative curve that
starts at 1, so the total mass is conserved; the rounding residual (a few ulp) is
put in the largest class so that the sum is 1 to 1e-14.
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np

from millflow.errors import GridError
from millflow.grid import SizeGrid, as_sizes, class_label, validate_edges

__all__ = [
    "validate_fractions",
    "cum_passing",
    "cum_retained",
    "retained",
    "percentile_size",
    "percentile_from_cum",
    "percentile_sizes",
    "p80",
    "p50",
    "regrid",
    "from_sieves",
    "cum_passing_at",
    "rosin_rammler",
    "gates_gaudin_schuhmann",
    "from_distribution",
    "TAIL_RULES",
    "TailFit",
    "fit_tail",
]

# Tolerance on sum(fractions) = 1 and P(x_1) = 1: beyond this the input is wrong, not
# rounded (measured PSDs typed with 4 digits sum to 1 within ~1e-4 and must be
# normalised explicitly with normalize=True).
SUM_TOL = 1e-9
# Relative size difference under which a target edge counts as a known edge.
_MATCH_RTOL = 1e-9


# --------------------------------------------------------------------- validation
def validate_fractions(frac, grid=None, *, normalize: bool = False, name: str = "frac") -> np.ndarray:
    """Check mass fractions per class and return them as a float array.

    Parameters
    ----------
    frac : array_like
        Mass fractions [-], coarse -> fine, the sink last.
    grid : SizeGrid or array_like, optional
        If given, the length must be N and error messages show the class sizes.
    normalize : bool
        If True, fractions whose sum differs from 1 are divided by their sum and a
        ``UserWarning`` states the sum; otherwise such input raises.
    name : str
        Argument name for messages.

    Raises
    ------
    GridError
        On NaN/inf, negative fractions (naming the class), a wrong length, or a sum
        differing from 1 by more than 1e-9 (naming the sum).
    """
    f = np.array(frac, dtype=float)
    x = None if grid is None else as_sizes(grid)
    if f.ndim != 1 or f.size < 1:
        raise GridError(f"{name}: expected a 1-D array of mass fractions, got shape {f.shape}")
    if x is not None and f.size != x.size:
        raise GridError(f"{name}: {f.size} fractions for a grid of {x.size} classes")
    bad = np.flatnonzero(~np.isfinite(f))
    if bad.size:
        raise GridError(f"{name}: {class_label(bad[0], x)} has fraction {float(f[bad[0]])!r}; expected a finite value")
    bad = np.flatnonzero(f < 0)
    if bad.size:
        raise GridError(f"{name}: {class_label(bad[0], x)} has fraction {float(f[bad[0]])!r}; expected >= 0")
    total = math.fsum(f)
    if abs(total - 1.0) > SUM_TOL:
        if not normalize:
            raise GridError(
                f"{name}: mass fractions sum to {total!r}, expected 1 (tolerance {SUM_TOL:g}); "
                "pass normalize=True to rescale them explicitly"
            )
        if total <= 0:
            raise GridError(f"{name}: mass fractions sum to {total!r}; cannot normalise")
        warnings.warn(f"{name}: mass fractions summed to {total!r}; divided by the sum (normalize=True)",
                      UserWarning, stacklevel=2)
        f = f / total
        f = _fix_sum(f)
    return f


def _validate_cum(cum, x=None, name: str = "cum") -> np.ndarray:
    """Cumulative passing at upper edges coarse -> fine: finite, in [0, 1], non-increasing."""
    P = np.array(cum, dtype=float)
    if P.ndim != 1 or P.size < 1:
        raise GridError(f"{name}: expected a 1-D array of cumulative passing, got shape {P.shape}")
    if x is not None and P.size != x.size:
        raise GridError(f"{name}: {P.size} values for {x.size} sizes")
    bad = np.flatnonzero(~np.isfinite(P))
    if bad.size:
        raise GridError(f"{name}: value at {class_label(bad[0], x)} is {float(P[bad[0]])!r}; expected finite")
    bad = np.flatnonzero((P < 0) | (P > 1 + SUM_TOL))
    if bad.size:
        k = bad[0]
        hint = " (give fractions, not percent)" if P[k] > 1.5 else ""
        raise GridError(f"{name}: value at {class_label(k, x)} is {float(P[k])!r}; expected 0 <= P <= 1{hint}")
    bad = np.flatnonzero(np.diff(P) > 0)
    if bad.size:
        k = bad[0] + 1
        raise GridError(
            f"{name}: cumulative passing rises from {float(P[k - 1])!r} to {float(P[k])!r} at {class_label(k, x)}; "
            "it must not increase from coarse to fine sizes"
        )
    return np.minimum(P, 1.0)


def _fix_sum(f: np.ndarray) -> np.ndarray:
    """Put the rounding residual 1 - sum(f) (a few ulp) into the largest class."""
    k = int(np.argmax(f))
    f[k] += 1.0 - math.fsum(f)
    return f


# ---------------------------------------------------------- cumulative <-> fractions
def cum_passing(frac) -> np.ndarray:
    """Cumulative passing P(x_i) [-] at the upper edges: the mass in classes i..N.

    ``cum_passing(frac)[0]`` is the total mass (1 for a valid PSD). No validation,
    so it also serves for mass flows per class [kg/s].
    """
    f = np.asarray(frac, dtype=float)
    return np.cumsum(f[::-1])[::-1]


def cum_retained(frac) -> np.ndarray:
    """Cumulative retained [-] at the lower edge of each class: the mass in classes 1..i."""
    return np.cumsum(np.asarray(frac, dtype=float))


def retained(cum, *, name: str = "cum") -> np.ndarray:
    """Mass fractions per class from cumulative passing at the upper edges.

    frac_i = P(x_i) - P(x_{i+1}) for i < N and frac_N = P(x_N) (the sink).

    Parameters
    ----------
    cum : array_like
        Cumulative passing [-] at the upper edges, coarse -> fine, with P(x_1) = 1
        (to 1e-9; the top edge must pass everything, else the mass above it has no
        class), non-increasing, within [0, 1].

    Raises
    ------
    GridError
        For NaN, values outside [0, 1], a rise from coarse to fine, or P(x_1) != 1.
    """
    P = _validate_cum(cum, name=name)
    if abs(P[0] - 1.0) > SUM_TOL:
        raise GridError(f"{name}: cumulative passing at the top edge is {float(P[0])!r}; expected 1 (100 % passing)")
    P = P.copy()
    P[0] = 1.0
    return _fix_sum(np.append(P[:-1] - P[1:], P[-1]))


# --------------------------------------------------------------- interpolation core
def _pchip_slopes(u: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Node slopes dy/du of scipy's ``PchipInterpolator`` for u increasing.

    Fritsch and Butland's weighted harmonic mean inside, zero at a local extremum or flat
    secant; the shape-preserving three-point formula at the two ends (Moler, Numerical
    Computing with MATLAB, 3.6). Computed here, with the Hermite form below, so that a
    PSD's percentiles and passing values need no interpolant object and no scalar root finder.
    """
    h = np.diff(u)
    m = np.diff(y) / h
    d = np.empty_like(y)
    if y.size == 2:
        d[:] = m[0]
        return d
    # harmonic-mean slopes overflow to inf for subnormal secants, giving derivative 0:
    # the right (monotone) answer, as in scipy
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        flat = (np.sign(m[1:]) != np.sign(m[:-1])) | (m[1:] == 0) | (m[:-1] == 0)
        w1, w2 = 2 * h[1:] + h[:-1], h[1:] + 2 * h[:-1]
        d[1:-1] = np.where(flat, 0.0, 1.0 / ((w1 / m[:-1] + w2 / m[1:]) / (w1 + w2)))
    d[0] = _pchip_edge(h[0], h[1], m[0], m[1])
    d[-1] = _pchip_edge(h[-1], h[-2], m[-1], m[-2])
    return d


def _pchip_edge(h0, h1, m0, m1) -> float:
    d = ((2 * h0 + h1) * m0 - h0 * m1) / (h0 + h1)
    if np.sign(d) != np.sign(m0):
        return 0.0
    if np.sign(m0) != np.sign(m1) and abs(d) > 3 * abs(m0):
        return 3 * m0
    return d


def _hermite(t, h, y0, y1, d0, d1):
    """Cubic Hermite on an interval of width h at fraction t in [0, 1]: value and d/dt."""
    t2 = t * t
    t3 = t2 * t
    val = (2 * t3 - 3 * t2 + 1) * y0 + (t3 - 2 * t2 + t) * h * d0 + (3 * t2 - 2 * t3) * y1 + (t3 - t2) * h * d1
    der = (6 * t2 - 6 * t) * (y0 - y1) + (3 * t2 - 4 * t + 1) * h * d0 + (3 * t2 - 2 * t) * h * d1
    return val, der


class _LogPchip:
    """PCHIP of P against ln x from data ordered coarse -> fine.

    Scipy's interpolant, evaluated in Hermite form; values agree with
    ``PchipInterpolator`` to rounding.
    """

    def __init__(self, x_desc: np.ndarray, P_desc: np.ndarray):
        self.u = np.log(x_desc[::-1])
        self.y = np.asarray(P_desc[::-1], dtype=float)
        self.d = _pchip_slopes(self.u, self.y)

    def __call__(self, u_new: np.ndarray) -> np.ndarray:
        k = np.clip(np.searchsorted(self.u, u_new, side="right") - 1, 0, self.u.size - 2)
        h = self.u[k + 1] - self.u[k]
        val, _ = _hermite((u_new - self.u[k]) / h, h, self.y[k], self.y[k + 1], self.d[k], self.d[k + 1])
        return val


def _pchip_logx(x_desc: np.ndarray, P_desc: np.ndarray) -> _LogPchip:
    """Monotone interpolant of P against ln x from data ordered coarse -> fine."""
    return _LogPchip(x_desc, P_desc)


def _eval_cum(x_known, P_known, x_new) -> np.ndarray:
    """P at x_new from known (x, P) coarse -> fine; flat outside the known range.

    Above the coarsest known size P keeps its value there (1 for a complete PSD);
    below the finest known size P keeps its value there: mass finer than the finest
    known size is not spread, it stays together in the finest class (the sink).
    Exact at sizes that match a known size (relative difference < 1e-9).
    """
    x_new = np.asarray(x_new, dtype=float)
    out = np.empty_like(x_new)
    above = x_new >= x_known[0]
    below = x_new <= x_known[-1]
    out[above] = P_known[0]
    out[below] = P_known[-1]
    inside = ~(above | below)
    if np.any(inside):
        f = _pchip_logx(x_known, P_known)  # inside is empty for a single size
        out[inside] = f(np.log(x_new[inside]))
    # known edges: take the data value, not the interpolant's rounding
    idx = np.searchsorted(-x_known, -x_new)  # x_known is decreasing
    for off in (0, -1):
        j = np.clip(idx + off, 0, x_known.size - 1)
        hit = np.abs(x_known[j] - x_new) <= _MATCH_RTOL * x_known[j]
        out[hit] = P_known[j[hit]]
    # PCHIP is monotone and bounded in exact arithmetic; clip rounding only
    out = np.clip(out, 0.0, 1.0)
    return np.minimum.accumulate(out)  # non-increasing coarse -> fine, as new sizes are


def cum_passing_at(grid, frac, sizes_m) -> np.ndarray:
    """Cumulative passing [-] of a PSD on ``grid`` at arbitrary sizes [m] (decreasing).

    Uses the module's monotone interpolation (PCHIP in ln x); P = 1 above the top
    edge; below the sink's upper edge x_N the value P(x_N) is returned (the grid says
    nothing about how the sink's mass is spread).
    """
    x = as_sizes(grid)
    f = validate_fractions(frac, x)
    s = np.atleast_1d(np.asarray(sizes_m, dtype=float))
    P = cum_passing(f)
    P[0] = 1.0
    order = np.argsort(-s, kind="stable")
    out = np.empty_like(s)
    out[order] = _eval_cum(x, P, s[order])
    return out


def _fractions_from_cum(P_new: np.ndarray) -> np.ndarray:
    f = np.append(P_new[:-1] - P_new[1:], P_new[-1])
    return _fix_sum(np.maximum(f, 0.0))


# ---------------------------------------------------------------- public transfers
def regrid(frac, from_grid, to_grid, *, lump_top: bool = False) -> np.ndarray:
    """Move a PSD from one grid to another, conserving mass.

    P is evaluated at the target edges: exactly where they coincide with source edges
    (so the reduction of a fine numerical grid to sieve sizes that are a subset of
    its edges, e.g. from :meth:`SizeGrid.refine`, is exact), otherwise by PCHIP in
    ln x. Target classes below the source sink edge x_N receive nothing: the source
    sink's mass goes to the target sink.

    Parameters
    ----------
    frac : array_like
        Mass fractions on ``from_grid`` [-], summing to 1.
    from_grid, to_grid : SizeGrid or array_like of upper edges [m]
    lump_top : bool
        Mass coarser than the target's top edge has no target class. By default that
        is an error (beyond 1e-12); with ``lump_top=True`` it is added to target class
        1 and a ``UserWarning`` states how much.

    Returns
    -------
    numpy.ndarray
        Mass fractions on ``to_grid``, >= 0, summing to 1 to within 1e-14.
    """
    xs = as_sizes(from_grid)
    xt = as_sizes(to_grid)
    f = validate_fractions(frac, xs)
    P = cum_passing(f)
    P[0] = 1.0
    P_new = _eval_cum(xs, P, xt)
    _handle_top(P_new, xt, lump_top, "regrid")
    return _fractions_from_cum(P_new)


def from_sieves(size_m, cum_passing_frac, grid, *, oversize: str = "error", tail: str | None = None,
                tail_points: int = 3) -> np.ndarray:
    """Put a measured sieve PSD onto a (usually finer) grid, conserving mass.

    Cumulative passing is interpolated between the sieves by PCHIP in ln x (monotone,
    no overshoot); grid edges equal to a sieve size take the measured value exactly.
    The mass finer than the smallest sieve goes to the grid's sink (it is not spread
    over finer grid classes, about which the data say nothing). Above the top sieve
    P keeps the top sieve's value.

    Parameters
    ----------
    size_m : array_like
        Sieve sizes [m], strictly decreasing (coarse -> fine), at least 2.
    cum_passing_frac : array_like
        Cumulative passing at each sieve, as a fraction in [0, 1] (not percent),
        non-increasing from coarse to fine.
    grid : SizeGrid or array_like
        Target grid.
    oversize : {"error", "lump"}
        What to do when the grid's top edge does not pass 100 % (the top sieve
        retains material, or the grid top is below it): "error" raises (beyond
        1e-9); "lump" adds the oversize mass to class 1 and warns how much.
    tail : None, "rosin_rammler" or "gates_gaudin_schuhmann"
        Below the finest sieve: None keeps the default (the mass finer than the
        finest sieve goes to the sink); a rule extrapolates cumulative passing to
        the finer grid edges with that form fitted to the ``tail_points`` finest
        sieves (:func:`fit_tail`), scaled to pass through the finest sieve's value.

    Returns
    -------
    numpy.ndarray
        Mass fractions on ``grid``, summing to 1 to within 1e-14.
    """
    s = validate_edges(size_m, name="size_m")
    if s.size < 2:
        raise GridError(f"size_m: expected at least 2 sieve sizes [m] in a 1-D array, got {size_m!r}")
    P = _validate_cum(cum_passing_frac, s, name="cum_passing_frac")
    if oversize not in ("error", "lump"):
        raise GridError(f"oversize = {oversize!r}: expected 'error' or 'lump'")
    x = as_sizes(grid)
    P_new = _eval_cum(s, P, x)
    if tail is not None:
        fitted = fit_tail(s, P, tail, tail_points)
        below = x < s[-1] * (1 - _MATCH_RTOL)
        if below.any():
            # continuous at the finest sieve; never above it (the tail decreases)
            P_new[below] = np.minimum(P[-1], fitted.passing(x[below]) * (P[-1] / fitted.passing(s[-1:])[0]))
    _handle_top(P_new, x, oversize == "lump", "from_sieves", tol=SUM_TOL)
    return _fractions_from_cum(P_new)


def _handle_top(P_new, x, lump: bool, where: str, tol: float = 1e-12) -> None:
    over = 1.0 - P_new[0]
    if over > tol and not lump:
        raise GridError(
            f"{where}: mass fraction {over:.6g} is coarser than the top edge {x[0]:.6g} m "
            f"(cumulative passing there is {float(P_new[0])!r}, expected 1); use a coarser grid "
            "or lump it into class 1 explicitly"
        )
    if over > tol:
        warnings.warn(f"{where}: mass fraction {over:.6g} coarser than {x[0]:.6g} m was added to class 1",
                      UserWarning, stacklevel=3)
    P_new[0] = 1.0


# ---------------------------------------------------------------------- percentiles
def percentile_size(grid, frac, percent: float, *, validate: bool = True) -> float:
    """Size [m] at which ``percent`` % of the mass passes (P80: percent = 80).

    Cumulative passing is known at the upper edges; between the two edges that bracket
    the crossing it is interpolated by the cubic in ln x through those and their two
    neighbours (error O(h^4) in the class width h; at ratio 2^(1/4) ~1e-6 relative for
    Rosin-Rammler and Gates-Gaudin-Schuhmann PSDs, against ~1e-4 for PCHIP, whose
    derivative estimates are first order). Where that cubic is not monotone on the
    interval, or the crossing is in the first or last class, P is interpolated by PCHIP in
    ln x (monotone; as :func:`from_sieves`). The crossing is solved on the one bracketing
    interval (:func:`percentile_sizes`).

    Parameters
    ----------
    grid : SizeGrid or array_like
        The size grid, or its upper edges x [m] (coarse -> fine).
    frac : array_like
        Mass fractions per class [-], coarse -> fine, the sink last; summing to 1.
    percent : float
        Percent passing, 0 < percent <= 100 [%].
    validate : bool, optional
        Check ``grid`` and ``frac`` (default). ``False`` is for loops over the library's
        own results, which are valid by construction: invalid input is then not caught.

    Returns
    -------
    float
        The size [m].

    Raises
    ------
    GridError
        If ``percent`` is not in (0, 100], or the percentile lies inside the sink
        (P(x_N) >= percent/100: the grid has no information below x_N; extend the grid
        to finer sizes); with ``validate``, on invalid sizes or fractions.

    Examples
    --------
    >>> from millflow.grid import SizeGrid
    >>> grid = SizeGrid.geometric(1e-3, 2.0, 4)          # edges 1, 0.5, 0.25, 0.125 mm
    >>> frac = [0.2, 0.3, 0.3, 0.2]                      # passing 1, 0.8, 0.5, 0.2 at the edges
    >>> percentile_size(grid, frac, 80), percentile_size(grid, frac, 50)
    (0.0005, 0.00025)
    """
    return float(percentile_sizes(grid, frac, [percent], validate=validate)[0])


def percentile_sizes(grid, frac, percents, *, validate: bool = True) -> np.ndarray:
    """Sizes [m] at which each of ``percents`` % of the mass passes, in one pass.

    The reading of :func:`percentile_size` for several percentiles at once. Each crossing
    is solved on its bracketing interval by Newton's method on the interval's cubic (the
    local cubic, or PCHIP's cubic Hermite with scipy's node slopes), safeguarded by
    bisection (the cubic is monotone there), to a step of ~2e-15 in ln x or a residual
    at rounding level.
    """
    if validate:
        x = as_sizes(grid)
        f = validate_fractions(frac, x)
    else:
        x = grid.upper_m if isinstance(grid, SizeGrid) else np.asarray(grid, dtype=float)
        f = np.asarray(frac, dtype=float)
    pct = np.atleast_1d(np.asarray(percents, dtype=float))
    for p in np.atleast_1d(np.asarray(percents)).tolist():  # plain numbers in the message
        if not (isinstance(p, (int, float)) and math.isfinite(p) and 0 < p <= 100):
            raise GridError(f"percent = {p!r}: expected 0 < percent <= 100")
    P = cum_passing(f)
    P[0] = 1.0
    return _percentiles_of_cum(x, P, pct)


def percentile_from_cum(x: np.ndarray, P: np.ndarray, q: float) -> float:
    """Size [m] where cumulative passing ``P`` reaches the fraction ``q``.

    ``P`` at the upper edges ``x`` (coarse -> fine, P[0] = 1, P[-1] < q): the reading of
    :func:`percentile_size` without validation, for loops that have checked their input.
    """
    return float(_percentiles_of_cum(np.asarray(x, float), np.asarray(P, float), np.array([100.0 * q]))[0])


def _percentiles_of_cum(x, P, pct) -> np.ndarray:
    q = pct / 100.0
    if P[-1] >= q.min():
        bad = float(pct[np.argmin(q)])
        raise GridError(
            f"P{bad:g} lies below the grid: {P[-1]:.6g} of the mass passes the finest edge "
            f"{x[-1]:.6g} m ({class_label(x.size - 1, x)} is the sink); extend the grid to finer sizes"
        )
    # first edge (from fine to coarse) where P reaches q: the crossing is between it and
    # the edge below it. P is non-increasing coarse -> fine: count the edges with P >= q.
    ks = np.searchsorted(-P, -q, side="right") - 1
    lx, Pl = np.log(x).tolist(), P.tolist()  # a few scalar steps: Python floats beat numpy here
    out = np.empty(q.size)
    for i, (k, qi) in enumerate(zip(ks.tolist(), q.tolist())):
        out[i] = x[k] if Pl[k] == qi else math.exp(_crossing(lx, Pl, k, qi))
    return out


def _node_slope(lx: list, P: list, j: int) -> float:
    """PCHIP slope dP/d(ln x) at edge j, as scipy's.

    Lists coarse -> fine (ln x, P); from its neighbours: the numbers of
    :func:`_pchip_slopes` at that node, in Python floats.
    """
    n = len(P)
    if n == 2:
        return (P[0] - P[1]) / (lx[0] - lx[1])
    if j in (0, n - 1):  # the coarsest or finest edge: the three-point end formula
        a, b, c = (0, 1, 2) if j == 0 else (n - 1, n - 2, n - 3)
        h0, h1 = abs(lx[a] - lx[b]), abs(lx[b] - lx[c])
        m0, m1 = (P[a] - P[b]) / (lx[a] - lx[b]), (P[b] - P[c]) / (lx[b] - lx[c])
        return _pchip_edge(h0, h1, m0, m1)
    h0, h1 = lx[j] - lx[j + 1], lx[j - 1] - lx[j]  # ascending in ln x: j+1, j, j-1
    m0, m1 = (P[j] - P[j + 1]) / h0, (P[j - 1] - P[j]) / h1
    if m0 == 0 or m1 == 0 or (m0 > 0) != (m1 > 0):
        return 0.0
    w1, w2 = 2 * h1 + h0, h1 + 2 * h0
    try:
        return (w1 + w2) / (w1 / m0 + w2 / m1)
    except (ZeroDivisionError, OverflowError):  # subnormal secants: slope 0, as in scipy
        return 0.0


def _local_cubic(lx: list, P: list, k: int):
    """Local cubic of P in ln x around the crossing between edges k+1 and k, or None.

    The cubic in v = ln x - ln x_{k+1} through the four edges k-1..k+2, as a function
    v -> (value, derivative), if it is monotone (P non-decreasing in ln x) on [0, h]; else
    None (too near a grid end, or not monotone). Newton's divided differences in Python floats.
    """
    if k < 1 or k + 2 > len(P) - 1:
        return None
    u0 = lx[k + 1]
    z = [lx[k + 2] - u0, 0.0, lx[k] - u0, lx[k - 1] - u0]
    y = [P[k + 2], P[k + 1], P[k], P[k - 1]]
    d1 = [(y[i + 1] - y[i]) / (z[i + 1] - z[i]) for i in range(3)]
    d2 = [(d1[i + 1] - d1[i]) / (z[i + 2] - z[i]) for i in range(2)]
    c0, c1, c2, c3 = y[0], d1[0], d2[0], (d2[1] - d2[0]) / (z[3] - z[0])

    def fun(v):
        r2 = c2 + (v - z[2]) * c3
        r1 = c1 + (v - z[1]) * r2
        return c0 + (v - z[0]) * r1, r1 + (v - z[0]) * (r2 + (v - z[1]) * c3)

    h = z[2]
    # the derivative is a quadratic: non-negative at both ends and at its vertex inside
    g0, gm, gh = fun(0.0)[1], fun(0.5 * h)[1], fun(h)[1]
    curv = 2.0 * (g0 - 2.0 * gm + gh) / (h * h)  # its second derivative (constant)
    checks = [g0, gh]
    if curv != 0.0:
        vertex = 0.5 * h - (gh - g0) / (h * curv)
        if 0.0 < vertex < h:
            checks.append(fun(vertex)[1])
    return fun if min(checks) >= 0.0 else None


def _crossing(lx: list, P: list, k: int, q: float) -> float:
    """Log size where the interval's cubic crosses q between edges k+1 (P < q) and k (P > q).

    Newton in v in [0, h] safeguarded by bisection (the cubic is monotone there), to a
    step of 2e-15 h or a residual at rounding level (near the root the cubic's rounding
    over its slope moves v back and forth by a few 1e-15 h).
    """
    u0, h = lx[k + 1], lx[k] - lx[k + 1]
    fun = _local_cubic(lx, P, k)
    if fun is None:  # PCHIP's cubic Hermite on the interval
        y0, y1 = P[k + 1], P[k]
        d0, d1 = _node_slope(lx, P, k + 1), _node_slope(lx, P, k)

        def fun(v):
            t = v / h
            t2 = t * t
            t3 = t2 * t
            val = (2 * t3 - 3 * t2 + 1) * y0 + (t3 - 2 * t2 + t) * h * d0 + (3 * t2 - 2 * t3) * y1 + (t3 - t2) * h * d1
            der = ((6 * t2 - 6 * t) * (y0 - y1) + (3 * t2 - 4 * t + 1) * h * d0 + (3 * t2 - 2 * t) * h * d1) / h
            return val, der

    a, b = 0.0, h
    v = min(max((q - P[k + 1]) / (P[k] - P[k + 1]), 0.0), 1.0) * h
    for _ in range(80):
        val, der = fun(v)
        r = val - q
        if r == 0:
            break
        if r < 0:
            a = v
        else:
            b = v
        vn = v - r / der if der != 0 else -1.0
        if not a <= vn <= b:
            vn = 0.5 * (a + b)
        step = abs(vn - v)
        v = vn
        if step <= 2e-15 * h or abs(r) <= 8.9e-16:
            break
    return u0 + v


def p80(grid, frac) -> float:
    """80 % passing size [m]; see :func:`percentile_size`."""
    return percentile_size(grid, frac, 80)


def p50(grid, frac) -> float:
    """Median size [m] (50 % passing); see :func:`percentile_size`."""
    return percentile_size(grid, frac, 50)


# ------------------------------------------------------------ distribution forms
def rosin_rammler(x, x63: float, n: float) -> np.ndarray:
    """Rosin-Rammler (Weibull) cumulative passing P(x) = 1 - exp(-(x/x63)^n) [-].

    x, x63 [m] (x63: the size passing 63.2 %), n > 0 the spread. Rosin and Rammler,
    J. Inst. Fuel 7 (1933) 29.
    """
    x = np.asarray(x, dtype=float)
    return -np.expm1(-(x / x63) ** n)


def gates_gaudin_schuhmann(x, xmax: float, m: float) -> np.ndarray:
    """Gates-Gaudin-Schuhmann cumulative passing P(x) = (x/xmax)^m for x < xmax, else 1.

    x, xmax [m] (the size passing 100 %), m > 0 the distribution modulus.
    Schuhmann, AIME Tech. Pub. 1189 (1940).
    """
    x = np.asarray(x, dtype=float)
    return np.minimum(x / xmax, 1.0) ** m


#: Tail rules of :func:`fit_tail`: name -> (form, its parameter names).
TAIL_RULES = {"rosin_rammler": (rosin_rammler, ("x63", "n")),
              "gates_gaudin_schuhmann": (gates_gaudin_schuhmann, ("xmax", "m"))}
TAIL_RULES["ggs"] = TAIL_RULES["gates_gaudin_schuhmann"]


def from_distribution(grid, cdf, *, top_tol: float = 1e-4, where: str = "psd") -> np.ndarray:
    """Mass fractions on ``grid`` of a cumulative-passing function ``cdf(x [m]) -> P``.

    Mass coarser than the grid's top edge, 1 - P(x_1), has no class: up to ``top_tol``
    (default 0.01 %) it is added to class 1, beyond that it is an error that asks for
    a larger grid top (nothing is lumped silently beyond the stated tolerance).
    """
    x = as_sizes(grid)
    P = np.asarray(cdf(x), dtype=float)
    if P.shape != x.shape or not np.all(np.isfinite(P)) or np.any(P < 0) or np.any(P > 1 + SUM_TOL):
        raise GridError(f"{where}: the cumulative passing is not a finite fraction in [0, 1] at every grid edge")
    if P[0] < 1 - top_tol:
        raise GridError(f"{where}: the size grid does not cover the PSD: {100 * (1 - P[0]):.3g} % of it is coarser "
                        f"than the grid top ({x[0] * 1e6:.6g} um; at most {100 * top_tol:.3g} % may be lumped into "
                        "class 1); raise the grid top")
    P = np.minimum.accumulate(np.minimum(P / P[0], 1.0))  # the <= top_tol above the top edge joins class 1
    return _fractions_from_cum(P) if x.size > 1 else np.ones(1)


@dataclass(frozen=True)
class TailFit:
    """A distribution form fitted to the finest sieves, for the PSD below them.

    ``rule`` names the form (:data:`TAIL_RULES`), ``params`` its parameters (sizes in
    m), ``sizes_m`` the sieves used and ``rms_residual`` the RMS misfit of the
    linearised fit there (in ln P for GGS, in ln(-ln(1 - P)) for Rosin-Rammler).
    """

    rule: str
    params: dict
    sizes_m: tuple
    rms_residual: float

    def passing(self, x) -> np.ndarray:
        """Cumulative passing of the fitted form at sizes x [m]."""
        return TAIL_RULES[self.rule][0](x, **self.params)

    def describe(self) -> str:
        """One line: the rule, the sieves it was fitted to and its parameters (sizes in um)."""
        p = ", ".join(f"{k} = {v * 1e6:.4g} um" if k in ("x63", "xmax") else f"{k} = {v:.4g}"
                      for k, v in self.params.items())
        return (f"{self.rule} fitted to the {len(self.sizes_m)} finest sieves "
                f"({self.sizes_m[-1] * 1e6:.4g}-{self.sizes_m[0] * 1e6:.4g} um): {p}")


def fit_tail(size_m, passing, rule: str, n_points: int = 3) -> TailFit:
    """Fit a form to the ``n_points`` finest sieves for extrapolation below them.

    Linear least squares on the form's straight-line coordinates: ln P against ln x
    (Gates-Gaudin-Schuhmann, slope m) or ln(-ln(1 - P)) against ln x (Rosin-Rammler,
    slope n). Only sieves with 0 < P < 1 are used; at least two are needed, and the
    slope must be positive (a PSD whose passing does not fall towards fine sizes has
    no such tail).
    """
    if rule not in TAIL_RULES:
        raise GridError(f"tail = {rule!r}: expected one of {', '.join(TAIL_RULES)}")
    rule = "gates_gaudin_schuhmann" if rule == "ggs" else rule
    if int(n_points) != n_points or n_points < 2:
        raise GridError(f"tail_points = {n_points!r}: expected a whole number >= 2")
    s = np.asarray(size_m, dtype=float)
    P = np.asarray(passing, dtype=float)
    ok = (P > 0) & (P < 1)
    s, P = s[ok][-int(n_points):], P[ok][-int(n_points):]
    if s.size < 2:
        raise GridError(f"tail = {rule!r}: needs at least 2 of the finest sieves with 0 < passing < 1, has {s.size}")
    lx = np.log(s)
    ggs = rule == "gates_gaudin_schuhmann"
    y = np.log(P) if ggs else np.log(-np.log1p(-P))
    slope, icpt = np.polyfit(lx, y, 1)
    # a slope near 0 is a flat curve: it says nothing of where the fines are (and its
    # scale size, exp(-intercept/slope), is not finite); 1e-3 is far below real moduli (~0.3-2)
    if not (np.isfinite(slope) and slope > 1e-3 and np.isfinite(-icpt / slope) and abs(icpt / slope) < 700):
        raise GridError(f"tail = {rule!r}: the finest {s.size} sieves give a slope {float(slope):.4g}; "
                        "expected > 1e-3 (passing falling towards fine sizes)")
    resid = float(np.sqrt(np.mean((slope * lx + icpt - y) ** 2)))
    scale = float(np.exp(-icpt / slope))
    params = {"xmax": scale, "m": float(slope)} if ggs else {"x63": scale, "n": float(slope)}
    return TailFit(rule, params, tuple(float(v) for v in s), resid)
