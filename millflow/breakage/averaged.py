"""Continuous-size forms put on a size grid by class averages (second order in the class width).

The forms of eqs. 5-8 and 10 describe a continuous model: a rate S(y) [1/s] of particles
of size y and a cumulative distribution B(x; y) [-], the mass fraction of the fragments
of a particle of size y that is finer than x (B = 1 for x >= y; eq. 6 is B = F(x/y)).
Austin's discrete convention evaluates them at class edges (S_i = S(x_i) at the upper
edge, B_ij = F(x_{i-1}/x_j)), which converges to that model at first order in the class
width h = ln(x_i/x_{i+1}). This module instead takes the class averages of the exact
class-to-class transfer, with the mass inside class j taken as uniform in ln y:

    T_ij = (1/h_j) integral over class j of S(y) B(x_i; y) d(ln y),
    S_j  = T_{j+1,j}                          (rate of leaving class j: fragments finer
                                               than its lower edge x_{j+1})
    b_ij = (T_ij - T_{i+1,j}) / S_j  (j < i < N),   b_Nj = T_Nj / S_j.

Breakage inside class j (the fragments coarser than x_{j+1}) does not change the class
masses and drops out exactly; every column of b sums to 1 by telescoping (mass is
conserved to rounding). The uniform-in-ln y weighting and the quadrature err at
O(h^2) per class, so class masses, and P80 read from them, converge at second order
(measured in docs/core.md). The integrals are taken by Gauss-Legendre quadrature in
ln y with :data:`NODES` points per class (the integrands are smooth inside a class).
A classification curve c(x) is averaged over each class the same way
(:func:`class_average`); the sink class (0, x_N] keeps c(x_N).

A user's own S_i and b_ij (tabulated, or a model without a continuous B) are the
discrete model itself: they are used as given and carry no grid error.
"""
from __future__ import annotations

import functools

import numpy as np

from millflow.breakage.distributions import validate_b
from millflow.breakage.rates import TabulatedRate, validate_rates
from millflow.grid import SCHEMES, as_sizes  # noqa: F401  (SCHEMES re-exported)

__all__ = ["NODES", "SCHEMES", "class_nodes", "class_average", "averaged_breakage", "continuous_rate",
           "is_continuous", "breakage_on_grid", "curve_on_grid"]


#: Gauss-Legendre points per class. 3 points integrate the smooth in-class integrands to
#: far below the O(h^2) error of the uniform-mass assumption (4 changes P80 of the
#: shipped circuits by < 1e-6 relative at 2^(1/4)).
NODES = 3


def class_nodes(grid, nodes: int = NODES) -> tuple[np.ndarray, np.ndarray]:
    """Quadrature sizes y [m] (shape (N - 1, nodes)) and weights (nodes,) summing to 1.

    The nodes are Gauss-Legendre points in ln y over each breaking class (x_{i+1}, x_i],
    coarse first, so ``y.ravel()`` is strictly decreasing.
    """
    x = as_sizes(grid)
    u, w = _leggauss(int(nodes))
    hi, lo = np.log(x[:-1]), np.log(x[1:])
    ln_y = 0.5 * (hi + lo)[:, None] + 0.5 * (hi - lo)[:, None] * u[None, :]
    return np.exp(ln_y), w / 2.0


@functools.lru_cache(maxsize=8)
def _leggauss(nodes: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Legendre points (descending: the coarse end of a class first) and weights,
    computed once per number of points (numpy builds them from a companion matrix)."""
    u, w = np.polynomial.legendre.leggauss(nodes)
    u, w = u[::-1].copy(), w[::-1].copy()
    u.flags.writeable = w.flags.writeable = False
    return u, w


def class_average(fun, grid, nodes: int = NODES) -> np.ndarray:
    """Class averages (uniform in ln x) of a continuous function of size ``fun(x) -> values``.

    Returns N values: the averages over the N - 1 classes above the sink and ``fun(x_N)``
    for the sink, which spans (0, x_N] and has no finite width in ln x.
    """
    x = as_sizes(grid)
    if x.size == 1:
        return np.asarray(fun(x), dtype=float)
    y, w = class_nodes(x, nodes)
    vals = np.asarray(fun(np.append(y.ravel(), x[-1])), dtype=float)
    nodes_vals = vals[:-1].reshape(y.shape)
    # a mean lies between its smallest and largest value: the weights' rounding (they sum
    # to 1 within a few eps) must not put a partition of 1 at 1 + 2e-16 (a negative flow)
    avg = np.clip(nodes_vals @ w, nodes_vals.min(axis=1), nodes_vals.max(axis=1))
    return np.append(avg, vals[-1])


def continuous_rate(rate):
    """S(y) [1/s] at arbitrary sizes y (a strictly decreasing array) of a rate model, or None.

    Built-in forms and a user's function of size are continuous; a :class:`TabulatedRate`
    (one value per class) is not, and gives None. Rate models zero their last entry
    (the sink); a dummy finer size is appended and dropped so every y keeps its S(y).
    """
    if isinstance(rate, TabulatedRate):
        return None
    if hasattr(rate, "specific") and continuous_rate(rate.specific) is None:  # rates per energy of a table
        return None
    fun = getattr(rate, "rates", rate)

    def S(y):
        y = np.asarray(y, dtype=float)
        return np.asarray(fun(np.append(y, y[-1] * 0.5)), dtype=float)[:-1]

    return S


def is_continuous(rate, breakage) -> bool:
    """True when both models are continuous-size forms (the class-averaged path applies)."""
    return continuous_rate(rate) is not None and callable(getattr(breakage, "cumulative", None))


def averaged_breakage(rate, breakage, grid, nodes: int = NODES) -> tuple[np.ndarray, np.ndarray]:
    """Class-averaged (S, b) on ``grid`` of a continuous rate and distribution (module docstring).

    Parameters
    ----------
    rate : rate model (callable of the sizes [m]; not a :class:`TabulatedRate`)
    breakage : object with ``cumulative(x, y) -> B(x; y)`` (broadcasting; sizes [m])
    grid : SizeGrid or array_like of upper edges [m]

    Returns
    -------
    S : (N,) [1/s], S_N = 0;  b : (N, N) [-], columns j < N summing to 1.
    """
    x = as_sizes(grid)
    n = x.size
    if n == 1:
        return np.zeros(1), np.zeros((1, 1))
    y, w = class_nodes(x, nodes)
    S_y = continuous_rate(rate)(y.ravel()).reshape(y.shape)
    if not np.all(np.isfinite(S_y)) or np.any(S_y < 0):
        bad = np.argwhere(~(np.isfinite(S_y) & (S_y >= 0)))[0]
        raise ValueError(f"rate {rate!r} is {float(S_y[tuple(bad)])!r} 1/s at {float(y[tuple(bad)]):.6g} m; "
                         "expected finite and >= 0")
    # B(x_i; y) for receiving edges i = 1..N-1 (0-based) and every node of every class
    C = np.asarray(breakage.cumulative(x[1:, None, None], y[None, :, :], top=x[0]), dtype=float)  # (N-1, N-1, Q)
    C = np.where(x[1:, None, None] >= y[None, :, :], 1.0, C)
    Sw = S_y * w  # (N-1, Q)
    T = np.einsum("ijq,jq->ij", C, Sw)  # T[i-1, j] = average of S(y) B(x_i; y) over class j
    T0 = np.einsum("ijq,q->ij", C, w)  # the same without S: b of a class that does not break
    jj = np.arange(n - 1)
    S_leave = T[jj, jj]  # B(x_{j+1}; y) weighted by S: the rate of leaving class j
    use = np.where(S_leave > 0, 1.0, 0.0)
    Tn = use * T / np.where(S_leave > 0, S_leave, 1.0) + (1 - use) * T0 / T0[jj, jj]
    b = np.zeros((n, n))
    b[1:, :-1] = Tn
    b[1:-1, :-1] -= Tn[1:]
    b = np.tril(b, -1)
    np.maximum(b, 0.0, out=b)  # B non-increasing in x: negatives are rounding only
    S = np.append(S_leave, 0.0)
    return validate_rates(S, x), validate_b(b, x, tol=1e-9)


def breakage_on_grid(rate, breakage, grid) -> tuple[np.ndarray, np.ndarray, str]:
    """(S [1/s], b [-], how) of a rate and a distribution model on ``grid``.

    Continuous forms on a grid whose ``scheme`` is "class_average" are class-averaged
    (:func:`averaged_breakage`); otherwise (Austin's upper-edge scheme, or a user's
    discrete S_i / b_ij) the models are evaluated at the upper edges. ``how`` names
    the path: "class average", "upper edge" or "discrete (as given)".
    """
    x = as_sizes(grid)
    scheme = getattr(grid, "scheme", "class_average")
    if scheme == "class_average" and is_continuous(rate, breakage):
        S, b = averaged_breakage(rate, breakage, x)
        return S, b, "class average"
    S = np.asarray(getattr(rate, "rates", rate)(x), dtype=float)
    fun = getattr(breakage, "b", breakage)
    b = np.asarray(fun(x), dtype=float)
    discrete = continuous_rate(rate) is None or not callable(getattr(breakage, "cumulative", None))
    return S, b, "discrete (as given)" if discrete else "upper edge"


def curve_on_grid(fun, grid) -> np.ndarray:
    """A classification (or any) curve of size ``fun(x) -> values`` on ``grid``: class
    averages on a "class_average" grid (:func:`class_average`), else values at the upper edges."""
    x = as_sizes(grid)
    if getattr(grid, "scheme", "class_average") == "class_average":
        return class_average(fun, x)
    return np.asarray(fun(x), dtype=float)
