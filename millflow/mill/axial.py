"""Axial dispersion mill: steady convection-dispersion-breakage along the mill axis.

With z = y/L in [0, 1], time in units of tau = L/u and c_i(z) the hold-up density of
class i (mass per unit length, per unit feed rate, times u), the steady state is

    d/dz [ v_i c_i - (w_i/Pe) dc_i/dz ] = -tau S_i c_i + tau sum_{j<i} b_ij S_j c_j,

with Danckwerts (closed vessel) boundaries: v_i c_i - (w_i/Pe) c_i' = f_i at z = 0 and
c_i' = 0 at z = 1, so the product is p_i = v_i c_i(1). v_i = d_i* is the relative
axial velocity of class i (classification along the axis: d_i* < 1 for a class that
travels more slowly than the water), w_i its relative dispersion (default 1). The
hold-up per unit feed rate is tau int_0^1 c_i dz [s]. With v = w = 1 the product
equals segregated flow with the Wehner-Wilhelm transform; with v = w = d* it equals
segregated flow with rates S/d* (every transport time of class i scaled by 1/d_i*).

Discretisation (vertex-centred finite volumes): nodes z_k = k h, h = 1/M, control
volumes of width h (h/2 at the two ends). Fluxes between nodes by exponential fitting
(Scharfetter-Gummel / Il'in-Allen-Southwell, :mod:`millflow.mill.finite_volume`),

    F_{k+1/2} = (D/h) [B(-P) c_k - B(P) c_{k+1}],   D = w/Pe,  P = v h / D,
    B(x) = x / (exp(x) - 1),

which is exact for convection-dispersion without breakage at any cell Peclet number
and gives a column-diagonally dominant M-matrix, so concentrations stay non-negative
for every Pe. Breakage is lumped at the nodes (trapezoidal rule). Conservation is
exact: fluxes cancel between volumes and columns of b sum to one, so sum(product)
equals sum(feed) to rounding. Error O(h^2) when the cell Peclet number v h Pe / w is
small; where it is large the scheme tends to upwinding (first order) until the grid
resolves 1/Pe. The grid is refined by doubling until the Richardson estimate
|p_2M - p_M| / (2^q - 1) (q the observed order, at least 1) is below the tolerance.

Each class is one tridiagonal solve (classes couple only downward, b strictly lower
triangular): N solves of size M + 1 plus O(N^2 M) for the breakage sources. The LU
factors are computed without subtractions from the column sums of the M-matrix
(:func:`_gth_factors`), so every Pe in (0, inf) is solved to rounding: as Pe -> 0 the
dispersion terms grow as 1/Pe and the ordinary pivots would cancel (at Pe = 1e-8 they
created 68 % extra mass). Below Pe v/w = 1e-250, where 1/Pe would overflow, the mill is
the perfectly mixed one (eq. 3 with rates S/v) to within Pe sum(f).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import lapack

from millflow.errors import SolverError
from millflow.mill.finite_volume import bernoulli as _bernoulli  # noqa: F401 (the name the benchmarks' baseline imports)
from millflow.mill.finite_volume import closed_faces, node_losses, tridiagonal

__all__ = ["AxialSolution", "solve_axial_grid", "solve_axial", "refine_grids"]


@dataclass(frozen=True)
class AxialSolution:
    """Steady axial-dispersion mill on a grid of M + 1 nodes.

    Attributes
    ----------
    product : (N,) or (N, m) discharge flows.
    z : (M + 1,) node positions [fraction of the mill length].
    density : (M + 1, N) or (M + 1, N, m) hold-up density tau c_i(z): hold-up per unit
        feed rate per unit fractional length [s]; its integral over z is the hold-up.
    holdup : (N,) or (N, m) hold-up per unit feed rate [s].
    error_estimate : Richardson estimate of the max abs error of ``product`` and of
        ``holdup`` / tau (both are refined until it is below the tolerance).
    order : observed order of convergence (nan if one grid only).
    history : list of (M, max |p_M - p_{M/2}|).
    """

    product: np.ndarray
    z: np.ndarray
    density: np.ndarray
    holdup: np.ndarray
    error_estimate: float
    order: float
    history: list = field(default_factory=list)


_gttrs = lapack.get_lapack_funcs("gttrs", dtype=np.float64)
_gtsv = lapack.get_lapack_funcs("gtsv", dtype=np.float64)


def _gth_factors(alpha: np.ndarray, beta: np.ndarray, loss: np.ndarray) -> np.ndarray:
    """Pivots d'_k (N, M + 1) of the LU factors of each class's tridiagonal M-matrix.

    Matrix of class i: diagonal l_k + alpha_k [k < M] + beta_(k-1) [k > 0], sub-diagonal
    -alpha_(k-1), super-diagonal -beta_k (alpha_k, beta_k of the face between nodes k and
    k + 1: scalars per class or (N, M) arrays), so column k sums to l_k >= 0 (``loss``).
    Eliminating node k-1 keeps that form with reduced column sums l'_k = l_k +
    beta_(k-1) l'_(k-1) / d'_(k-1) and pivots d'_k = l'_k + alpha_k [k < M]: only additions,
    products and divisions of non-negative numbers (Grassmann-Taksar-Heyman), where the
    usual pivot d_k - alpha beta / d'_(k-1) cancels catastrophically when alpha, beta >> l
    (small Pe).
    """
    n_cls, n = loss.shape
    alpha = np.broadcast_to(np.asarray(alpha, dtype=float).reshape(n_cls, -1), (n_cls, max(n - 1, 1)))
    beta = np.broadcast_to(np.asarray(beta, dtype=float).reshape(n_cls, -1), (n_cls, max(n - 1, 1)))
    piv = np.empty((n_cls, n))
    red = loss[:, 0].copy()  # l'_0
    for k in range(n):
        if k:
            red = loss[:, k] + beta[:, k - 1] * red / piv[:, k - 1]
        piv[:, k] = red + (alpha[:, k] if k < n - 1 else 0.0)
    return piv


def solve_axial_grid(S, b, feed, tau: float, pe: float, m_cells: int, d=None, w=None):
    """Concentrations c (M + 1, N[, m]) and product on one grid of ``m_cells`` volumes.

    Parameters as :func:`solve_axial`. Returns (z, c, product). The product is taken
    from the discrete balance of each class, p_i = f_i - sum_k w_k tau (S_i c_ik -
    sum_j b_ij S_j c_jk) (equal to v_i c_i(1) up to the rounding of the tridiagonal
    solves), so that sum(p) = sum(f) to rounding whatever the conditioning.
    """
    S = np.asarray(S, dtype=float)
    n_cls = S.size
    feed = np.asarray(feed, dtype=float)
    cols = feed.shape[1:]
    v = np.ones(n_cls) if d is None else np.asarray(d, dtype=float)  # relative axial velocity v_i = d_i*
    w = np.ones(n_cls) if w is None else np.asarray(w, dtype=float)
    M = int(m_cells)
    faces = closed_faces(pe, M, v, w)
    weights = faces.weights
    # Column sums of each class's matrix (what leaves the system from node k): breakage
    # tau S_i w_k, and the discharge v_i at the last node. The LU factors come from them
    # by the subtraction-free recurrence of _gth_factors, so every pivot keeps its
    # relative accuracy however large the dispersion terms D/h are (Pe -> 0).
    loss = node_losses(faces, v, tau * S)
    # Cancellation in the ordinary pivots grows as (D/h)/v = 1/P; above 1e3 (small cell
    # Peclet numbers) the subtraction-free factors are used, below it LAPACK's (faster
    # here: the Python loop of _gth_factors costs ~1 us per node).
    gth = float(1.0 / faces.cell_peclet.min()) > 1e3  # max(1/P), without an (N, M) array
    piv = _gth_factors(faces.alpha, faces.beta, loss) if gth else None
    lower, diag, upper = tridiagonal(faces, loss, overwrite_loss=True)
    if gth:  # L's sub-diagonal -alpha/d'_(k-1): y_k = r_k + (alpha / d'_(k-1)) y_(k-1),
        # in the memory of A's diagonal (which these factors do not use: one (N, M) array less)
        sub = np.divide(lower, piv[:, :-1], out=diag[:, :-1])
    c = np.empty((n_cls, M + 1) + cols)
    wc = np.empty((n_cls, (M + 1) * int(np.prod(cols, dtype=int))))  # weights * c, flattened
    gain = tau * b * S[np.newaxis, :]  # gain[i, j] = tau b_ij S_j
    wk = weights.reshape((M + 1,) + (1,) * len(cols))
    du2 = np.zeros(max(M - 1, 0))
    ipiv = np.arange(1, M + 2, dtype=np.int32)  # no row exchanges: the factors are an M-matrix's
    for i in range(n_cls):
        # breakage into class i from every coarser class: one matrix-vector product
        rhs = (gain[i, :i] @ wc[:i]).reshape((M + 1,) + cols) if i else np.zeros((M + 1,) + cols)
        rhs[0] += feed[i]
        if gth:
            c_i, info = _gttrs(sub[i], piv[i], upper[i], du2, ipiv, rhs if cols else rhs[:, np.newaxis])
        else:
            _, _, _, c_i, info = _gtsv(lower[i], diag[i], upper[i], rhs if cols else rhs[:, np.newaxis])
        if info != 0:
            raise SolverError(f"axial dispersion: tridiagonal solve failed for class {i + 1} (info {info})")
        c_i = c_i if cols else c_i[:, 0]
        c[i] = c_i
        wc[i] = (wk * c_i).ravel()
    # discharge of each class: v_i c_i(1), non-negative. With the subtraction-free factors
    # it is accurate to rounding per class, and the mass balance closes to rounding. With
    # LAPACK's it is taken from the discrete balance of each class, p_i = f_i - tau
    # (lost_i - gained_i) (exact conservation by construction), except where rounding
    # would make that negative.
    vk = v.reshape((n_cls,) + (1,) * len(cols))
    product = vk * c[:, -1]
    if not gth:
        lost = (S[:, np.newaxis] * wc).reshape((n_cls, M + 1) + cols).sum(axis=1)
        gained = np.tensordot(b, lost, axes=([1], [0]))
        balance = feed - tau * (lost - gained)
        product = np.where(balance >= 0, balance, product)
    return faces.z, np.moveaxis(c, 1, 0), product


def solve_axial(S, b, feed, tau: float, pe: float, d=None, w=None, *, tol: float = 1e-8,
                m_start: int = 16, m_max: int = 16384, m_cells: int | None = None) -> AxialSolution:
    """Steady axial-dispersion mill with optional size-dependent velocity and dispersion.

    Grids of M, 2M, 4M, ... control volumes. From three successive grids the observed
    order q = log2(|p_2M - p_M| / |p_4M - p_2M|); when it is close to an integer
    is 2 and stable and the cell Peclet number v h Pe / w <= 1, the product is
    Richardson-extrapolated, r = p_4M + (p_4M - p_2M) / 3, and the error
    estimate is |r - r_prev| (r_prev the same extrapolation one grid coarser, so the
    estimate is conservative); otherwise the finest product is returned with the
    estimate |p_4M - p_2M| / (2^q - 1). Refinement stops when the estimate is below
    ``tol`` or at ``m_max`` (then ``converged`` in the history is False). Profiles
    and hold-up are those of the finest grid (second order).

    Parameters
    ----------
    S : (N,) rates [1/s]; b : (N, N) fractional breakage distribution.
    feed : (N,) or (N, m) feed flows.
    tau : L/u [s]; pe : Peclet number u L / D [-].
    d, w : (N,) classification d_i* (the relative axial velocity of class i) and relative
        dispersion of each class (default 1).
    tol : target of the error estimate (max abs error of the product).
    m_start, m_max : first and largest number of control volumes.
    m_cells : solve on this one grid only (no refinement, error estimate nan).
    """
    n_cls = np.asarray(S).size
    v_arr = np.ones(n_cls) if d is None else np.asarray(d, float)
    w_arr = np.ones(n_cls) if w is None else np.asarray(w, float)
    if pe * float(np.min(v_arr / w_arr)) < PE_MIXED:
        return _perfectly_mixed_limit(S, b, feed, tau, pe, v_arr, w_arr)
    if m_cells is None and large_peclet_applies(pe, v_arr, w_arr, m_max):
        # the finest grid cannot resolve 1/Pe: the plug-flow limit and its 1/Pe terms
        def at(pe_j, tol_j):
            return solve_axial(S, b, feed, tau, pe_j, d, w, tol=tol_j, m_start=m_start, m_max=m_max)

        return large_peclet_limit(at, S, b, feed, tau, pe, v_arr, w_arr, tol=tol, m_max=m_max)
    if m_cells is not None:
        z, c, p = solve_axial_grid(S, b, feed, tau, pe, m_cells, d, w)
        return AxialSolution(p, z, tau * c, _holdup(z, tau * c), float("nan"), float("nan"), [])
    ratio = v_arr / w_arr

    def grid(M):
        # refined on what is reported: the product and the hold-up in units of tau
        z, c, p = solve_axial_grid(S, b, feed, tau, pe, M, d, w)
        return z, c, np.concatenate([p, _holdup(z, c)])

    cols = int(np.prod(np.shape(feed)[1:], dtype=int))
    both, estimate, order, history, finest, _, _ = refine_grids(
        grid, float(ratio.max()) * pe, tol=tol, m_start=m_start, m_max=m_max,
        bytes_per_cell=8.0 * 6 * n_cls * cols)  # c, w c, tau c and three kept grids
    z, c, _ = finest
    fv = AxialSolution(both[:n_cls], z, tau * c, tau * both[n_cls:], estimate, order, history)
    if estimate > tol and large_peclet_nodes_valid(pe, v_arr, w_arr, m_max):
        def at_nodes(pe_j, tol_j):
            return solve_axial(S, b, feed, tau, pe_j, d, w, tol=tol_j, m_start=m_start, m_max=m_max)

        return better_of_fv_and_limit(
            fv, lambda: large_peclet_limit(at_nodes, S, b, feed, tau, pe, v_arr, w_arr, tol=tol, m_max=m_max), tol)
    return fv


#: Share of the memory budget (MILLFLOW_MEMORY_BUDGET_GB) the finite-volume grids may hold:
#: a transfer matrix solves N columns at once, (M + 1) N^2 numbers per grid.
FV_MEMORY_SHARE = 0.25


def refine_grids(solve_grid, cell_pe: float, *, tol: float, m_start: int, m_max: int,
                 bytes_per_cell: float = 0.0):
    """Grids of M, 2M, 4M, ... volumes until the error estimate of the product is below ``tol``.

    ``solve_grid(M)`` returns a tuple whose third item is the product on that grid;
    ``cell_pe`` is the largest v Pe / w (the cell Peclet number of a grid is cell_pe / M).
    From three successive grids the observed order q = log2(|p_2M - p_M| / |p_4M - p_2M|);
    when it is 2 and stable and the cell Peclet number <= 1 the product is
    Richardson-extrapolated (estimate: the change of the extrapolation since the previous
    grid), otherwise the finest product is taken with the estimate |p_4M - p_2M| / (2^q - 1).
    ``bytes_per_cell``: what one volume of a grid costs in memory (every array the solve and
    the kept grids hold); refinement stops before a grid would exceed
    :data:`FV_MEMORY_SHARE` of the memory budget (the history says so, the estimate stays).
    Returns (product >= 0, estimate, order, history, finest grid's tuple, the one before,
    extrapolated: True when the product is the Richardson extrapolation).
    """
    from millflow.grid import memory_budget_bytes

    limit = FV_MEMORY_SHARE * memory_budget_bytes()
    M = int(m_start)
    grids = [solve_grid(M * k) for k in (1, 2)]
    history = [(M, float("nan")), (2 * M, float(np.abs(grids[1][2] - grids[0][2]).max()))]
    r_prev = None
    order_prev = float("nan")
    M *= 2
    while True:
        M *= 2
        grids = [grids[-2], grids[-1], solve_grid(M)]
        p1, p2, p3 = (g[2] for g in grids)
        d1, d2 = float(np.abs(p2 - p1).max()), float(np.abs(p3 - p2).max())
        history.append((M, d2))
        order = float(np.log2(d1 / d2)) if d1 > 0 and d2 > 0 else float("nan")
        # extrapolate only in the asymptotic range: the order near an integer and
        # unchanged since the previous refinement
        stable = np.isfinite(order) and abs(order - order_prev) < 0.1
        # and the cell Peclet number <= 1 (the exponentially fitted fluxes are then
        # central differences to O(P^2) and the error expands in h^2)
        q = 2 if stable and abs(order - 2.0) < 0.15 and cell_pe / M <= 1.0 else None
        order_prev = order
        if d2 == 0.0:
            product, estimate = p3, 0.0
        elif q is not None:
            r = p3 + (p3 - p2) / (2.0**q - 1.0)
            r_coarse = p2 + (p2 - p1) / (2.0**q - 1.0)
            ref = r_prev if r_prev is not None else r_coarse
            product, estimate = r, float(np.abs(r - ref).max())
            r_prev = r
        else:
            product, estimate = p3, d2 / (2.0 ** max(order if np.isfinite(order) else 1.0, 1.0) - 1.0)
            r_prev = None
        converged = estimate <= tol
        if converged or 2 * M > m_max:
            break
        if bytes_per_cell * (2 * M + 1) > limit:
            history.append(("memory budget", 2 * M))
            break
    product = np.maximum(product, 0.0)  # extrapolation may dip below 0 by < estimate
    history.append(("converged", bool(converged)))
    return product, float(estimate), order, history, grids[-1], grids[-2], q is not None and d2 != 0.0


#: Below this Pe v/w the mill is solved as its Pe -> 0 limit (1/Pe would overflow on fine grids).
PE_MIXED = 1e-250

#: Large-Pe route: the finite-volume references are solved at Pe_hi, Pe_hi/2, Pe_hi/4 with
#: Pe_hi max(v/w) = m_max / LARGE_PE_NODE_CELLS (cell Peclet number <= 1 from m_max/8 volumes on).
LARGE_PE_NODE_CELLS = 8
#: ... and only when every class's own Peclet number Pe_j v_i/w_i at the smallest node is at
#: least this: below it a class is not in the plug-flow regime at the nodes (a class retained
#: by classification, v << w, breaks in a dispersion layer of width sqrt(w/(Pe tau S)), which
#: makes the deviation from plug flow O(Pe^-1/2), not a power series in 1/Pe).
LARGE_PE_MIN_CLASS_PECLET = 100.0


def large_peclet_applies(pe: float, v, w, m_max: int) -> bool:
    """Whether the large-Pe route applies: the finest grid cannot resolve 1/Pe (Pe max(v/w) >
    m_max) and every class is in the plug-flow regime at the route's nodes
    (:data:`LARGE_PE_MIN_CLASS_PECLET`), i.e. max(v/w) / min(v/w) <= m_max / (32 x 100)."""
    ratio = np.asarray(v, float) / np.asarray(w, float)
    return pe * float(ratio.max()) > m_max and large_peclet_nodes_valid(pe, v, w, m_max)


def large_peclet_nodes_valid(pe: float, v, w, m_max: int) -> bool:
    """Whether every class is in the plug-flow regime at the large-Pe route's nodes and Pe
    lies below its first node (x = 1/Pe inside the fitted range's end at 0).

    The route is then also a fallback where the finite volumes stop above the tolerance
    (Pe between the grids' reach and m_max: the grids reach their second-order range
    only at the finest one)."""
    ratio = np.asarray(v, float) / np.asarray(w, float)
    pe_hi = m_max / LARGE_PE_NODE_CELLS / float(ratio.max())
    return pe > pe_hi and pe_hi / 4.0 * float(ratio.min()) >= LARGE_PE_MIN_CLASS_PECLET


def better_of_fv_and_limit(fv: AxialSolution, limit_solve, tol: float) -> AxialSolution:
    """The finite-volume solution, or the large-Pe route's where the grids stopped above
    ``tol`` and the route's estimate is smaller (its history then records both)."""
    lim = limit_solve()
    if lim.error_estimate < fv.error_estimate:
        history = [("finite volumes stopped above the tolerance", fv.error_estimate), *lim.history]
        return AxialSolution(lim.product, lim.z, lim.density, lim.holdup, lim.error_estimate, lim.order, history)
    return fv


def plug_flow_limit(S, b, feed, tau: float, v, positions: int = 65):
    """Pe -> inf: class i travels at v_i u without dispersion (rates S/v over the contact time tau).

    Flux F(z) = exp(K' tau z) f with K' the breakage matrix of rates S/v (the batch solution
    at time tau z); product F(1), hold-up per unit feed rate int_0^tau exp(K' t) f dt / v_i [s],
    density tau F(z)/v_i at ``positions`` nodes. Returns (z, density, product, holdup, error)
    with the plug-flow path's rounding estimate (:func:`millflow.mill.segregated.plug_flow`).
    """
    from millflow.linalg import SpectralBlocks
    from millflow.mill.segregated import plug_flow

    S = np.asarray(S, dtype=float)
    feed = np.asarray(feed, dtype=float)
    v = np.asarray(v, dtype=float)
    rates = S / v
    blocks, _, _ = SpectralBlocks.decompose(rates, b)
    product, hold, err, _ = plug_flow(rates, b, feed, tau, blocks=blocks)
    vk = v.reshape((-1,) + (1,) * (feed.ndim - 1))
    z = np.linspace(0.0, 1.0, positions)
    cols = [feed] if feed.ndim == 1 else [feed[:, k] for k in range(feed.shape[1])]
    flux = np.stack([blocks.expm_apply(c, tau * z) for c in cols], axis=-1)  # (M, N, m)
    density = tau * flux / v[None, :, None]
    if feed.ndim == 1:
        density = density[..., 0]
    return z, density, product, hold / vk, float(err)


def large_peclet_limit(solve_at, S, b, feed, tau: float, pe: float, v, w, *, tol: float, m_max: int,
                       unit: float | None = None) -> AxialSolution:
    """The axial mill at a Peclet number the finite volumes cannot resolve (Pe max(v/w) > m_max).

    The product and hold-up are analytic in x = 1/Pe at x = 0 (the plug-flow limit,
    :func:`plug_flow_limit`, exact to rounding) up to terms exp(-Pe ...) of the boundary
    layers: y(x) = y(0) + c1 x + c2 x^2 + c3 x^3 + ... (for one class without
    classification, ln(p/f) = -k + k^2/Pe - 2 k^3/Pe^2 + ..., k = S tau). The coefficients
    are fitted from finite-volume solutions at Pe_j = Pe_hi / 2^j, j = 0, 1, 2, where the
    grid resolves 1/Pe (``solve_at(pe_j, tol_j)``): y at x is the cubic through x = 0 and the
    three x_j. Error estimate: the cubic minus the quadratic through (0, x_0, x_1) at x (the
    size of the last term kept, the Richardson argument in x), plus the references' own
    estimates times sum |L_j(x)| of the cubic's Lagrange basis (<= 0.43 for x <= x_0/8),
    plus the plug-flow rounding. In units of the feed for the product and of ``unit``
    (default tau) for the hold-up. At Pe = 1e6 with k ~ 1 the first-order term is ~1e-6 and
    the estimate ~1e-12; outside the asymptotic range (a class whose Peclet number Pe_j v/w
    is small at the nodes, or k^2 comparable to Pe_j) the estimate says so.
    """
    unit = tau if unit is None else float(unit)
    n_cls = np.asarray(S).size
    z, dens, p0, h0, err0 = plug_flow_limit(S, b, feed, tau, v)
    pe_hi = m_max / LARGE_PE_NODE_CELLS / float(np.max(np.asarray(v) / np.asarray(w)))
    nodes = np.array([0.0, 1.0 / pe_hi, 2.0 / pe_hi, 4.0 / pe_hi])
    x = 1.0 / pe
    ys = [np.concatenate([p0, h0 / unit])]
    refs_err, history = [], [("plug-flow limit", 0.0)]
    for xj in nodes[1:]:
        sol = solve_at(1.0 / xj, 0.25 * tol)
        ys.append(np.concatenate([sol.product, sol.holdup / unit]))
        refs_err.append(sol.error_estimate)
        history.append((f"finite volumes at Pe = {1.0 / xj:.4g}", sol.error_estimate))
    ys = np.stack(ys)

    def lagrange(points, at):
        out = []
        for j, xj in enumerate(points):
            others = np.delete(points, j)
            out.append(float(np.prod((at - others) / (xj - others))))
        return np.array(out)

    L3 = lagrange(nodes, x)
    L2 = lagrange(nodes[:3], x)
    cubic = np.tensordot(L3, ys, axes=1)
    quad = np.tensordot(L2, ys[:3], axes=1)
    truncation = float(np.abs(cubic - quad).max(initial=0.0))
    propagated = float(np.abs(L3[1:]) @ np.array(refs_err))
    estimate = truncation + propagated + err0 * max(1.0, tau / unit)
    both = np.maximum(cubic, 0.0)
    history.append(("large-Pe limit: plug flow + 1/Pe terms", estimate))
    return AxialSolution(both[:n_cls], z, dens, unit * both[n_cls:], estimate, float("nan"), history)


def _perfectly_mixed_limit(S, b, feed, tau, pe, v, w) -> AxialSolution:
    """Pe -> 0: every class uniform along the axis, p_i = v_i c_i, i.e. eq. 3 with rates
    S/v (the well-mixed mill with classification d = v). The axial profile deviates from
    uniform by O(Pe v/w); the error estimate bounds it by (1 + tau max S/v)^2 Pe max(v/w)
    sum|f|, far below rounding here (Pe v/w < 1e-250)."""
    from millflow.mill.well_mixed import solve_well_mixed

    S = np.asarray(S, dtype=float)
    feed = np.asarray(feed, dtype=float)
    p = solve_well_mixed(S, b, feed, tau, v)
    z = np.array([0.0, 1.0])
    c = np.stack([p / v.reshape((-1,) + (1,) * (p.ndim - 1))] * 2)  # uniform density per class
    bound = (1 + tau * float(np.max(S / v))) ** 2 * pe * float(np.max(v / w)) * float(np.abs(feed).sum())
    density = tau * c
    return AxialSolution(p, z, density, _holdup(z, density), max(bound, 0.0), float("nan"),
                         [("perfectly mixed limit", pe)])


def _holdup(z: np.ndarray, density: np.ndarray) -> np.ndarray:
    """Trapezoidal integral over z (consistent with the lumped breakage terms)."""
    integrate = getattr(np, "trapezoid", None) or np.trapz
    return integrate(density, z, axis=0)
