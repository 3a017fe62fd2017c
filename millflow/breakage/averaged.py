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
           "is_continuous", "breakage_on_grid", "curve_on_grid", "node_sizes", "average_at_nodes",
           "averaged_power_terms", "averaged_power_population"]


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


# ------------------------------------------------------------- populations (the fit)
def node_sizes(grid, nodes: int = NODES) -> np.ndarray:
    """The quadrature sizes of every breaking class followed by x_N (the sink's value), [m].

    ``fun(node_sizes(x))`` evaluated once for a whole population (trailing axis the sizes)
    is what :func:`average_at_nodes` and :func:`averaged_power_population` take: the
    (N - 1) * nodes Gauss points of :func:`class_nodes`, coarse first, then x_N.
    """
    x = as_sizes(grid)
    y, _ = class_nodes(x, nodes)
    return np.append(y.ravel(), x[-1])


def average_at_nodes(values, nodes: int = NODES) -> np.ndarray:
    """Class averages (*L, N) of values (*L, (N - 1) nodes + 1) at :func:`node_sizes`.

    The population form of :func:`class_average`: the Gauss-weighted mean over each
    breaking class, the sink keeps its value at x_N. Non-finite members stay non-finite.
    """
    v = np.asarray(values, dtype=float)
    _, w = _leggauss(int(nodes))
    body = v[..., :-1].reshape(v.shape[:-1] + (-1, int(nodes)))
    lo = hi = body[..., 0]
    for q in range(1, int(nodes)):  # node by node: numpy's min/max over an axis of 3 is ~4x slower
        lo, hi = np.minimum(lo, body[..., q]), np.maximum(hi, body[..., q])
    with np.errstate(invalid="ignore"):
        avg = np.clip(body @ (w / 2.0), lo, hi)
    return np.concatenate([avg, v[..., -1:]], axis=-1)


def averaged_power_terms(grid, S_nodes, phi0, gamma, beta, theta=0.0, x_max=None, nodes: int = NODES,
                         idle_split: bool = False):
    """Class-averaged transfer of eqs. 6/8 in separable form, for a population of parameter sets.

    With B(x; y) = phi(y) (x/y)^gamma + (1 - phi(y)) (x/y)^beta, phi(y) = phi0 (x_max/y)^theta
    (eq. 8; theta = 0 is eq. 6) and the mass inside class j uniform in ln y (module
    docstring), the class average of S(y) B(x_i; y) over class j separates for every
    receiving edge x_i <= x_{j+1}:

        T_ij = (x_i/x_j)^gamma a1_j + (x_i/x_j)^beta a2_j,
        a1_j = sum_q w_q S(y_jq) phi(y_jq) (x_j/y_jq)^gamma,
        a2_j = sum_q w_q S(y_jq) (1 - phi(y_jq)) (x_j/y_jq)^beta,

    (Gauss points y_jq, weights w_q of :func:`class_nodes`), so that the leaving rate is
    S_j = T_{j+1,j} and b_ij = (T_ij - T_{i+1,j}) / S_j, b_Nj = T_Nj / S_j: the same
    numbers as :func:`averaged_breakage`, but O(N) per member instead of O(N^2), which is
    what a fit evaluating hundreds of members needs (:func:`averaged_power_population`
    forms b from them; :func:`millflow.mill.well_mixed.well_mixed_population_separable`
    solves eq. 3 from them directly on a geometric grid).

    Parameters
    ----------
    grid : SizeGrid or array_like of upper edges x [m] (N).
    S_nodes : (*L, (N - 1) nodes + 1) rates S(y) [1/s] at :func:`node_sizes` (the last
        value, at x_N, is not used).
    phi0, gamma, beta, theta : parameters broadcasting to L; x_max [m] (default x_1).

    Returns
    -------
    S : (*L, N) leaving rates [1/s] (S_N = 0); a1, a2 : (*L, N) [1/s] (last entry 0).
    With ``idle_split`` a class whose leaving rate is 0 (S(y) = 0 throughout) gets the
    weights of the distribution alone (as :func:`averaged_breakage`), so that its b column
    still sums to 1; without, its weights are 0 (it sends nothing anywhere).
    Members outside the domain (phi(y) outside [0, 1], negative or non-finite exponents)
    get NaN, as :func:`~millflow.breakage.distributions.breakage_population`.
    """
    x = as_sizes(grid)
    y, w = class_nodes(x, nodes)  # (N - 1, Q)
    S_y = np.asarray(S_nodes, dtype=float)[..., :-1]
    lead = S_y.shape[:-1]
    S_y = S_y.reshape(lead + y.shape)
    phi0, gamma, beta, theta = (np.asarray(v, dtype=float)[..., None, None] for v in (phi0, gamma, beta, theta))
    x_max = x[0] if x_max is None else float(x_max)
    ln_rel = np.log(x[:-1, None] / y)  # ln(x_j / y_jq) in [0, h_j): bounded powers
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        phi = phi0 * np.exp(theta * np.log(x_max / y)) if np.any(theta != 0) else phi0 + 0.0 * ln_rel
        k1 = phi * np.exp(gamma * ln_rel) * w
        k2 = (1.0 - phi) * np.exp(beta * ln_rel) * w
        a1, a2 = _node_sum(S_y, k1), _node_sum(S_y, k2)
        r = np.log(x[1:] / x[:-1])  # ln(x_{j+1}/x_j) < 0
        g, bt = gamma[..., 0], beta[..., 0]
        S = np.exp(g * r) * a1 + np.exp(bt * r) * a2
        ok = ((phi >= 0) & (phi <= 1)).all(axis=(-1, -2)) & (g[..., 0] >= 0) & (bt[..., 0] >= 0)
        ok &= np.isfinite(g[..., 0]) & np.isfinite(bt[..., 0])
        zero = ~(S > 0) & np.isfinite(S)
        if idle_split and zero.any():  # a class that does not break: b from the distribution alone
            a10, a20 = np.sum(k1, axis=-1), np.sum(k2, axis=-1)
            a10, a20 = np.broadcast_to(a10, a1.shape), np.broadcast_to(a20, a2.shape)
            a1, a2 = np.where(zero, a10, a1), np.where(zero, a20, a2)
    S = np.concatenate([S, np.zeros(S.shape[:-1] + (1,))], axis=-1)
    a1 = np.concatenate([a1, np.zeros(a1.shape[:-1] + (1,))], axis=-1)
    a2 = np.concatenate([a2, np.zeros(a2.shape[:-1] + (1,))], axis=-1)
    if not np.all(ok):
        bad = ~np.broadcast_to(ok, S.shape[:-1])
        S, a1, a2 = (np.where(bad[..., None], np.nan, v) for v in (S, a1, a2))
    return S, a1, a2


def _node_sum(a, b) -> np.ndarray:
    """sum_q a[..., q] b[..., q] over the nodes (last axis), node after node: the numbers of
    ``np.sum(a * b, axis=-1)`` (numpy adds a short trailing axis in order), without the
    product array and numpy's slow reduction over an axis of 3."""
    out = a[..., 0] * b[..., 0]
    for q in range(1, a.shape[-1]):
        out += a[..., q] * b[..., q]
    return out


def averaged_power_population(grid, S_nodes, phi0, gamma, beta, theta=0.0, x_max=None,
                              nodes: int = NODES) -> tuple[np.ndarray, np.ndarray]:
    """Class-averaged (S (*L, N) [1/s], b (*L, N, N) [-]) of eqs. 5-8 for a population.

    The population form of :func:`averaged_breakage` for the power-law distributions of
    eqs. 6 and 8 (arguments and separable form: :func:`averaged_power_terms`):
    b_ij = [((x_i/x_j)^gamma - (x_{i+1}/x_j)^gamma) a1_j + (same in beta) a2_j] / S_j,
    b_Nj = [(x_N/x_j)^gamma a1_j + (x_N/x_j)^beta a2_j] / S_j, each column summing to 1 by
    telescoping. A class with S_j = 0 takes the distribution's own split.
    """
    x = as_sizes(grid)
    n = x.size
    S, a1, a2 = averaged_power_terms(x, S_nodes, phi0, gamma, beta, theta, x_max, nodes, idle_split=True)
    gamma = np.asarray(gamma, dtype=float)[..., None]
    beta = np.asarray(beta, dtype=float)[..., None]
    lx = np.log(x / x[0])  # <= 0
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        # (x_i/x_1)^e and its drop to the next edge, (x_i/x_1)^e (1 - (x_{i+1}/x_i)^e), from expm1
        step = np.log(x[1:] / x[:-1])
        E1, E2 = np.exp(gamma * lx), np.exp(beta * lx)
        # the sink row keeps all that passes x_N: T_Nj itself
        d1 = np.concatenate([E1[..., :-1] * -np.expm1(gamma * step), E1[..., -1:]], axis=-1)
        d2 = np.concatenate([E2[..., :-1] * -np.expm1(beta * step), E2[..., -1:]], axis=-1)
        nxt = np.append(step, 0.0)
        leave = np.where(S > 0, S, np.exp(gamma * nxt) * a1 + np.exp(beta * nxt) * a2)
        g1 = a1 / (E1 * leave)
        g2 = a2 / (E2 * leave)
        b = d1[..., :, None] * g1[..., None, :] + d2[..., :, None] * g2[..., None, :]
    b = b * np.tril(np.ones((n, n)), -1)
    b[..., :, -1] = 0.0
    return S, b
