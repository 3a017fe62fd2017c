"""Open-vessel axial dispersion mill with classification, size-dependent dispersion and profiles.

The open-open vessel (``rtd.AxialDispersion(bc="open")``) is the line -inf < z < inf with
the same velocity and dispersion on both sides of the mill; the feed enters as a plane
source at z = 0 and the discharge is taken at z = 1 (z = y/L, time in units of tau = L/u).
Breakage acts wherever the material is, as in the homogeneous medium behind the open
density E(theta) = sqrt(Pe/(4 pi theta)) exp(-Pe (1 - theta)^2 / (4 theta)). Steady state
of class i, with relative axial velocity v_i = d_i* and relative dispersion w_i:

    d/dz [ v_i c_i - (w_i/Pe) dc_i/dz ] = -tau S_i c_i + tau sum_{j<i} b_ij S_j c_j + f_i delta(z),

c_i -> 0 as z -> -inf and bounded as z -> +inf. Two discharges (``discharge=``):

- ``"sampled"`` (default): p_i = v_i c_i(1), the flow-weighted concentration at the
  discharge plane: what the open density E measures (its mean tau (1 + 2/Pe) exceeds
  L/u because a concentration, not a flux, is sampled). With v = w = 1 the product is
  segregated flow with the open E exactly; with v = w = d* it is segregated flow with rates
  S/d*. Mass is conserved, sum p = sum f, exactly when every class has the same Peclet
  number Pe v_i / w_i: the total Q = sum v_i c_i then obeys Q - (w/(v Pe)) Q' = sum f
  downstream of the source, whose only bounded solution is Q = sum f (and the discrete
  scheme below keeps that identity to rounding). With unequal Peclet numbers the sampled
  concentrations do not add up to the feed, so that case is refused.
- ``"flux"``: p_i = v_i c_i(1) - (w_i/Pe) c_i'(1), the net flux through the discharge
  plane (what crosses it, counting the material that disperses back), taken from the
  balance of (-inf, 1]: p = f - tau (I - b) S int_(-inf)^1 c dz. Conserves mass for any
  v, w. Without classification it corresponds to the flux-weighted open density
  E_f = (1 + 1/theta) E / 2, mean tau (1 + 1/Pe), not to E.

Default dispersion for the open vessel: w = d* (classification scales velocity and
dispersion alike, one Peclet number), unlike the closed vessel, where w = 1.

Hold-up per unit feed rate [s]: with the flux discharge tau int_(-inf)^1 c dz (what has not
yet crossed the discharge plane); with the sampled discharge that plus tau int_(-inf)^1 c^
dz, where c^ solves the same equations on (-inf, 1] without source and with c^(1) = c(1)
(the back-dispersion layer the sampling counts). For a class that does not break this is
tau (1 + 2/Pe), the mean of E; for v = w = 1 it is the segregated hold-up G(-K) f, and
f - p = tau (I - b) S H holds whenever the Peclet numbers are equal.

Discretisation as the closed vessel (:mod:`millflow.mill.axial`): vertex-centred finite
volumes with exponentially fitted fluxes
(:func:`millflow.mill.finite_volume.open_faces`), breakage lumped at the nodes, the
subtraction-free (GTH) LU factors of each class's tridiagonal M-matrix, Richardson
extrapolation over doubled grids. The mill [0, 1] has M uniform volumes; each tail has M
volumes on the smooth stretching z = L_t (e^(beta j/M) - 1)/(e^beta - 1) with the first
volume 1/M (uniform when L_t <= 1), so doubling M halves every volume. The tails end at
L_t = 40 / min_i r_i, r_i = (Pe_i/2)(1 + sqrt(1 + 4 tau S_i / (Pe_i v_i))) the slowest
upstream decay rate (Pe_i = Pe v_i / w_i): a boundary there changes c(0..1) by e^-40.
Zero flux at the upstream end, outflow (Danckwerts) at the downstream end.
"""
from __future__ import annotations

import numpy as np
from scipy.linalg import lapack

from millflow.errors import InputError, SolverError
from millflow.mill.axial import (AxialSolution, _gth_factors, better_of_fv_and_limit, large_peclet_applies,
                                 large_peclet_limit, large_peclet_nodes_valid, refine_grids)
from millflow.mill.finite_volume import AxialFaces, node_losses, open_faces

__all__ = ["DISCHARGES", "solve_axial_open", "solve_axial_open_grid", "back_layer_matrix", "tail_length"]

#: Discharges of the open vessel (module docstring).
DISCHARGES = ("sampled", "flux")

#: Tail length in upstream decay lengths: e^-40 ~ 4e-18 of the mill's values.
TAIL_DECAY_LENGTHS = 40.0

_gttrs = lapack.get_lapack_funcs("gttrs", dtype=np.float64)


#: Longest tail [mill lengths]: the stretching's exp(beta) stays finite up to ~1e301.
MAX_TAIL = 1e250


def tail_length(S, tau: float, pe: float, v, w) -> float:
    """L_t = 40 / min_i r_i (module docstring); InputError beyond :data:`MAX_TAIL`."""
    pe_i = pe * np.asarray(v, float) / np.asarray(w, float)
    with np.errstate(over="ignore", divide="ignore"):
        r = 0.5 * pe_i * (1.0 + np.sqrt(1.0 + 4.0 * tau * np.asarray(S, float) / (pe_i * np.asarray(v, float))))
        length = TAIL_DECAY_LENGTHS / float(r.min())
    if not length <= MAX_TAIL:
        raise InputError(
            f"open-vessel axial dispersion: Pe d*/dispersion = {float(pe_i.min()):.3g} is too small to solve "
            f"(the open vessel's mean residence time tau (1 + 2/Pe) is {2 / pe:.3g} tau); expected Pe d*/dispersion "
            f">= {TAIL_DECAY_LENGTHS / MAX_TAIL:.0e}")
    return length


def _solve_class(alpha_i, beta_i, piv_i, rhs):
    """One class's tridiagonal M-matrix solve from its GTH pivots (LAPACK gttrs)."""
    n = piv_i.size
    c, info = _gttrs(-alpha_i[: n - 1] / piv_i[:-1], piv_i, -beta_i[: n - 1], np.zeros(max(n - 2, 0)),
                     np.arange(1, n + 1, dtype=np.int32), rhs)
    if info != 0:
        raise SolverError(f"open axial dispersion: tridiagonal solve failed (info {info})")
    return c


def _sweep_classes(alpha, beta, piv, gain, weights, source) -> np.ndarray:
    """Solve the open vessel's finite-volume system class by class, coarse to fine.

    C (N, n[, m]) class by class, coarse to fine: class i's tridiagonal M-matrix (GTH
    pivots ``piv``) with right-hand side sum_(j<i) gain_ij w_k c_jk + source(i) (n[, m]).
    """
    n_cls, n = piv.shape
    first = source(0)
    cols = first.shape[1:]
    wk = weights.reshape((n,) + (1,) * len(cols))
    c = np.empty((n_cls, n) + cols)
    wc = np.empty((n_cls, n * int(np.prod(cols, dtype=int))))  # weights * c, flattened
    for i in range(n_cls):
        rhs = first if i == 0 else (gain[i, :i] @ wc[:i]).reshape((n,) + cols) + source(i)
        c_i = _solve_class(alpha[i], beta[i], piv[i], rhs if cols else rhs[:, None])
        c[i] = c_i if cols else c_i[:, 0]
        wc[i] = (wk * c[i]).ravel()
    return c


def back_layer_matrix(S, b, tau: float, grid: AxialFaces, v) -> np.ndarray:
    """Map (N, N) from c(1) to the back-dispersion layer of the sampled discharge.

    (N, N) map from c(1) to int_(-inf)^1 c^ dz (the sampled discharge's back-dispersion
    layer, module docstring): lower triangular, linear in c(1).
    """
    S = np.asarray(S, dtype=float)
    loss = node_losses(grid, np.asarray(v, float), tau * S)
    gain = tau * np.asarray(b, float) * S[None, :]
    return _back_layer(grid, loss, gain, np.eye(S.size))


def solve_axial_open_grid(S, b, feed, tau: float, pe: float, m_cells: int, d=None, w=None,
                          discharge: str = "sampled", tail: float | None = None):
    """Concentrations c (nodes, N[, m]), product and hold-up on one grid (module docstring).

    Returns (z, c, product, holdup) with z the nodes of the whole line; ``tail`` overrides
    the tail length (fractions of the mill length).
    """
    S = np.asarray(S, dtype=float)
    b = np.asarray(b, dtype=float)
    n_cls = S.size
    feed = np.asarray(feed, dtype=float)
    cols = feed.shape[1:]
    v = np.ones(n_cls) if d is None else np.asarray(d, dtype=float)
    w = v.copy() if w is None else np.asarray(w, dtype=float)
    L_t = tail_length(S, tau, pe, v, w) if tail is None else float(tail)
    g = open_faces(pe, m_cells, v, w, L_t)
    z, k0, k1, alpha, beta, weights = g.z, g.inlet, g.outlet, g.alpha, g.beta, g.weights
    n = z.size
    loss = node_losses(g, v, tau * S)  # breakage, and the outflow at the downstream end
    piv = _gth_factors(alpha, beta, loss)
    gain = tau * b * S[None, :]

    def fed(i):  # the feed enters at the node of z = 0
        r = np.zeros((n,) + cols)
        r[k0] = feed[i]
        return r

    c = _sweep_classes(alpha, beta, piv, gain, weights, fed)
    lk = g.upstream.reshape((n,) + (1,) * len(cols))
    upstream = (lk[None] * c).sum(axis=1)  # int_(-inf)^1 c dz, (N[, m])
    vk = v.reshape((n_cls,) + (1,) * len(cols))
    if discharge == "flux":
        lost = S.reshape((n_cls,) + (1,) * len(cols)) * upstream
        product = feed - tau * (lost - np.tensordot(b, lost, axes=([1], [0])))
        holdup = tau * upstream
    else:
        product = vk * c[:, k1]
        holdup = tau * (upstream + _back_layer(g, loss, gain, c[:, k1]))
    return z, np.moveaxis(c, 1, 0), product, holdup


def _back_layer(grid: AxialFaces, loss, gain, c_end):
    """int_(-inf)^1 c^ dz: the source-free equations on nodes 0..k1 with c^(k1) = c(k1) (k1 the outlet)."""
    alpha, beta, weights, h, k1 = grid.alpha, grid.beta, grid.weights, grid.h, grid.outlet
    cols = c_end.shape[1:]
    n = k1  # unknown nodes 0..k1-1
    if n == 0:
        return 0.5 * h[0] * c_end
    loss_b = loss[:, :n].copy()
    # node k1 - 1 loses alpha to the fixed node as well: its column sum grows by alpha
    loss_b[:, n - 1] += alpha[:, n - 1]
    faces = slice(0, max(n - 1, 1))  # faces between the unknown nodes (one unused when n = 1)
    piv = _gth_factors(alpha[:, faces], beta[:, faces], loss_b)

    def from_fixed_node(i):  # c^(k1) = c(k1) enters node k1 - 1 through the face between them
        r = np.zeros((n,) + cols)
        r[n - 1] = beta[i, n - 1] * c_end[i]
        return r

    ch = _sweep_classes(alpha, beta, piv, gain, weights[:n], from_fixed_node)
    wk = weights[:n].reshape((1, n) + (1,) * len(cols))
    return (wk * ch).sum(axis=1) + 0.5 * h[k1 - 1] * c_end


def check_discharge(discharge, v, w) -> str:
    """The discharge name, refusing the sampled one when the Peclet numbers differ."""
    if discharge is None:
        discharge = "sampled"
    if discharge not in DISCHARGES:
        raise InputError(f"discharge = {discharge!r}; expected one of {', '.join(map(repr, DISCHARGES))} "
                         "(open-vessel axial dispersion)")
    ratio = np.asarray(v, float) / np.asarray(w, float)
    if discharge == "sampled" and float(ratio.max() - ratio.min()) > 1e-9 * float(ratio.max()):
        raise InputError(
            "open-vessel axial dispersion: the sampled discharge (v c at z = 1, what the open density "
            "measures) conserves mass only when every class has the same Peclet number Pe d*/dispersion; "
            f"here d*/dispersion ranges over {ratio.min():.3g}..{ratio.max():.3g}. Give dispersion "
            "proportional to d (the default is dispersion = d), use discharge='flux' (the net flux through "
            "the discharge plane) or the closed vessel")
    return discharge


def solve_axial_open(S, b, feed, tau: float, pe: float, d=None, w=None, *, discharge: str = "sampled",
                     tol: float = 1e-8, m_start: int = 16, m_max: int = 16384,
                     m_cells: int | None = None) -> AxialSolution:
    """Steady open-vessel axial-dispersion mill.

    Steady open-vessel axial-dispersion mill (module docstring), refined until the
    error estimate of the product and of the hold-up / (tau (1 + 2/Pe)) is below ``tol`` (or on
    the one grid ``m_cells``): ``error_estimate`` bounds both (the hold-up's error in units
    of the open density's mean residence time).

    Parameters
    ----------
    S : (N,) rates [1/s]; b : (N, N) fractional breakage distribution.
    feed : (N,) or (N, m) feed flows.
    tau : L/u [s] (the open density's mean is tau (1 + 2/Pe)); pe : u L / D [-].
    d, w : (N,) relative axial velocity d_i* and relative dispersion (default w = d).
    discharge : "sampled" (v c(1)) or "flux" (net flux through z = 1).

    Returns
    -------
    AxialSolution
        Its ``z``, ``density`` (tau c [s]) and ``holdup`` cover the whole line of the
        finest grid; profiles inside the mill are its nodes with 0 <= z <= 1.
    """
    S = np.asarray(S, dtype=float)
    v = np.ones(S.size) if d is None else np.asarray(d, dtype=float)
    w_arr = v.copy() if w is None else np.asarray(w, dtype=float)
    discharge = check_discharge(discharge, v, w_arr)
    if m_cells is None and large_peclet_applies(pe, v, w_arr, m_max):
        # the finest grid cannot resolve 1/Pe: the plug-flow limit and its 1/Pe terms; the
        # hold-up's estimate in units of tau (<= the mean tau (1 + 2/Pe), as stated)
        def at(pe_j, tol_j):
            return solve_axial_open(S, b, feed, tau, pe_j, v, w_arr, discharge=discharge, tol=tol_j,
                                    m_start=m_start, m_max=m_max)

        return large_peclet_limit(at, S, b, feed, tau, pe, v, w_arr, tol=tol, m_max=m_max)
    L_t = tail_length(S, tau, pe, v, w_arr)

    n_cls = S.size
    mean = tau * (1.0 + 2.0 / pe)  # the open density's mean residence time [s]

    def grid(M):
        # refined on what is reported: the product and the hold-up in units of the mean
        # residence time (the product of a class that does not break is exact on every
        # grid, its hold-up is not)
        z, c, p, hold = solve_axial_open_grid(S, b, feed, tau, pe, M, v, w_arr, discharge, tail=L_t)
        return z, c, np.concatenate([p, hold / mean]), hold

    if m_cells is not None:
        z, c, p, hold = solve_axial_open_grid(S, b, feed, tau, pe, m_cells, v, w_arr, discharge, tail=L_t)
        return AxialSolution(np.maximum(p, 0.0), z, tau * c, hold, float("nan"), float("nan"), [])
    cols = int(np.prod(np.shape(feed)[1:], dtype=int))
    both, estimate, order, history, finest, coarser, extrapolated = refine_grids(
        grid, float((v / w_arr).max()) * pe, tol=tol, m_start=m_start, m_max=m_max,
        bytes_per_cell=8.0 * 3 * 8 * n_cls * cols)  # the mill and two tails; c, back layer, kept grids
    z, c, _, _ = finest
    fv = AxialSolution(both[:n_cls], z, tau * c, mean * both[n_cls:], estimate, order, history)
    if estimate > tol and large_peclet_nodes_valid(pe, v, w_arr, m_max):
        def at_nodes(pe_j, tol_j):
            return solve_axial_open(S, b, feed, tau, pe_j, v, w_arr, discharge=discharge, tol=tol_j,
                                    m_start=m_start, m_max=m_max)

        return better_of_fv_and_limit(
            fv, lambda: large_peclet_limit(at_nodes, S, b, feed, tau, pe, v, w_arr, tol=tol, m_max=m_max), tol)
    return fv
