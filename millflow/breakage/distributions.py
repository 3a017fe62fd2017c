"""Breakage distributions B_ij and b_ij on a size grid (docs/equations.md, eqs. 6 and 8).

B_ij [-] is the mass fraction of the material broken out of class j that is finer
than the upper size of class i (i > j); b_ij = B_ij - B_{i+1,j} is the fraction that
lands in class i, and b_Nj = B_Nj for the sink. Both are (N, N) arrays, row i the
receiving class, column j the breaking class, with entries only strictly below the
diagonal; column N (the sink, which does not break) is all zero. The index convention
of eqs. 6 and 8, B_ij = F(x_{i-1}/x_j), makes B_{j+1,j} = 1 (all broken material
leaves its class), so every column j < N of b sums to 1. Sizes x are the upper class
edges [m] (Austin). A distribution model is anything callable as ``model(x) -> b``;
the dataclasses also offer ``.B(x)``; :func:`evaluate_b` checks any model's output.
"""
from __future__ import annotations

from dataclasses import dataclass

import functools

import numpy as np

from millflow.errors import BreakageError
from millflow.grid import as_sizes, class_label

__all__ = [
    "normalized_B",
    "non_normalized_B",
    "breakage_population",
    "continuous_B",
    "b_from_B",
    "B_from_b",
    "validate_B",
    "validate_b",
    "evaluate_b",
    "NormalizedBreakage",
    "NonNormalizedBreakage",
    "TabulatedBreakage",
]

# Default tolerance on column sums of b and on B_{j+1,j} = 1: beyond rounding, below
# the precision with which a tabulated b is normally published it must be exact;
# callers with 4-digit tables pass a looser tol explicitly.
COLUMN_TOL = 1e-9


def _param(value, name: str, lo: float | None = None, hi: float | None = None) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError) as exc:
        raise BreakageError(f"{name} = {value!r}: expected a number") from exc
    if not np.isfinite(v) or (lo is not None and v < lo) or (hi is not None and v > hi):
        rng = f"in [{lo:g}, {hi:g}]" if hi is not None else (f">= {lo:g}" if lo is not None else "finite")
        raise BreakageError(f"{name} = {value!r}: expected a finite number {rng}")
    return v


@functools.lru_cache(maxsize=32)
def _pair_table(key: bytes) -> dict:
    """Index tables of the strict lower triangle for the sizes in ``key`` (float64 bytes).

    The pairs i > j with their distinct ratios r = x_{i-1}/x_j (on a geometric grid a
    few hundred instead of N^2/2: the powers are taken once per ratio) and maps that
    scatter values on distinct ratios (or on pairs) into the full (N, N) matrix in one
    gather (``np.take``), for B and for b = B_ij - B_{i+1,j}.
    """
    xs = np.frombuffer(key, dtype=float)
    n = xs.size
    i, j = np.tril_indices(n, -1)
    ratios, inverse = np.unique(xs[i - 1] / xs[j], return_inverse=True)
    n_r, n_p = ratios.size, i.size
    one, zero = n_r, n_r + 1  # extended value table: [F(ratios), 1, 0]
    c = np.where(i == j + 1, one, inverse.ravel())  # B_{j+1,j} = 1 exactly
    pos = np.full((n + 1, n), n_p)
    pos[i, j] = np.arange(n_p)
    nxt = pos[i + 1, j]  # pair (i + 1, j), or n_p (B = 0 below the sink)
    c_next = np.append(c, zero)[nxt]
    combos, inv_b = np.unique(np.stack([c, c_next]), axis=1, return_inverse=True)
    full_B = np.full(n * n, zero)
    full_B[i * n + j] = c
    full_b = np.full(n * n, combos.shape[1])  # extended: [b on combos, 0]
    full_b[i * n + j] = inv_b.ravel()
    full_pair = np.full(n * n, n_p)  # extended: [values on pairs, 0]
    full_pair[i * n + j] = np.arange(n_p)
    out = dict(i=i, j=j, log_r=np.log(ratios), inverse=inverse.ravel(), c=c, nxt=nxt, combos=combos,
               full_B=full_B, full_b=full_b, full_pair=full_pair)
    for arr in out.values():
        arr.setflags(write=False)
    return out


def breakage_population(x, phi0, gamma, beta, theta=0.0, x_max=None, *, kind: str = "B") -> np.ndarray:
    """Eqs. 6 and 8 for a population of parameter sets: B (or b) of shape (*L, N, N).

    B_ij = phi_j r^gamma + (1 - phi_j) r^beta, r = x_{i-1}/x_j (i > j), phi_j =
    phi0 (x_max/x_j)^theta (theta = 0: eq. 6 with phi = phi0), B_{j+1,j} = 1 exactly.
    The one implementation of both equations: :func:`normalized_B` and
    :func:`non_normalized_B` are this with scalar parameters, then checked.

    Parameters
    ----------
    x : SizeGrid or array_like, upper class sizes [m].
    phi0, gamma, beta, theta : float or arrays broadcasting to a leading shape L
        (members of a population, conditions); x_max [m] (default the top size x_1).
    kind : "B" (cumulative) or "b" (fractional, b_ij = B_ij - B_{i+1,j}, b_Nj = B_Nj).

    Nothing is raised for parameter values (the hot loop of a fit): a member whose
    phi_j leaves [0, 1] for a breaking class, or with a negative or non-finite exponent,
    gets NaN entries, which an optimiser reads as "outside the model's domain".
    """
    if kind not in ("B", "b"):
        raise BreakageError(f"kind = {kind!r}: expected 'B' or 'b'")
    xs = as_sizes(x)
    n = xs.size
    tab = _pair_table(np.ascontiguousarray(xs, dtype=float).tobytes())
    phi0, gamma, beta, theta = (np.asarray(v, dtype=float) for v in (phi0, gamma, beta, theta))
    lead = np.broadcast_shapes(phi0.shape, gamma.shape, beta.shape, theta.shape)
    x_max = xs[0] if x_max is None else float(x_max)
    log_r = tab["log_r"]
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        phi_j = phi0[..., np.newaxis] * (x_max / xs[:-1]) ** theta[..., np.newaxis]  # breaking classes
        ok = ((phi_j >= 0) & (phi_j <= 1)).all(axis=-1) & (gamma >= 0) & (beta >= 0)
        ok &= np.isfinite(gamma) & np.isfinite(beta)
        fine = np.exp(gamma[..., np.newaxis] * log_r)  # r^gamma on the distinct ratios
        single = bool((phi_j == 1).all())
        coarse = None if single else np.exp(beta[..., np.newaxis] * log_r)
        if not (theta == 0).all():  # eq. 8: phi depends on the breaking class j
            pj = phi_j[..., tab["j"]]
            vals = pj * fine[..., tab["inverse"]] + (1.0 - pj) * coarse[..., tab["inverse"]]
            vals = np.where(tab["c"] == log_r.size, 1.0, np.broadcast_to(vals, lead + vals.shape[-1:]))
            ext = np.concatenate([vals, np.zeros(lead + (1,))], axis=-1)
            if kind == "b":
                ext[..., :-1] = vals - ext[..., tab["nxt"]]
            out = np.take(ext, tab["full_pair"], axis=-1)
        else:  # eq. 6: B is a function of the ratio alone
            F = fine if single else phi0[..., np.newaxis] * fine + (1.0 - phi0[..., np.newaxis]) * coarse
            F = np.broadcast_to(F, lead + log_r.shape)
            ext = np.concatenate([F, np.ones(lead + (1,)), np.zeros(lead + (1,))], axis=-1)
            if kind == "b":
                c1, c2 = tab["combos"]
                ext = np.concatenate([ext[..., c1] - ext[..., c2], np.zeros(lead + (1,))], axis=-1)
                out = np.take(ext, tab["full_b"], axis=-1)
            else:
                out = np.take(ext, tab["full_B"], axis=-1)
    out = out.reshape(lead + (n, n))
    if not ok.all():
        out[~ok] = np.nan
    return out


def continuous_B(x, y, phi0, gamma, beta, theta=0.0, x_max=None):
    """B(x; y) [-] of eqs. 6 and 8 as a function of continuous sizes (broadcasting, [m]).

    The mass fraction of the fragments of a particle of size y finer than x:
    phi(y) (x/y)^gamma + (1 - phi(y)) (x/y)^beta for x < y, 1 for x >= y, with
    phi(y) = phi0 (x_max/y)^theta (theta = 0: eq. 6). The discrete B_ij of
    :func:`breakage_population` is this at x = x_{i-1}, y = x_j (Austin's convention);
    :mod:`millflow.breakage.averaged` averages it over the classes instead. ``x_max``
    is required when theta != 0.
    """
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    r = np.minimum(x / y, 1.0)
    phi = phi0 if theta == 0 else phi0 * (float(x_max) / y) ** theta
    with np.errstate(divide="ignore"):
        lr = np.log(r)
    return phi * np.exp(gamma * lr) + (1.0 - phi) * np.exp(beta * lr)


def normalized_B(x, phi: float, gamma: float, beta: float) -> np.ndarray:
    """Normalized cumulative breakage distribution, eq. 6.

    B_ij = phi (x_{i-1}/x_j)^gamma + (1 - phi) (x_{i-1}/x_j)^beta  for i > j,
    zero on and above the diagonal; B_{j+1,j} = 1.

    Parameters
    ----------
    x : SizeGrid or array_like
        Upper class sizes [m], coarse -> fine.
    phi : float
        Weight of the fine-fragment term [-], in [0, 1].
    gamma, beta : float
        Exponents [-], >= 0 (typically gamma 0.5-1.5, beta 2.5-5).

    Returns
    -------
    numpy.ndarray
        B, shape (N, N); column N (the sink) is zero.

    Examples
    --------
    >>> B = normalized_B([4e-3, 2e-3, 1e-3], phi=0.5, gamma=1.0, beta=2.0)
    >>> float(B[2, 0])  # 0.5 * 0.5 + 0.5 * 0.25
    0.375
    """
    xs = as_sizes(x)
    phi = _param(phi, "phi", 0.0, 1.0)
    gamma = _param(gamma, "gamma", 0.0)
    beta = _param(beta, "beta", 0.0)
    return breakage_population(xs, phi, gamma, beta)


def non_normalized_B(x, phi0: float, gamma: float, beta: float, theta: float,
                     x_max: float | None = None) -> np.ndarray:
    """Non-normalized cumulative breakage distribution, eq. 8.

    B_ij = phi_j (x_{i-1}/x_j)^gamma + (1 - phi_j) (x_{i-1}/x_j)^beta,
    phi_j = phi0 (x_max/x_j)^theta; theta = 0 gives eq. 6.

    Parameters
    ----------
    x : SizeGrid or array_like
        Upper class sizes [m].
    phi0 : float
        phi at x_j = x_max [-], in [0, 1].
    gamma, beta : float
        Exponents [-], >= 0.
    theta : float
        Size dependence of phi [-] (Austin's -delta).
    x_max : float, optional
        Reference size [m], default the top size x_1.

    Raises
    ------
    BreakageError
        If phi_j leaves [0, 1] for a breaking class j (naming the class and phi_j).
    """
    xs = as_sizes(x)
    phi0 = _param(phi0, "phi0", 0.0, 1.0)
    gamma = _param(gamma, "gamma", 0.0)
    beta = _param(beta, "beta", 0.0)
    theta = _param(theta, "theta")
    x_max = xs[0] if x_max is None else _param(x_max, "x_max", 0.0)
    if x_max <= 0:
        raise BreakageError(f"x_max = {x_max!r}: expected a size > 0 [m]")
    phi_j = phi0 * (x_max / xs) ** theta
    phi_j[-1] = 0.0  # the sink does not break; its phi is never used
    bad = np.flatnonzero(~np.isfinite(phi_j) | (phi_j < 0) | (phi_j > 1))
    if bad.size:
        k = bad[0]
        raise BreakageError(
            f"phi_j = phi0 (x_max/x_j)^theta = {float(phi_j[k])!r} at {class_label(k, xs)}; expected 0 <= phi_j <= 1 "
            f"(phi0 = {phi0:g}, theta = {theta:g}, x_max = {x_max:.6g} m)"
        )
    return breakage_population(xs, phi0, gamma, beta, theta, x_max)


def b_from_B(B, x=None) -> np.ndarray:
    """Fractional distribution b_ij = B_ij - B_{i+1,j}, b_Nj = B_Nj (validated B in).

    Returns a strictly lower triangular (N, N) array whose columns j < N sum to 1
    and whose sink column is zero.
    """
    B = validate_B(B, x)
    b = B.copy()
    b[:-1] -= B[1:]
    # above and on the diagonal B is 0 but B_{j+1,j} = 1 would leave b_jj = -1
    return np.tril(b, -1)


def B_from_b(b, x=None, *, tol: float = COLUMN_TOL) -> np.ndarray:
    """Cumulative distribution B_ij = sum_{k >= i} b_kj for i > j (validated b in)."""
    b = validate_b(b, x, tol=tol)
    B = np.cumsum(b[::-1], axis=0)[::-1]
    return np.tril(B, -1)


# ------------------------------------------------------------------------ validation
@functools.lru_cache(maxsize=16)
def _upper_mask(n: int) -> np.ndarray:
    """1.0 on and above the diagonal, 0.0 below (read-only, cached per size)."""
    mask = 1.0 - np.tri(n, k=-1)
    mask.flags.writeable = False
    return mask


def _square(M, x, name: str) -> tuple[np.ndarray, np.ndarray | None]:
    xs = None if x is None else as_sizes(x)
    try:
        A = np.array(M, dtype=float)
    except (TypeError, ValueError) as exc:
        raise BreakageError(f"{name}: cannot read the matrix as numbers ({exc})") from exc
    if A.ndim != 2 or A.shape[0] != A.shape[1] or A.shape[0] < 1:
        raise BreakageError(f"{name}: expected a square (N, N) array, got shape {A.shape}")
    if xs is not None and A.shape[0] != xs.size:
        raise BreakageError(f"{name}: shape {A.shape} does not match a grid of {xs.size} classes")
    if not np.isfinite(A).all():  # locate the offender only on failure (hot path)
        i, j = np.argwhere(~np.isfinite(A))[0]
        raise BreakageError(f"{name}: {_entry(i, j, xs)} is {float(A[i, j])!r}; expected finite")
    if (A * _upper_mask(A.shape[0])).any():  # a cached mask: np.triu costs 40 us at N = 100
        i, j = np.argwhere(np.triu(A) != 0)[0]
        raise BreakageError(
            f"{name}: {_entry(i, j, xs)} is {float(A[i, j])!r}; expected 0 on and above the diagonal "
            "(only finer classes i > j receive broken material)"
        )
    return A, xs


def _entry(i: int, j: int, xs) -> str:
    return f"entry for receiving {class_label(i, xs)} from breaking {class_label(j, xs)}"


def validate_B(B, x=None, *, tol: float = COLUMN_TOL) -> np.ndarray:
    """Check a cumulative breakage distribution B and return it as float array.

    Requires: square (N, N), finite, zero on and above the diagonal, 0 <= B <= 1,
    B_{j+1,j} = 1 (to ``tol``) for every breaking class j < N, and B non-increasing
    down each column (finer sizes receive no more than coarser ones).

    Raises
    ------
    BreakageError
        Naming the receiving and breaking classes (1-based, with sizes if ``x`` is
        given) and the offending value.
    """
    B, xs = _square(B, x, "B")
    bad = np.argwhere((B < 0) | (B > 1 + tol))
    if bad.size:
        i, j = bad[0]
        raise BreakageError(f"B: {_entry(i, j, xs)} is {float(B[i, j])!r}; expected 0 <= B <= 1")
    n = B.shape[0]
    k = np.arange(n - 1)
    bad = np.flatnonzero(np.abs(B[k + 1, k] - 1.0) > tol)
    if bad.size:
        j = bad[0]
        raise BreakageError(
            f"B: {_entry(j + 1, j, xs)} is {float(B[j + 1, j])!r}; expected B_(j+1,j) = 1 "
            "(everything broken out of a class is finer than its lower edge)"
        )
    # rise[i, j] = B_{i+1,j} - B_ij, kept where row i is itself below the diagonal
    rise = np.tril(B[1:] - B[:-1], -1)
    bad = np.argwhere(rise > 0)
    if bad.size:
        i, j = bad[0]
        raise BreakageError(
            f"B: {_entry(i + 1, j, xs)} is {float(B[i + 1, j])!r}, above {float(B[i, j])!r} for the coarser "
            f"{class_label(i, xs)}; B must not increase down a column"
        )
    return B


def validate_b(b, x=None, *, tol: float = COLUMN_TOL) -> np.ndarray:
    """Check a fractional breakage distribution b and return it as float array.

    Requires: square (N, N), finite, strictly lower triangular (so the sink column N
    is zero), b >= 0, and every column j < N summing to 1 within ``tol``.

    Raises
    ------
    BreakageError
        Naming the classes (1-based, with sizes if ``x`` is given) and the value.
    """
    b, xs = _square(b, x, "b")
    if (b < 0).any():
        i, j = np.argwhere(b < 0)[0]
        raise BreakageError(f"b: {_entry(i, j, xs)} is {float(b[i, j])!r}; expected >= 0")
    sums = b.sum(axis=0)
    bad = np.flatnonzero(np.abs(sums[:-1] - 1.0) > tol)
    if bad.size:
        j = bad[0]
        raise BreakageError(
            f"b: column of breaking {class_label(j, xs)} sums to {float(sums[j])!r}; expected 1 (tolerance {tol:g})"
        )
    return b


def evaluate_b(model, grid, *, tol: float = COLUMN_TOL) -> np.ndarray:
    """Evaluate any distribution model (callable ``x -> b`` or object with ``.b``) and check it."""
    x = as_sizes(grid)
    fun = getattr(model, "b", model)
    if not callable(fun):
        raise BreakageError(f"breakage model {model!r} is neither callable nor has a .b(x) method")
    return validate_b(fun(x), x, tol=tol)


# ------------------------------------------------------------------------ dataclasses
@dataclass(frozen=True)
class NormalizedBreakage:
    """Eq. 6 distribution: phi (x_{i-1}/x_j)^gamma + (1 - phi)(x_{i-1}/x_j)^beta.

    Normalized: B depends on sizes only through x_{i-1}/x_j, the same for every breaking
    class j.

    Parameters
    ----------
    phi : float
        Weight of the fine branch [-], in [0, 1].
    gamma, beta : float
        Exponents of the two branches [-], >= 0 (gamma < beta: gamma the fines).

    References
    ----------
    L. G. Austin, R. R. Klimpel and P. T. Luckie, Process Engineering of Size Reduction:
    Ball Milling (SME-AIME, New York, 1984), ch. 4.

    Examples
    --------
    >>> import numpy as np
    >>> from millflow.grid import SizeGrid
    >>> x = SizeGrid.geometric(4e-3, 2.0, 4).x
    >>> b = NormalizedBreakage(phi=0.5, gamma=0.9, beta=4.0).b(x)
    >>> np.allclose(b.sum(axis=0), [1, 1, 1, 0])  # every breaking class's fragments sum to 1
    True
    """

    phi: float
    gamma: float
    beta: float

    def __post_init__(self):
        _param(self.phi, "phi", 0.0, 1.0)
        _param(self.gamma, "gamma", 0.0)
        _param(self.beta, "beta", 0.0)

    def B(self, x) -> np.ndarray:
        """Cumulative B (N, N) on the sizes x [m]."""
        return normalized_B(x, self.phi, self.gamma, self.beta)

    def cumulative(self, x, y, top=None) -> np.ndarray:
        """Continuous B(x; y) [-] (:func:`continuous_B`); ``top`` is unused (eq. 6 has no x_max)."""
        return continuous_B(x, y, self.phi, self.gamma, self.beta)

    def b(self, x) -> np.ndarray:
        """Fractional b (N, N) on the sizes x [m]."""
        return b_from_B(self.B(x), x)

    __call__ = b


@dataclass(frozen=True)
class NonNormalizedBreakage:
    """Eq. 8 distribution with phi_j = phi0 (x_max/x_j)^theta; see :func:`non_normalized_B`.

    Whether phi_j stays in [0, 1] depends on the grid and is checked in ``B(x)``.
    """

    phi0: float
    gamma: float
    beta: float
    theta: float
    x_max: float | None = None

    def __post_init__(self):
        _param(self.phi0, "phi0", 0.0, 1.0)
        _param(self.gamma, "gamma", 0.0)
        _param(self.beta, "beta", 0.0)
        _param(self.theta, "theta")
        if self.x_max is not None and _param(self.x_max, "x_max", 0.0) <= 0:
            raise BreakageError(f"x_max = {self.x_max!r}: expected a size > 0 [m]")

    def B(self, x) -> np.ndarray:
        """Cumulative B (N, N) on the sizes x [m]."""
        return non_normalized_B(x, self.phi0, self.gamma, self.beta, self.theta, self.x_max)

    def cumulative(self, x, y, top=None) -> np.ndarray:
        """Continuous B(x; y) [-] (:func:`continuous_B`); x_max defaults to ``top``, the grid's top size [m]."""
        x_max = self.x_max if self.x_max is not None else top
        if self.theta != 0 and x_max is None:
            raise BreakageError("NonNormalizedBreakage.cumulative: x_max is not set; pass top= (the grid top [m])")
        return continuous_B(x, y, self.phi0, self.gamma, self.beta, self.theta, x_max)

    def b(self, x) -> np.ndarray:
        """Fractional b (N, N) on the sizes x [m]."""
        return b_from_B(self.B(x), x)

    __call__ = b


@dataclass(frozen=True, eq=False, init=False)
class TabulatedBreakage:
    """Form-free distribution: give exactly one of ``b`` or ``B`` as an (N, N) array.

    Validated on construction (``tol`` on column sums / B_{j+1,j}); the other matrix is
    derived. ``.b(x)`` and ``.B(x)`` check that the grid has N classes.
    """

    b_matrix: np.ndarray | None = None
    B_matrix: np.ndarray | None = None
    tol: float = COLUMN_TOL

    def __init__(self, b=None, B=None, tol: float = COLUMN_TOL):
        if (b is None) == (B is None):
            raise BreakageError("TabulatedBreakage: give exactly one of b= or B=")
        if b is not None:
            bm = validate_b(b, tol=tol)
            Bm = B_from_b(bm, tol=tol)
        else:
            Bm = validate_B(B, tol=tol)
            bm = b_from_B(Bm)
        for m in (bm, Bm):
            m.setflags(write=False)
        object.__setattr__(self, "b_matrix", bm)
        object.__setattr__(self, "B_matrix", Bm)
        object.__setattr__(self, "tol", tol)

    def _check(self, x) -> None:
        xs = as_sizes(x)
        if xs.size != self.b_matrix.shape[0]:
            raise BreakageError(
                f"TabulatedBreakage is {self.b_matrix.shape[0]} x {self.b_matrix.shape[0]}; "
                f"the grid has {xs.size} classes"
            )

    def b(self, x) -> np.ndarray:
        """Fractional b (N, N) [-] (a copy)."""
        self._check(x)
        return self.b_matrix.copy()

    def B(self, x) -> np.ndarray:
        """Cumulative B (N, N) [-] (a copy)."""
        self._check(x)
        return self.B_matrix.copy()

    __call__ = b

    def __repr__(self) -> str:
        return f"TabulatedBreakage(n={self.b_matrix.shape[0]})"
