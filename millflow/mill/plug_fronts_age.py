"""Transient plug flow with classes at different speeds and slowing-down in the particle's age.

With S_i = S_i0 kappa(a), a the time a particle has spent in the mill, the mill is linear in
its feed and invariant under shifts of the entry time (:mod:`millflow.mill.age_transient`), so
a step is a sum of impulses. With theta = a / tau, X_f(theta) the mass of an impulse f that
has left by the age theta and Q_f(theta) = int_0^theta (its mass inside) dtheta'::

    product(t) = X_f1(t / tau) + X_f0(inf) - X_f0(t / tau),
    hold-up(t) = tau (Q_f1(t / tau) + Q_f0(inf) - Q_f0(t / tau)),

f0 the feed before the step (its steady state at t = 0), f1 after.

An impulse in plug flow with class i at speed v_i = d_i*: the material of each speed group g
(the classes at speed w_g) that has not yet changed group is a delta at z = w_g theta, its
masses D obeying the batch grind
within the group, dD/dtheta = tau kappa K_gg D. Fragments that change speed spread over z
with a density y. In xi = z / theta and s = ln theta::

    dy_i/ds + (v_i - xi) dy_i/dxi = e^s tau kappa (K y)_i,

on the strip and pieces of :mod:`millflow.mill.plug_fronts` (every group at a face). The births
from group g enter as a jump where each class crosses that face: downstream = upstream +
tau kappa (K D_g)_i / |v_i - w_g| (the edges' upstream is empty); at theta_0 -> 0 each fragment
class is uniform between its source's face and its own speed at that value (tau kappa |K|
theta_0 <= 1e-13). The system is linear in y, its coefficients polynomials in e^s and k = tau
kappa(tau e^s). Exits: group g's delta at theta = 1 / w_g; the continuous part at xi = 1 /
theta, dX_i/ds = e^s v_i y_i(1 / theta). Inside: the deltas with w_g theta < 1 plus theta int
y dxi up to min(w_max, 1 / theta); its running integral is carried as Q / theta, d(Q / theta)/ds
= inside - Q / theta, which varies on the scale of the kinetics (Q itself grows as e^s and
would hold the steps down to the tolerance's share of that growth). Integrated by Radau in
segments between the deltas' exits (the integrands jump there).

Error estimate as :func:`millflow.mill.plug_fronts.plug_fronts`: coarse against fine strip plus
the fine one at 10x looser tolerances, the pieces halved until ``tol`` is met.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from millflow.mill.plug_fronts import FRONT_NODES, FRONT_TOL, MAX_STATE, _Strip, refine
from millflow.ode import integrate
from millflow.threads import limit_blas_threads

__all__ = ["plug_fronts_age"]


class _AgeSystem:
    """The linear system of one impulse on a strip: y = [u (owned nodes) | 2m empty edges | D | X | Q]."""

    def __init__(self, strip: _Strip, K):
        v, m, J, P = strip.v, strip.m, strip.J, strip.P
        self.strip, self.K, self.m = strip, K, m
        n_s = strip.n_s
        self.iD, self.iX, self.iQ = n_s + 2 * m, n_s + 3 * m, n_s + 4 * m
        self.size = n_s + 5 * m
        speeds = np.unique(v)
        group = np.searchsorted(speeds, v)
        self.group, self.speeds = group, speeds
        same = group[:, None] == group[None, :]
        self.K_in = K * same  # breakage that stays in the group: the deltas' batch grind
        n_slots = J * P * m
        slot = np.arange(n_slots).reshape(J, P, m)
        Psel = sp.csr_matrix((np.ones(n_slots), (np.arange(n_slots), strip.idx.ravel())), shape=(n_slots, self.size))
        # births: the inflow node of class i at the face of group g gets K[i, G_g] D / |v_i - w_g|
        rows, cols, vals = [], [], []
        right = v[None, :] >= strip.hi[:, None]
        for j in range(J):
            for i in range(m):
                q, face = (0, strip.lo[j]) if right[j, i] else (P - 1, strip.hi[j])
                g = np.searchsorted(speeds, face)
                if g < speeds.size and speeds[g] == face:
                    members = np.nonzero(group == g)[0]
                    rows += [slot[j, q, i]] * members.size
                    cols += list(self.iD + members)
                    vals += list(K[i, members] / abs(v[i] - face))
        A = sp.csr_matrix((vals, (rows, cols)), shape=(n_slots, self.size))
        jj, qq, ii = np.nonzero(np.ones((J, P, m), dtype=bool))
        speed = -(v[ii] - strip.xi[jj, qq])
        tr = sp.csr_matrix(((speed[:, None] * strip.D[jj, qq, :]).ravel(),
                            (np.repeat(slot.ravel(), P),
                             slot[jj[:, None], np.arange(P)[None, :], ii[:, None]].ravel())),
                           shape=(n_slots, n_slots))
        kj = np.repeat(slot.ravel(), m)
        kc = slot[jj[:, None], qq[:, None], np.arange(m)[None, :]].ravel()
        kop = sp.csr_matrix((K[ii][:, np.arange(m)].ravel(), (kj, kc)), shape=(n_slots, n_slots))
        R = sp.csr_matrix((np.ones(n_s), (np.arange(n_s), slot[strip.owned])), shape=(n_s, n_slots))
        self.Psel, self.A = Psel, A
        self.M0 = (R @ tr @ Psel).tocsr()  # transport
        self.MA = (R @ tr @ A).tocsr()  # x k: transport of the births
        self.MK = (R @ kop @ Psel).tocsr()  # x e k: breakage
        self.MKA = (R @ kop @ A).tocsr()  # x e k^2: breakage of the births
        self.n_s = n_s

    def initial(self, f, k0):
        """y at theta -> 0: each fragment class uniform between its source's face and its own speed."""
        strip, m, v = self.strip, self.m, self.strip.v
        y = np.zeros(self.size)
        y[self.iD:self.iD + m] = f
        mid = 0.5 * (strip.lo + strip.hi)  # (J,)
        C = np.zeros((strip.J, strip.P, m))
        for g, w in enumerate(self.speeds):
            members = self.group == g
            s = k0 * (self.K[:, members] @ f[members])  # births per class from group g at theta -> 0
            for i in np.nonzero((self.group != g) & (s != 0))[0]:
                between = (mid - w) * (mid - v[i]) < 0  # the intervals between w_g and v_i
                C[between, :, i] += s[i] / abs(v[i] - w)
        y[:self.n_s] = C[strip.owned]
        return y

    def nodes(self, y, k):
        """Every node's values (J, P, m) with the births at the faces."""
        return (self.Psel @ y + k * (self.A @ y)).reshape(self.strip.J, self.strip.P, self.m)

    def exits(self, s):
        """Sparse (m, size) rows: v_i u_i at xi = e^-s (zero outside the strip), and the
        integral of u up to min(w_max, e^-s), as maps of y (before the births' factor c)."""
        strip, m = self.strip, self.m
        xi = np.exp(-s)
        J, P = strip.J, strip.P
        slot = np.arange(J * P * m).reshape(J, P, m)
        vmin, vmax = strip.lo[0], strip.hi[-1]
        if vmin <= xi <= vmax:
            j, w = strip.point_weights(xi)
            ex = sp.csr_matrix(((strip.v[:, None] * w[None, :]).ravel(),
                                (np.repeat(np.arange(m), P), slot[j].T.ravel())), shape=(m, J * P * m))
        else:
            ex = sp.csr_matrix((m, J * P * m))
        j, w_full, w_top = strip.integral_weights(min(vmax, max(xi, vmin)))
        W = np.concatenate([w_full, w_top[None, :]])  # (j + 1, P)
        cols = slot[:j + 1].transpose(2, 0, 1).reshape(m, -1)
        it = sp.csr_matrix((np.tile(W.ravel(), m), (np.repeat(np.arange(m), W.size), cols.ravel())),
                           shape=(m, J * P * m))
        return ex, it

    def operator(self, s, k, inside):
        """L(s) (sparse, size x size) for k = tau kappa(tau e^s) and the deltas ``inside`` (m,) 0/1."""
        m = self.m
        e = np.exp(s)
        ex, it = self.exits(s)
        sel = self.Psel + k * self.A
        strip_rows = self.M0 + k * self.MA + (e * k) * self.MK + (e * k * k) * self.MKA
        zero_edges = sp.csr_matrix((2 * m, self.size))
        D_rows = sp.csr_matrix((e * k * self.K_in.ravel(), (np.repeat(np.arange(m), m),
                                                             self.iD + np.tile(np.arange(m), m))), shape=(m, self.size))
        X_rows = e * (ex @ sel)
        Q_rows = e * (it @ sel) + sp.csr_matrix((np.concatenate([inside, -np.ones(m)]),
                                                 (np.tile(np.arange(m), 2),
                                                  np.concatenate([self.iD + np.arange(m), self.iQ + np.arange(m)]))),
                                                shape=(m, self.size))
        return sp.vstack([strip_rows, zero_edges, D_rows, X_rows, Q_rows], format="csc")

    def apply(self, s, k, inside, y):
        """L(s) y without assembling L."""
        m, n_s, strip = self.m, self.n_s, self.strip
        e = np.exp(s)
        C = self.nodes(y, k)
        D = y[self.iD:self.iD + m]
        out = np.zeros(self.size)
        out[:n_s] = self.M0 @ y + k * (self.MA @ y) + (e * k) * (self.MK @ y) + (e * k * k) * (self.MKA @ y)
        out[self.iD:self.iD + m] = e * k * (self.K_in @ D)
        xi = np.exp(-s)
        vmin, vmax = strip.lo[0], strip.hi[-1]
        if vmin <= xi <= vmax:
            out[self.iX:self.iX + m] = e * strip.v * strip.value(C, xi)
        out[self.iQ:self.iQ + m] = (e * strip.integral(C, min(vmax, max(xi, vmin))) + inside * D
                                    - y[self.iQ:self.iQ + m])
        return out


def _impulse(system: _AgeSystem, kap, tau, f, theta, theta0, rtol, atol, method):
    """X and Q of the impulse f at the sorted theta (T,), and at infinity."""
    m = system.m
    speeds = system.speeds
    v = system.strip.v
    y0 = system.initial(f, tau * kap(0.0))
    y0[system.iQ:system.iQ + m] = f  # Q / theta: the impulse whole at theta_0
    breaks = np.log(1.0 / speeds[::-1])  # the deltas' exits, fastest first
    edges = np.concatenate([[np.log(theta0)], breaks])
    X = np.zeros((theta.size, m))
    Q = np.zeros((theta.size, m))
    left = np.zeros(m)  # the deltas that have left
    s_out = np.log(np.maximum(theta, theta0))
    info = {"nfev": 0, "njev": 0, "nlu": 0}
    y = y0
    for k in range(edges.size - 1):
        a, b = edges[k], edges[k + 1]
        inside = (v * np.exp(0.5 * (a + b)) < 1.0).astype(float)

        def c_of(s):
            return tau * kap(tau * np.exp(s))

        def rhs(s, z, inside=inside):
            return system.apply(s, c_of(s), inside, z)

        def jac(s, _z, inside=inside):
            return system.operator(s, c_of(s), inside)

        mask = (s_out > a) & (s_out <= b)
        t_eval = np.unique(np.append(s_out[mask], b))
        sol = integrate(rhs, (float(a), float(b)), y, jac=jac, method=method, rtol=rtol, atol=atol, t_eval=t_eval,
                        what="transient plug flow with kappa(t) and classes at different speeds")
        for key in info:
            info[key] += int(getattr(sol, key))
        Y = sol.y.T
        for i in np.nonzero(mask)[0]:
            row = Y[np.searchsorted(t_eval, s_out[i])]
            at_exit = np.isclose(s_out[i], b, rtol=0.0, atol=1e-14)
            gone = left + (row[system.iD:system.iD + m] * (v == speeds[speeds.size - 1 - k]) if at_exit else 0.0)
            X[i] = row[system.iX:system.iX + m] + gone
            Q[i] = np.exp(s_out[i]) * row[system.iQ:system.iQ + m]
        y = Y[-1]
        group_k = v == speeds[speeds.size - 1 - k]  # the group leaving at b
        left = left + y[system.iD:system.iD + m] * group_k
    X_inf = y[system.iX:system.iX + m] + left
    Q_inf = np.exp(edges[-1]) * y[system.iQ:system.iQ + m]
    early = s_out <= np.log(theta0)
    X[early] = 0.0
    Q[early] = theta[early, None] * f[None, :]
    late = theta >= 1.0 / speeds[0]
    X[late], Q[late] = X_inf, Q_inf
    return X, Q, X_inf, Q_inf, info


@limit_blas_threads
def plug_fronts_age(kap, K, v, tau: float, feed, old, t, *, tol: float = FRONT_TOL, nodes=FRONT_NODES,
                    rtol: float = 1e-9, atol: float | None = None, method: str = "Radau",
                    max_state: int = MAX_STATE):
    """Transient plug flow with kappa(a) kinetics and classes at different speeds (module docstring).

    Parameters
    ----------
    kap : callable
        kappa(a) [-] of the age a [s].
    K : (m, m) array
        Breakage matrix (b - I) diag(S0) [1/s].
    v : (m,) array
        Relative axial velocity d_i* > 0, at least two distinct.
    tau : float
        Mean residence time at d* = 1 [s].
    feed, old : (m,) array
        Feed rates after and before the step at t = 0 [mass/s].
    t : (T,) array
        Times >= 0 [s].
    tol, nodes, rtol, atol, method, max_state
        As :func:`millflow.mill.plug_fronts.plug_fronts` (atol None: 1e-4 rtol times the feed).

    Returns
    -------
    product, holdup : (T, m) arrays
        Discharge [mass/s] and hold-up [mass].
    diff : dict
        ``product`` and ``holdup``: the error estimate.
    info : dict
        Solver counts, nodes and pieces of the returned solve.
    """
    v = np.asarray(v, dtype=float)
    K = np.asarray(K, dtype=float)
    feed, old = np.asarray(feed, float), np.asarray(old, float)
    theta = np.asarray(t, dtype=float) / tau
    th, where = np.unique(theta, return_inverse=True)
    vmin, vmax = float(v.min()), float(v.max())
    rho = max(1.0, tau * float(np.abs(K).sum(axis=1).max()) * max(1.0, float(kap(0.0))))
    theta0 = min(1e-13 / rho, 1e-6 / vmax)
    scale = max(float(feed.sum()), float(old.sum()), 1e-300)
    if atol is None:
        atol = 1e-4 * rtol * scale
    target = {"product": tol * scale, "holdup": tol * tau * scale}

    def run(P, width, r, a):
        system = _AgeSystem(_Strip(v, P, width), K)
        parts, counts = [], {"nfev": 0, "njev": 0, "nlu": 0}
        for f in (feed, old):
            if np.any(f != 0) or f is feed:
                res = _impulse(system, kap, tau, f, th, theta0, r, a, method)
                for key in counts:
                    counts[key] += res[4][key]
            else:
                zero = np.zeros((th.size, v.size))
                res = (zero, zero, np.zeros(v.size), np.zeros(v.size), None)
            parts.append(res)
        (X1, Q1, _, _, _), (X0, Q0, X0i, Q0i, _) = parts
        return X1 + X0i[None, :] - X0, tau * (Q1 + Q0i[None, :] - Q0), counts

    folds = rho / vmin * (vmax - vmin) / vmin
    fine, est, info = refine(run, v, (vmax - vmin) / float(np.clip(folds / 8.0, 1.0, 8.0)), nodes, rtol, atol, tol,
                             target, max_state)
    return fine[0][where], fine[1][where], est, info
