"""Transient plug flow with classification on the axis: classes travelling at different speeds.

Class i travels at d_i* u (u = L / tau; ``d`` the relative axial velocity). With the hold-up
density c_i (flux F_i = d_i* c_i, hold-up tau int_0^1 c dz) and theta = t / tau the mill obeys::

    dc/dtheta + V dc/dz = tau R(c),   V = diag(d*),   V c(0, theta) = f(theta),

R the kinetics' rate [1/s] (K c for first-order breakage, or a non-linear rate). A step of the
feed at t = 0 (from the steady state of f0 to f1; f0 = 0 for a start-up) starts one front per
speed, along z = v theta. Behind the slowest front (z < v_min theta) every class's domain of
dependence lies after the step, so the mill is at the new steady state there; ahead of the
fastest (z > v_max theta) it is at the old one. Only the sector v_min <= z / theta <= v_max is
transient. In the similarity coordinates xi = z / theta, s = ln theta the sector is a strip::

    dc_i/ds + (v_i - xi) dc_i/dxi = e^s tau R_i(c),

with every front fixed at xi = v_i, where class i's own velocity is zero: the jump of c_i stays
on the face between two intervals and is never smeared. Every kink of the solution lies on a
front line, so between consecutive speeds it is smooth. The strip is cut at the speeds into
intervals with Chebyshev-Gauss-Lobatto nodes (spectral collocation). Each class flows one way
through each interval, towards its own front, and takes its inflow value from the upstream
interval. At the strip's two edges the inflow comes from the steady states along z = v_min
theta (new) and z = v_max theta (old), carried as extra states: d c/ds = v_edge e^s tau R(c) / v,
the steady z-ODE along the edge. The initial condition at theta_0 (tau |dR/dc| theta_0 <= 1e-13)
is the transport alone: each class at the new feed behind its front and the old one ahead.
Method of lines in s (Radau with the sparse analytic Jacobian, through
:func:`millflow.ode.integrate`).

Product p_i(t) = v_i c_i(1, theta): the old steady product before the fastest front arrives
(t < tau / v_max), the new one from t >= tau / v_min, between them c at xi = 1 / theta (the
interval's interpolant; a class whose front is there has arrived). Hold-up tau int_0^1 c dz:
the new steady part up to v_min theta, theta tau int c dxi over the sector inside the mill, the
old steady part beyond v_max theta (the two steady parts are running integrals along the edges).

Error estimate (measured): the strip on P and on about 1.5 P nodes per interval (spectral
convergence: the difference bounds the coarser solution's error, and the finer one's by a wide
margin), plus the finer one at 10x looser tolerances against its tight solve; the finer, tight
answer is returned. With one speed (no classification) there is no sector: the step is a delay.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numpy.polynomial import chebyshev as cheb

from millflow.errors import SolverError
from millflow.ode import integrate
from millflow.threads import limit_blas_threads

__all__ = ["plug_fronts", "FRONT_NODES", "FRONT_TOL"]

#: Chebyshev-Gauss-Lobatto nodes per piece of the coarse and the fine strip.
FRONT_NODES = (9, 14)
#: Default target of the error estimate, relative to the feed (module docstring).
FRONT_TOL = 1e-6
#: Largest strip (nodes x state components) tried before the target is declared missed.
MAX_STATE = 120_000


def _lobatto(P: int):
    """Ascending Chebyshev-Gauss-Lobatto nodes on [-1, 1], their differentiation matrix and the
    maps from nodal values to Chebyshev coefficients."""
    N = P - 1
    x = np.cos(np.pi * np.arange(P) / N)  # descending (Trefethen's cheb)
    c = np.ones(P)
    c[0] = c[-1] = 2.0
    c *= (-1.0) ** np.arange(P)
    X = x[:, None] - x[None, :]
    D = np.outer(c, 1.0 / c) / (X + np.eye(P))
    D -= np.diag(D.sum(axis=1))
    x, D = x[::-1], D[::-1, ::-1]
    to_coef = np.linalg.inv(cheb.chebvander(x, N))
    return x, D, to_coef


def _faces(v, width: float):
    """The speeds, each gap between two cut into pieces no wider than ``width``."""
    speeds = np.unique(v)
    parts = [speeds[:1]]
    for a, b in zip(speeds[:-1], speeds[1:]):
        k = max(1, int(np.ceil((b - a) / width * (1.0 - 1e-12))))
        cut = a + (b - a) * np.arange(1, k + 1) / k
        cut[-1] = b  # the speeds themselves exactly
        parts.append(cut)
    faces = np.concatenate(parts)
    faces[-1] = speeds[-1]
    return faces


class _Strip:
    """The strip xi in [v_min, v_max] cut at the speeds, with P nodes per interval."""

    def __init__(self, v, P: int, width: float):
        self.v, self.P = v, P
        m = v.size
        self.m = m
        faces = _faces(v, width)
        self.lo, self.hi = faces[:-1], faces[1:]
        self.h = self.hi - self.lo
        J = self.lo.size
        self.J = J
        x, D, self.to_coef = _lobatto(P)
        # int_{-1}^{X} of the interpolant = chebvander(X, P) @ _anti @ values; _cc: Clenshaw-Curtis weights
        anti = np.zeros((P + 1, P))
        for n in range(P):
            e = np.zeros(P)
            e[n] = 1.0
            anti[:, n] = cheb.chebint(e, lbnd=-1.0)
        self._anti = anti @ self.to_coef
        self._cc = cheb.chebvander(np.ones(1), P)[0] @ self._anti
        self.xi = self.lo[:, None] + 0.5 * (x[None, :] + 1.0) * self.h[:, None]  # (J, P)
        self.D = D[None, :, :] * (2.0 / self.h)[:, None, None]  # (J, P, P)
        # each class flows towards its front: rightwards where v_i >= the interval's top
        right = v[None, :] >= self.hi[:, None]  # (J, m)
        owned = np.ones((J, P, m), dtype=bool)
        owned[:, 0, :] &= ~right
        owned[:, -1, :] &= right
        self.owned = owned
        n_s = int(owned.sum())
        self.n_s = n_s
        idx = np.full((J, P, m), -1, dtype=np.int64)
        idx[owned] = np.arange(n_s)
        self.edge_new, self.edge_old = n_s, n_s + m  # the steady states along the two edges
        self.hold_new, self.hold_old = n_s + 2 * m, n_s + 3 * m  # their running hold-ups
        self.size = n_s + 4 * m
        k = np.arange(m)
        for j in range(J):  # inflow nodes: the upstream interval's node, or the edge's state
            r = right[j]
            idx[j, 0, r] = idx[j - 1, -1, r] if j > 0 else self.edge_new + k[r]
            idx[j, -1, ~r] = idx[j + 1, 0, ~r] if j < J - 1 else self.edge_old + k[~r]
        self.idx = idx
        # the transport: -(v_i - xi) D, on the owned rows
        jj, qq, kk = np.nonzero(owned)
        speed = -(v[kk] - self.xi[jj, qq])
        self.t_rows = np.repeat(np.arange(n_s), P)
        self.t_cols = idx[jj[:, None], np.arange(P)[None, :], kk[:, None]].ravel()
        self.t_vals = (speed[:, None] * self.D[jj, qq, :]).ravel()
        self.r_rows = np.repeat(np.arange(n_s), m)
        self.r_cols = idx[jj, qq, :].ravel()

    def full(self, y):
        """Every node's values (J, P, m), the inflow nodes copied from upstream."""
        return y[self.idx]

    def locate(self, xi):
        """The interval of xi (lo < xi <= hi; the lowest one at v_min) and its reference node."""
        j = np.clip(np.searchsorted(self.hi, xi, side="left"), 0, self.J - 1)
        return j, 2.0 * (xi - self.lo[j]) / self.h[j] - 1.0

    def point_weights(self, xi):
        """(j, w): c(xi) = w @ C[j] for the nodal values C (J, P, m) (the interval's interpolant)."""
        j, X = self.locate(xi)
        return j, cheb.chebvander(np.atleast_1d(X), self.P - 1)[0] @ self.to_coef

    def integral_weights(self, top):
        """(j, w_full, w_top): int_{v_min}^{top} c dxi = sum_{k<j} w_full[k] @ C[k] + w_top @ C[j]."""
        j, X = self.locate(top)
        w_top = 0.5 * self.h[j] * (cheb.chebvander(np.atleast_1d(X), self.P)[0] @ self._anti)
        return j, 0.5 * self.h[:j, None] * self._cc[None, :], w_top

    def value(self, C, xi):
        """c at xi (m,) from the nodal values C (J, P, m)."""
        j, w = self.point_weights(xi)
        return w @ C[j]

    def integral(self, C, top):
        """int_{v_min}^{top} c dxi (m,) from the nodal values C (J, P, m)."""
        j, w_full, w_top = self.integral_weights(top)
        return np.einsum("jp,jpm->m", w_full, C[:j]) + w_top @ C[j]


def _system(strip: _Strip, rate_many, jacobian_many, tau: float):
    v, m, n_s = strip.v, strip.m, strip.n_s
    vmin, vmax = strip.lo[0], strip.hi[-1]
    en, eo, hn, ho = strip.edge_new, strip.edge_old, strip.hold_new, strip.hold_old
    edge_scale = np.concatenate([vmin * tau / v, vmax * tau / v])

    def rhs(s, y):
        e = np.exp(s)
        C = strip.full(y)
        dC = np.einsum("jpq,jqm->jpm", strip.D, C)
        R = rate_many(C.reshape(-1, m)).reshape(C.shape)
        out = np.empty_like(y)
        out[:n_s] = (-(v[None, None, :] - strip.xi[:, :, None]) * dC + e * tau * R)[strip.owned]
        E = y[en:en + 2 * m].reshape(2, m)
        out[en:en + 2 * m] = e * edge_scale * rate_many(E).ravel()
        out[hn:hn + m] = tau * vmin * e * y[en:en + m]
        out[ho:ho + m] = tau * vmax * e * y[eo:eo + m]
        return out

    rows_e = np.repeat(np.arange(en, en + 2 * m), m)
    cols_e = np.concatenate([np.tile(np.arange(en, en + m), m), np.tile(np.arange(eo, eo + m), m)])
    rows_h = np.arange(hn, hn + 2 * m)
    cols_h = np.arange(en, en + 2 * m)
    rows = np.concatenate([strip.t_rows, strip.r_rows, rows_e, rows_h])
    cols = np.concatenate([strip.t_cols, strip.r_cols, cols_e, cols_h])
    hold_scale = tau * np.concatenate([np.full(m, vmin), np.full(m, vmax)])

    def jac(s, y):
        e = np.exp(s)
        C = strip.full(y)
        JR = jacobian_many(C.reshape(-1, m)).reshape(strip.J, strip.P, m, m)
        JE = jacobian_many(y[en:en + 2 * m].reshape(2, m))
        vals = np.concatenate([strip.t_vals, e * tau * JR[strip.owned].ravel(),
                               (e * edge_scale[:, None] * np.concatenate(JE)).ravel(), e * hold_scale])
        return sp.csc_matrix((vals, (rows, cols)), shape=(strip.size, strip.size))

    return rhs, jac


def _initial(strip: _Strip, c_new, c_old):
    """The transport alone at theta -> 0: new behind each class's front, old ahead."""
    behind = strip.v[None, :] >= strip.hi[:, None]  # (J, m): xi < v_i on the whole interval
    C = np.where(behind[:, None, :], c_new[None, None, :], c_old[None, None, :])
    C = np.broadcast_to(C, strip.owned.shape)
    return np.concatenate([C[strip.owned], c_new, c_old, np.zeros(2 * strip.m)])


def _solve(strip, rate_many, jacobian_many, tau, c_new, c_old, theta, theta0, rtol, atol, method):
    """The strip at the sorted unique theta (>= theta0); (product, hold-up) (T, m) inside the sector's
    times and the steady ends."""
    rhs, jac = _system(strip, rate_many, jacobian_many, tau)
    y0 = _initial(strip, c_new, c_old)
    v = strip.v
    vmin, vmax = strip.lo[0], strip.hi[-1]
    inner = theta[(theta > theta0) & (theta < 1.0 / vmin)]
    s_eval = np.unique(np.concatenate([np.log(inner), [np.log(1.0 / vmax), np.log(1.0 / vmin)]]))
    sol = integrate(rhs, (float(np.log(theta0)), float(s_eval[-1])), y0, jac=jac, method=method, rtol=rtol,
                    atol=atol, t_eval=s_eval, what="transient plug flow with classes at different speeds")
    Y = sol.y.T
    m = strip.m
    at = {float(s): Y[i] for i, s in enumerate(s_eval)}
    end_old, end_new = at[float(np.log(1.0 / vmax))], at[float(np.log(1.0 / vmin))]
    en, eo, hn, ho = strip.edge_new, strip.edge_old, strip.hold_new, strip.hold_old
    p_old, p_new = v * end_old[eo:eo + m], v * end_new[en:en + m]
    h_old, h_new = end_old[ho:ho + m], end_new[hn:hn + m]
    product = np.empty((theta.size, m))
    holdup = np.empty((theta.size, m))
    speeds = np.unique(v)
    for i, th in enumerate(theta):
        xi = 1.0 / th if th > 0 else np.inf  # the outlet in the strip; at a front (to rounding) on it
        near = speeds[np.argmin(np.abs(speeds - xi))]
        xi = near if abs(xi - near) <= 8 * np.finfo(float).eps * near else xi
        if xi <= vmin:
            product[i], holdup[i] = p_new, h_new
            continue
        if th <= theta0:
            product[i], holdup[i] = p_old, h_old
            continue
        y = at[float(np.log(th))]
        C = strip.full(y)
        product[i] = p_old if xi > vmax else v * strip.value(C, xi)
        sector = th * tau * strip.integral(C, min(vmax, xi))
        old_part = h_old - y[ho:ho + m] if xi > vmax else 0.0
        holdup[i] = y[hn:hn + m] + sector + old_part
    return product, holdup, {"nfev": int(sol.nfev), "njev": int(sol.njev), "nlu": int(sol.nlu)}


def refine(run, v, width, nodes, rtol, atol, tol, target, max_state):
    """Halve the pieces' width from ``width`` until the estimate meets ``target``.

    ``run(P, width, rtol, atol)`` -> (product, hold-up, info) on P nodes per piece; the estimate
    is the coarse against the fine strip plus the fine one at 10x looser tolerances. Returns
    the fine run, the estimate and the info; SolverError when the strip would exceed
    ``max_state`` first.
    """
    def gap(x, y):
        return {"product": float(np.abs(x[0] - y[0]).max(initial=0.0)),
                "holdup": float(np.abs(x[1] - y[1]).max(initial=0.0))}

    est, pieces = None, 0
    while True:
        wanted = _faces(v, width).size - 1
        if wanted * nodes[1] * v.size > max_state:
            missed = "no solve" if est is None else \
                f"estimate {max(est[k] / target[k] for k in est) * tol:.2g} (relative) on {pieces} pieces"
            raise SolverError(f"transient plug flow with classes at different speeds: tol {tol:g} missed ({missed}; "
                              f"{wanted} pieces of {nodes[1]} nodes would exceed max_state {max_state}); expected "
                              "a larger tol or max_state")
        pieces = wanted
        coarse, fine = run(nodes[0], width, rtol, atol), run(nodes[1], width, rtol, atol)
        est = gap(coarse, fine)
        if all(est[k] <= 0.5 * target[k] for k in est):
            loose = run(nodes[1], width, 10 * rtol, 10 * atol)
            more = gap(loose, fine)
            est = {k: est[k] + more[k] for k in est}
            if all(est[k] <= target[k] for k in est):
                break
        width /= 2.0
    info = dict(fine[2], fronts_nodes=int(nodes[1]), fronts_pieces=int(pieces), speeds=int(np.unique(v).size))
    return fine, est, info


@limit_blas_threads
def plug_fronts(rate_many, jacobian_many, v, tau: float, feed, old, t, *, tol: float = FRONT_TOL,
                nodes=FRONT_NODES, rtol: float = 1e-9, atol: float | None = None, method: str = "Radau",
                max_state: int = MAX_STATE):
    """Transient plug flow with classes at different speeds (module docstring): a step from the
    steady state of ``old`` to ``feed`` at t = 0.

    The intervals between speeds are cut into pieces no wider than a width halved from the
    whole strip until the estimate meets ``tol``.

    Parameters
    ----------
    rate_many, jacobian_many : callable
        R of every row of C (k, m) [1/s] as (k, m), and dR/dc as (k, m, m).
    v : (m,) array
        Relative axial velocity d_i* > 0 of each state component, at least two distinct.
    tau : float
        Mean residence time at d* = 1 [s].
    feed, old : (m,) array
        Feed rates after and before the step [mass/s].
    t : (T,) array
        Times >= 0 [s].
    tol : float
        Target of the error estimate relative to the larger feed (product [mass/s]) and to it
        times tau (hold-up [mass]).
    nodes : (int, int)
        Nodes per piece of the coarse and the fine strip.
    rtol, atol : float
        Tolerances of the method of lines (atol in the units of c [mass/s]; None: 1e-4 rtol
        times the largest feed density).
    max_state : int
        Largest state (nodes x components) tried before the target is declared missed.

    Returns
    -------
    product, holdup : (T, m) arrays
        Discharge [mass/s] and hold-up [mass] (the fine strip at the tight tolerances).
    diff : dict
        ``product`` and ``holdup``: the error estimate, the nodes' part plus the tolerances'.
    info : dict
        Right-hand sides, Jacobians and factorisations of the returned solve, the nodes and
        the pieces.

    Raises
    ------
    SolverError
        When the estimate misses ``tol`` on the largest strip allowed.
    """
    v = np.asarray(v, dtype=float)
    c_new, c_old = np.asarray(feed, float) / v, np.asarray(old, float) / v
    theta = np.asarray(t, dtype=float) / tau
    vmin, vmax = float(v.min()), float(v.max())
    rho = 1.0
    for c in (c_new, c_old):
        rho = max(rho, tau * float(np.abs(jacobian_many(c[None, :])[0]).sum(axis=1).max()))
    theta0 = min(1e-13 / rho, 1e-6 / vmax)
    th, where = np.unique(theta, return_inverse=True)
    if atol is None:
        atol = 1e-4 * rtol * max(float(np.abs(c_new).max()), float(np.abs(c_old).max()), 1e-300)
    scale = max(float(np.sum(feed)), float(np.sum(old)), 1e-300)
    target = {"product": tol * scale, "holdup": tol * tau * scale}

    def run(P, width, r, a):
        return _solve(_Strip(v, P, width), rate_many, jacobian_many, tau, c_new, c_old, th, theta0, r, a, method)

    # first width: about 8 e-folds of the fastest decay across a piece, at most 8 pieces (halved from there)
    folds = rho / vmin * (vmax - vmin) / vmin
    fine, est, info = refine(run, v, (vmax - vmin) / float(np.clip(folds / 8.0, 1.0, 8.0)), nodes, rtol, atol, tol,
                             target, max_state)
    return fine[0][where], fine[1][where], est, info
