"""Exact linear algebra for first-order breakage: the breakage matrix and its functions.

First-order breakage (eq. 4) is dM/dt = K M with the lower-triangular breakage matrix

    K = (b - I) diag(S),     K_ii = -S_i,   K_ij = b_ij S_j (i > j).

Every linear result of millflow is a function of this matrix applied to a feed vector:
exp(K t) f for batch grinding and plug flow, (I - tau K)^-1 f for a perfectly mixed
mill, E_hat(-K) f for any residence time distribution (segregated flow). This module
evaluates them without the failure of Reid's (1965) closed form, which divides by
S_i - S_j and loses everything when rates coincide.

Method (block eigen-decomposition). With A = -K (eigenvalues S_i >= 0), the rates are
grouped into clusters of nearly equal values (relative gap below the cluster gap).
A is then factored exactly as A = X D X^-1, X unit lower triangular with X = I on the
rows of each cluster, D lower triangular and block diagonal over the clusters (blocks
sit at the clusters' own, possibly scattered, indices). Row i of A X = X D gives the
recurrence

    x_i (D_<i - S_i I) = sum_{k<i} A_ik x_k          (i outside a cluster C)
    D_i = S_i e_i + sum_{k<i} A_ik x_k               (i inside C)

solved row by row. Columns of different clusters never divide by a difference smaller
than the gap times the rates, so X stays well conditioned; inside a cluster
the function of the small block D_C is evaluated directly: exp by a Taylor series on
the vector (finite for equal rates) or Taylor scaling and squaring of the block, a
general transform by a Taylor series about the cluster centre (:func:`contour_funm`).
The gap adapts to an a-posteriori cancellation estimate (:meth:`SpectralBlocks.decompose`).
For distinct rates (all clusters of size one) this reduces to Reid's eigenvectors,
computed stably, and each function value costs one O(N^2) product.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.linalg.lapack import dtrtrs

from millflow import compiled
from millflow.errors import SolverError

__all__ = ["breakage_matrix", "cluster_rates", "SpectralBlocks", "eigenvectors_distinct_population"]

#: Rates closer than this relative gap are treated as one cluster (first trial).
DEFAULT_CLUSTER_GAP = 1e-3
#: Gaps tried in turn until the cancellation estimate meets its target. Small first:
#: on fine grids (ratio 2^(1/16)) consecutive rates differ by a few percent, and a
#: large first gap would chain every class into one slow cluster.
GAP_SEQUENCE = (DEFAULT_CLUSTER_GAP, 0.05, 0.2, 0.8, np.inf)


def breakage_matrix(S: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Breakage matrix K = (b - I) diag(S) of eq. 4 [1/s].

    Parameters
    ----------
    S : (N,) specific breakage rates [1/s], S_N = 0 for the sink.
    b : (N, N) fractional breakage distribution, strictly lower triangular,
        b[i, j] = fraction of material broken out of class j that lands in class i.
    """
    S = np.asarray(S, dtype=float)
    b = np.asarray(b, dtype=float)
    K = b * S[np.newaxis, :]
    K[np.diag_indices_from(K)] = -S
    return K


def _minus_breakage_matrix(S: np.ndarray, b: np.ndarray) -> np.ndarray:
    """A = -K = (I - b) diag(S) in one pass (the decomposition works with A)."""
    A = b * -S
    A.flat[:: S.size + 1] = S
    return A


def cluster_rates(S: np.ndarray, gap: float = DEFAULT_CLUSTER_GAP) -> np.ndarray:
    """Label each class with its cluster of nearly equal rates.

    Two rates are close when |S_a - S_b| <= gap * max(S_a, S_b); clusters are the
    transitive closure of that relation over the sorted rates. Returns integer labels
    (N,) numbered 0.. in order of first appearance.
    """
    S = np.asarray(S, dtype=float)
    s_sorted = np.sort(S)
    if not (np.diff(s_sorted) <= gap * s_sorted[1:]).any():  # all distinct: the common case
        return np.arange(S.size)
    order = np.argsort(S, kind="stable")
    s_sorted = S[order]
    close = np.abs(np.diff(s_sorted)) <= gap * np.maximum(s_sorted[1:], s_sorted[:-1])
    sorted_labels = np.concatenate(([0], np.cumsum(~close)))
    labels = np.empty_like(sorted_labels)
    labels[order] = sorted_labels
    # renumber by first appearance so that labels read naturally from coarse to fine
    _, first = np.unique(labels, return_index=True)
    rank = np.empty(first.size, dtype=int)
    rank[np.argsort(first)] = np.arange(first.size)
    return rank[labels]


@dataclass(frozen=True)
class SpectralBlocks:
    """Block eigen-decomposition A = X D X^-1 of A = -K = (I - b) diag(S).

    Attributes
    ----------
    S : (N,) rates [1/s].
    X : (N, N) unit lower-triangular basis.
    labels : (N,) cluster label of each class.
    clusters : list of index arrays of clusters with more than one member.
    blocks : list of the lower-triangular blocks D_C of those clusters.
    """

    S: np.ndarray
    X: np.ndarray
    labels: np.ndarray
    clusters: list = field(default_factory=list)
    blocks: list = field(default_factory=list)
    gap: float = DEFAULT_CLUSTER_GAP
    kernel: str = "numpy"  # which implementation built X: "compiled" or "numpy"

    @classmethod
    def from_rates(
        cls, S, b, gap: float | None = None, *, feed=None, target: float = 1e-13, kernel: str | None = None
    ) -> "SpectralBlocks":
        """Decompose the breakage matrix of rates S [1/s] and distribution b.

        With ``gap=None`` the cluster gap adapts: it starts at 1e-3 and widens
        (0.05, 0.2, 0.8, then one cluster) until the cancellation estimate
        ``eps * max |X| |X^-1 f|`` is below ``target`` (for ``feed`` if given, else
        for the worst unit feed). One cluster is Taylor scaling and squaring of the
        whole Metzler matrix: slower, but accurate because no term cancels.
        ``kernel``: who runs the row recurrences (:func:`millflow.compiled.kernel`).
        """
        return cls.decompose(S, b, gap, feed=feed, target=target, kernel=kernel)[0]

    @classmethod
    def decompose(cls, S, b, gap: float | None = None, *, feed=None, target: float = 1e-13,
                  kernel: str | None = None):
        """As :meth:`from_rates`, also returning w = X^-1 feed and the cancellation
        estimate eps * max |X| |w| (None and the unit-feed estimate without a feed)."""
        S = np.asarray(S, dtype=float)
        A = _minus_breakage_matrix(S, np.asarray(b, dtype=float))
        module = compiled.kernel("eigenbasis", kernel)
        for trial in (gap,) if gap is not None else GAP_SEQUENCE:
            blocks = cls._build(A, S, trial, module)
            if feed is None:
                w, estimate = None, blocks.cancellation()
            else:
                w = blocks.coordinates(feed)
                estimate = float(np.finfo(float).eps * (np.abs(blocks.X) @ np.abs(w)).max())
                estimate = estimate if np.isfinite(estimate) else np.inf
            if estimate <= target:
                break
        return blocks, w, estimate

    @classmethod
    def _build(cls, A, S, gap, module=None):
        name = "numpy" if module is None else "compiled"
        labels = cluster_rates(S, gap) if np.isfinite(gap) else np.zeros(S.size, dtype=int)
        if labels.max(initial=-1) + 1 == S.size:  # as many clusters as classes: all singletons
            return cls(S=S, X=_eigenvectors_distinct(A, S, module), labels=labels, gap=gap, kernel=name)
        X, cc, D_cc = _block_basis(A, S, labels, module)
        # clusters in index order of their members, from one stable sort of the labels
        order = np.argsort(labels[cc], kind="stable")
        bounds = np.cumsum(np.bincount(labels[cc])[np.unique(labels[cc])])[:-1]
        clusters, blocks = [], []
        for local in np.split(order, bounds):  # positions within cc
            clusters.append(cc[local])
            blocks.append(D_cc[np.ix_(local, local)])
        return cls(S=S, X=X, labels=labels, clusters=clusters, blocks=blocks, gap=gap, kernel=name)

    def cancellation(self, v: np.ndarray | None = None) -> float:
        """Rounding-error estimate eps * max_i (|X| |X^-1 v|)_i for a feed v (default:
        the worst unit feed, i.e. eps * max |X| |X^-1|). It bounds the absolute error
        of every function value computed through this basis, for |v| <= 1."""
        eps = np.finfo(float).eps
        if v is None:
            Xinv = self.coordinates(np.eye(self.n))
            return float(eps * (np.abs(self.X) @ np.abs(Xinv)).max()) if np.isfinite(Xinv).all() else np.inf
        w = self.coordinates(v)
        return float(eps * (np.abs(self.X) @ np.abs(w)).max()) if np.isfinite(w).all() else np.inf

    def summary(self) -> dict:
        """What a result reports of the decomposition: cluster gap, sizes of the
        multi-member clusters, and which kernel ran the row recurrences."""
        return {"cluster_gap": float(self.gap), "cluster_sizes": [int(c.size) for c in self.clusters],
                "kernel": self.kernel}

    @property
    def n(self) -> int:
        return self.S.size

    def coordinates(self, v: np.ndarray) -> np.ndarray:
        """w = X^-1 v (one unit lower-triangular solve); v may be (N,) or (N, m)."""
        return dtrtrs(self.X, v, lower=1, unitdiag=1)[0]  # unit diagonal: never singular

    def expm_apply(self, v: np.ndarray, t: np.ndarray, *, w: np.ndarray | None = None) -> np.ndarray:
        """exp(-A t) v = exp(K t) v for each time in t; returns (T, N).

        ``w = X^-1 v`` may be passed when it is already known."""
        t = np.atleast_1d(np.asarray(t, dtype=float))
        if w is None:
            w = self.coordinates(v)
        # singleton clusters: exp(-S_j t) w_j, underflow to zero is exact enough
        coeff = np.exp(-np.outer(t, self.S)) * w[np.newaxis, :]
        for members, blocks in self._clusters_by_size():
            coeff[:, members] = _blocks_expm_apply(blocks, t, w[members])
        return coeff @ self.X.T

    def _clusters_by_size(self):
        """Clusters grouped by size: (members (k, p), blocks (k, p, p)) per size p."""
        sizes = sorted({idx.size for idx in self.clusters})
        for p in sizes:
            pick = [k for k, idx in enumerate(self.clusters) if idx.size == p]
            yield (np.array([self.clusters[k] for k in pick]), np.array([self.blocks[k] for k in pick]))


def kernel_name(kernel: str | None = None) -> str:
    """Which implementation runs the row recurrences for ``kernel``: "compiled" or "numpy"."""
    return "compiled" if compiled.kernel("eigenbasis", kernel) is not None else "numpy"


def _eigenvectors_distinct(A: np.ndarray, S: np.ndarray, module=None) -> np.ndarray:
    """Unit lower-triangular eigenvector matrix of A for well separated rates.

    Column j solves (A - S_j I) x = 0 with x_j = 1: for i > j,
    x_i = sum_{k<i} A_ik x_k / (S_j - S_i), row by row (this recurrence is the cost
    of a batch solve). Runs in ``module`` (the compiled kernel) when given, else numpy.
    """
    if module is None:
        return _eigenvectors_distinct_numpy(A, S)
    X = np.eye(S.size)
    module.distinct(np.ascontiguousarray(A), np.ascontiguousarray(S), X)
    return X


def _eigenvectors_distinct_numpy(A: np.ndarray, S: np.ndarray) -> np.ndarray:
    """:func:`_eigenvectors_distinct` in numpy: one member of
    :func:`eigenvectors_distinct_population` (the reference and the fallback)."""
    return _eigenvectors_population_numpy(A[np.newaxis], S[np.newaxis])[0]


def _eigenvectors_population_numpy(A: np.ndarray, S: np.ndarray) -> np.ndarray:
    """The numpy row recurrence for a population: A (P, N, N), S (P, N) -> X (P, N, N).

    Row i of every member at once, vectorised over the columns j < i, written in place:
    x_ij = (A_i,<i X_<i,j) / (S_j - S_i). Equal rates give inf or NaN (callers route
    such members to the clustered method first).
    """
    n_pop, n = S.shape
    X = np.zeros((n_pop, n, n))
    X[:, np.arange(n), np.arange(n)] = 1.0
    gaps = S[:, np.newaxis, :] - S[:, :, np.newaxis]  # gaps[p, i, j] = S_j - S_i
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        for i in range(1, n):
            r = np.matmul(A[:, i:i + 1, :i], X[:, :i, :i])[:, 0]
            np.divide(r, gaps[:, i, :i], out=X[:, i, :i])
    return X


def eigenvectors_distinct_population(A: np.ndarray, S: np.ndarray, kernel: str | None = None) -> np.ndarray:
    """Unit lower-triangular eigenvectors X (P, N, N) of A = -K for P members at once.

    A (P, N, N) = (I - b) diag(S) per member, S (P, N) rates with no two (nearly) equal
    (callers check, see :func:`millflow.batch.batch_grind_population`). The same row
    recurrence as :func:`_eigenvectors_distinct`: the compiled kernel member by member
    when it is available (``kernel`` as :func:`millflow.compiled.kernel`), else numpy
    vectorised over the population.
    """
    A = np.asarray(A, dtype=float)
    S = np.asarray(S, dtype=float)
    module = compiled.kernel("eigenbasis", kernel)
    if module is None:
        return _eigenvectors_population_numpy(A, S)
    n_pop, n = S.shape
    X = np.zeros((n_pop, n, n))
    X[:, np.arange(n), np.arange(n)] = 1.0
    A = np.ascontiguousarray(A)
    S = np.ascontiguousarray(S)
    for k in range(n_pop):
        module.distinct(A[k], S[k], X[k])
    return X


def _block_basis(A: np.ndarray, S: np.ndarray, labels: np.ndarray, module=None):
    """Basis X and, on the clustered indices cc, the block-diagonal D_cc (returns
    X, cc, D_cc) for clustered rates (see module docstring and
    :func:`_block_basis_numpy`). Runs in ``module`` (the compiled kernel) when given.
    """
    if module is None:
        return _block_basis_numpy(A, S, labels)
    labels = np.ascontiguousarray(labels, dtype=np.int64)
    counts = np.bincount(labels)
    cc = np.flatnonzero(counts[labels] > 1).astype(np.int64)
    X = np.eye(S.size)
    D_cc = np.diag(S[cc])
    module.clustered(np.ascontiguousarray(A), np.ascontiguousarray(S), X, cc, labels, D_cc)
    return X, cc, D_cc


def _block_basis_numpy(A: np.ndarray, S: np.ndarray, labels: np.ndarray):
    """:func:`_block_basis` in numpy (the reference and the fallback).

    Row i: r = A[i, :i] X[:i, :i]. Singleton columns divide by S_j - S_i. The
    columns of all multi-member clusters together form a compact lower-triangular
    system x (D_cc - S_i I) = r_c, solved once per row; the row's own cluster is
    decoupled (unit diagonal, zero right-hand side) and receives the row of D.
    """
    n = S.size
    X = np.eye(n)
    counts = np.bincount(labels)
    single = counts[labels] == 1
    cc = np.flatnonzero(~single)  # clustered columns, in index order
    pos = np.full(n, -1)
    pos[cc] = np.arange(cc.size)
    D_cc = np.diag(S[cc])  # D restricted to clustered indices (block diagonal)
    label_cc = labels[cc]
    # per-row constants, hoisted out of the loop (it runs N times in Python)
    gaps = S[np.newaxis, :] - S[:, np.newaxis]  # gaps[i, j] = S_j - S_i
    gaps[:, cc] = np.inf  # clustered columns get 0 from the division, then their solve
    n_before = np.searchsorted(cc, np.arange(n))  # clustered columns < i
    # per clustered row: positions (among cc[:k]) of the earlier members of its cluster
    own_pos = [None] * n
    for i in cc:
        own_pos[i] = np.flatnonzero(label_cc[: n_before[i]] == labels[i])
    for i in range(1, n):
        xi = X[i, :i]  # the row is written in place
        r = A[i, :i] @ X[:i, :i]
        np.divide(r, gaps[i, :i], out=xi)
        k = n_before[i]
        if not k:
            continue
        idx = cc[:k]
        rc = r[idx]
        own = own_pos[i]
        if own is not None:
            D_cc[pos[i], own] = rc[own]
            rc[own] = 0.0
        if not rc.any():
            continue
        M = D_cc[:k, :k].copy(order="F")  # Fortran order: f2py would copy again
        M.flat[:: k + 1] -= S[i]
        if own is not None:
            M.flat[own * (k + 1)] = 1.0  # own cluster: decoupled, zero right-hand side
        # LAPACK directly: scipy.linalg.solve_triangular costs ~90 us a call in scipy
        # 1.17, dtrtrs ~6 us, and this runs once per row
        xi[idx] = dtrtrs(M, rc, lower=1, trans=1)[0]
    return X, cc, D_cc


def _blocks_expm_apply(blocks: np.ndarray, t: np.ndarray, w: np.ndarray) -> np.ndarray:
    """exp(-B_k t) w_k for k clusters of equal size p and each t: (T, k, p).

    A cluster has diagonal entries close to their mean mu, so B = mu I + Delta + L
    (Delta small diagonal, L strictly lower). Where |Delta| t <= 1 the Taylor series
    of exp(-(Delta + L) t) applied to exp(-mu t) w is summed on the vector: L is
    nilpotent, so the series ends after about p terms plus a few for Delta, and for
    breakage -L >= 0, so the terms do not cancel. Elsewhere each block is
    exponentiated by scaling and squaring (:func:`_block_expm`).
    """
    k, p, _ = blocks.shape
    diag = np.diagonal(blocks, axis1=1, axis2=2)
    mu = diag.mean(axis=1)
    spread = np.abs(diag - mu[:, np.newaxis]).max(axis=1)
    G = -(blocks - mu[:, np.newaxis, np.newaxis] * np.eye(p))
    out = np.empty((t.size, k, p))
    tight = spread.max() * t <= 1.0
    if tight.any():
        out[tight] = _tight_block_series(G, mu, t[tight], w)
    loose = np.flatnonzero(~tight)
    if loose.size:  # one scaling-and-squaring per block for all its loose times (same arithmetic per time)
        # |exp(-B t)| <= exp(-d_min t) sum_{m<p} (|L| t)^m / m! entrywise (B = D + L lower
        # triangular, L nilpotent): where that is below e^-800 (under the smallest
        # subnormal, 5e-324, by far) the block's contribution is zero in double precision
        d_min = diag.min(axis=1)
        lower = np.abs(np.tril(blocks, -1)).sum(axis=1).max(axis=1)
        for c in range(k):
            tl = t[loose]
            log_bound = -d_min[c] * tl + np.log(p) + (p - 1) * np.log(np.maximum(1.0, lower[c] * tl))
            log_bound += np.log(max(float(np.abs(w[c]).sum()), 1e-300))
            zero = log_bound < -800.0
            out[loose[zero], c] = 0.0
            if (~zero).any():
                out[loose[~zero], c] = _block_expm(blocks[c], tl[~zero]) @ w[c]
    return out


def _tight_block_series(G: np.ndarray, mu: np.ndarray, t: np.ndarray, w: np.ndarray) -> np.ndarray:
    """sum_n (G t)^n exp(-mu t) w / n!, for k blocks G (k, p, p) and times t; (T, k, p)."""
    term = np.exp(-np.outer(mu, t))[:, np.newaxis, :] * w[:, :, np.newaxis]  # (k, p, T)
    total = term.copy()
    growth = np.abs(G).sum(axis=1).max() * t.max()
    p = G.shape[1]
    for n in range(1, 10 * p + 200):
        term = np.matmul(G, term)
        term *= t / n
        total += term
        # past n = p the nilpotent part is spent and, with |Delta| t <= 1, terms only
        # shrink; before that, a small term may still grow (Poisson-like) until n ~ |G t|
        if (n >= p or n >= growth) and np.abs(term).max() <= 1e-18 * max(np.abs(total).max(), 1e-300):
            break
    return total.transpose(2, 0, 1)


def _block_expm(block: np.ndarray, t: np.ndarray) -> np.ndarray:
    """exp(-block t) for each t: (T, p, p), by Taylor series with scaling and squaring.

    The block of a cluster has nearly equal diagonal entries mu and, for breakage, a
    non-negative strictly lower part of -block, so the shifted Taylor terms
    (-(block - mu I) h)^k / k! barely cancel; scipy.linalg.expm's Pade step loses up
    to 1e-9 on such nilpotent-dominated blocks, this loses ~1e-15. The factor
    exp(-mu h) stays inside the squaring so that nothing overflows when mu t is huge.
    """
    p = block.shape[0]
    mu = float(np.mean(np.diag(block)))
    shifted = block - mu * np.eye(p)
    norm = np.abs(shifted).sum(axis=0).max()
    squarings = np.maximum(0, np.ceil(np.log2(np.maximum(norm * t, 1e-300)))).astype(int)
    h = t / 2.0 ** squarings
    # times that share the scaled step h (t_j = t_i 2^m, e.g. geometric sampling times:
    # division by 2^s is exact) share the Taylor part, and the squaring chain of the
    # longer passes through the shorter: each is computed once (the same operations
    # per time as separately)
    steps, which = np.unique(h, return_inverse=True)
    which = which.ravel()
    E = -shifted[np.newaxis] * steps[:, np.newaxis, np.newaxis]
    term = np.broadcast_to(np.eye(p), E.shape).copy()
    base = term.copy()
    for k in range(1, 19):  # |E| <= 1: 18 terms reach 1/19! ~ 8e-18
        term = term @ E / k
        base += term
    base *= np.exp(-mu * steps)[:, np.newaxis, np.newaxis]
    total = np.empty((t.size, p, p))
    for u in range(steps.size):
        members = np.flatnonzero(which == u)
        members = members[np.argsort(squarings[members], kind="stable")]
        M, level = base[u], 0
        for m in members:
            while level < squarings[m]:
                M = M @ M
                level += 1
            total[m] = M
    return total


def contour_funm(fun, block: np.ndarray, n_points: int = 64, *, analytic_left: float = 0.0,
                 radius_factor: float = 0.9, v: np.ndarray | None = None) -> np.ndarray:
    """fun(block) for a small lower-triangular block with clustered eigenvalues.

    Taylor series about the centre c of the diagonal's range, f(B) = sum_k c_k
    ((B - c I)/r)^k, summed by Horner on the block; the scaled Taylor coefficients
    c_k = f^(k)(c) r^k / k! come from the Cauchy integral on the circle |z - c| = r,
    evaluated by the trapezoidal rule (one FFT of fun on the circle). The radius is
    r = radius_factor * rho, rho = c - analytic_left the distance to the half plane
    where fun may be singular (0 for any Laplace transform of a density: analytic and
    |E_hat(z)| <= 1 for Re z > 0), so the coefficients are accurate to
    eps * max|f| / radius_factor^k and aliasing (radius_factor^n_points) is negligible
    with >= 512 points. Unlike a resolvent integral on a small circle, this does not
    amplify rounding by (|N| / r)^k for the nilpotent part N of the block (breakage
    makes |N| ~ c): for a completely monotone transform and breakage (N <= 0) the terms
    do not cancel. The half-range of the diagonal must stay below 0.75 r (else
    SolverError: the cluster is too wide for one Taylor series).

    Parameters
    ----------
    fun : vectorised scalar function accepting complex arrays.
    block : (p, p) lower-triangular block.
    n_points : minimum number of points on the circle (raised to >= 512 if needed).
    analytic_left : fun is analytic for Re z > analytic_left (-inf for entire fun).
    radius_factor : r / rho, in (0, 1); two factors give two independent evaluations
        whose difference estimates the rounding error.
    v : (p,) or (p, m), optional: return f(block) v, Horner on the vectors (p^2 per
        term instead of p^3). fun must be real on the real axis (coefficients real).
    """
    block = np.asarray(block, dtype=float)
    p = block.shape[0]
    ev = np.diag(block).copy()
    if not np.tril(block, -1).any():
        diag = np.real(np.asarray(fun(ev.astype(complex)), dtype=complex))
        if v is None:
            return np.diag(diag)
        v = np.asarray(v, dtype=float)
        return (diag if v.ndim == 1 else diag[:, np.newaxis]) * v
    centre = 0.5 * float(ev.max() + ev.min())
    half = 0.5 * float(ev.max() - ev.min())
    G = block - centre * np.eye(p)
    if np.isfinite(analytic_left):
        r = radius_factor * (centre - float(analytic_left))
    else:  # entire function: a circle wide enough for the block's norm
        r = max(2.0 * float(np.abs(G).sum(axis=0).max()), abs(centre), 1e-300)
    if r <= 0 or half > 0.75 * r:
        raise SolverError(
            f"contour_funm: eigenvalues {ev.min():.3g}..{ev.max():.3g} are too spread for a Taylor "
            f"series inside the analytic region Re z > {analytic_left:.3g}")
    eps = np.finfo(float).eps
    extra = int(np.ceil(np.log(eps) / np.log(half / r))) if half > 0 else 0
    terms = p + min(extra, 400)
    n = max(int(n_points), 512)
    while n < 4 * terms:
        n *= 2
    theta = 2.0 * np.pi * np.arange(n) / n
    values = np.asarray(fun(centre + r * np.exp(1j * theta)), dtype=complex)
    coeffs = np.fft.fft(values)[: terms + 1] / n
    Gs = G / r
    if v is not None:  # f real on the real axis: Taylor coefficients about c are real
        v = np.asarray(v, dtype=float)
        c = coeffs.real
        out = c[terms] * v
        for k in range(terms - 1, -1, -1):
            out = Gs @ out + c[k] * v
        return out
    result = coeffs[terms] * np.eye(p, dtype=complex)
    for k in range(terms - 1, -1, -1):
        result = result @ Gs
        result[np.diag_indices(p)] += coeffs[k]
    return result.real
