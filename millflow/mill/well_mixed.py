"""The perfectly mixed mill at steady state, eq. 3: one member, or a population at once.

    p_i = f_i - tau (S_i/d_i*) p_i + tau sum_{j<i} b_ij (S_j/d_j*) p_j
    <=>  (I - tau K diag(1/d*)) p = f,   K = (b - I) diag(S),

lower triangular, so forward substitution gives the product exactly. With s_i =
tau S_i / d_i* every term of p_i = (f_i + sum_{j<i} b_ij s_j p_j) / (1 + s_i) is
non-negative: nothing cancels, and the relative error is a few N eps. The hold-up per
unit feed rate is tau p_i / d_i*. :func:`solve_well_mixed` is the one-mill solve that
``steady_mill`` runs for ``rtd.PerfectMixing``; :func:`well_mixed_population` the same
substitution for many parameter sets and conditions at once (the fit's hot loop).
"""
from __future__ import annotations

import numpy as np
from scipy.linalg.lapack import dtrtrs

from millflow.errors import InputError
from millflow.linalg import breakage_matrix

__all__ = ["solve_well_mixed", "well_mixed_population", "well_mixed_population_geometric",
           "well_mixed_population_separable"]


def solve_well_mixed(S, b, feed, tau: float, d=None) -> np.ndarray:
    """Product of a perfectly mixed mill at steady state, eq. 3, by one triangular solve.

    Parameters
    ----------
    S : (N,) rates [1/s]; b : (N, N) fractional breakage distribution;
    feed : (N,) or (N, m) feed flows (any unit; the product has the same unit);
    tau : mean residence time [s]; d : (N,) normalised discharge rates
        d_i* = tau d_i (> 0), None for no classification (all ones).
    """
    S = np.asarray(S, dtype=float)
    scaled = S if d is None else S / np.asarray(d, dtype=float)
    M = np.eye(S.size) - tau * breakage_matrix(scaled, b)
    p, info = dtrtrs(M, np.asarray(feed, dtype=float), lower=1)
    if info > 0:
        raise InputError(f"eq. 3 is singular at class {info}: tau * S / d* makes 1 + tau S_i / d_i* zero")
    return p


def well_mixed_population(S, b, feed, tau=1.0, d=None) -> np.ndarray:
    """Eq. 3 for a population of parameter sets (and conditions) at once: (*L, N).

    Parameters
    ----------
    S : (*L, N) rates [1/s], e.g. L = (P, C) for P members and C conditions;
    b : (*Lb, N, N) fractional breakage, Lb broadcasting against L (e.g. (P, 1) when
        the members' b is shared by the conditions, or (N, N) for one b);
    feed : (*Lf, N) feed flows, broadcasting against L (e.g. (C, N));
    tau : mean residence time [s], a scalar or broadcasting against L;
    d : (*Ld, N) normalised discharge d_i*, None for all ones.

    Forward substitution p_i = (f_i + sum_{j<i} b_ij s_j p_j) / (1 + s_i), s = tau S/d*,
    vectorised over the leading axes: the same arithmetic as :func:`solve_well_mixed`,
    to rounding. Nothing is raised for parameter values: non-finite inputs of a member
    give non-finite products (an optimiser's "outside the domain").
    """
    S = np.asarray(S, dtype=float)
    b = np.asarray(b, dtype=float)
    tau = np.asarray(tau, dtype=float)
    s = S * tau[..., np.newaxis] if tau.ndim else S * float(tau)
    if d is not None:
        s = s / np.asarray(d, dtype=float)
    n = s.shape[-1]
    f = np.asarray(feed, dtype=float)
    lead = np.broadcast_shapes(s.shape[:-1], f.shape[:-1], b.shape[:-2])
    s = np.broadcast_to(s, lead + (n,))
    f = np.broadcast_to(f, lead + (n,))
    b_lead = (1,) * (len(lead) - (b.ndim - 2)) + b.shape[:-2]
    with np.errstate(over="ignore", invalid="ignore"):
        if len(lead) >= 1 and b_lead[-1] == 1 and lead[-1] > 1:
            return _substitute_shared(s, np.broadcast_to(b.reshape(b_lead + (n, n))[..., 0, :, :],
                                                         lead[:-1] + (n, n)), f)
        q = np.zeros(lead + (n,))  # q_j = s_j p_j, the broken mass flow out of class j
        p = np.empty(lead + (n,))
        denom = 1.0 + s
        for i in range(n):
            acc = f[..., i] + np.einsum("...j,...j->...", b[..., i, :i], q[..., :i]) if i else f[..., 0]
            p[..., i] = acc / denom[..., i]
            q[..., i] = s[..., i] * p[..., i]
    return p


def _substitute_shared(s, b, f):
    """The substitution when b is shared along the last leading axis (conditions):
    s, f (*B, C, N), b (*B, N, N). The sum over j < i is then one batched matrix
    product per class, b[..., i, :i] @ q[..., :i, :], with classes before conditions."""
    n = s.shape[-1]
    sT = np.swapaxes(s, -1, -2)
    fT = np.swapaxes(f, -1, -2)
    q = np.zeros(sT.shape)
    p = np.empty(sT.shape)
    denom = 1.0 + sT
    for i in range(n):
        acc = fT[..., i, :] + np.matmul(b[..., i:i + 1, :i], q[..., :i, :])[..., 0, :] if i else fT[..., 0, :]
        p[..., i, :] = acc / denom[..., i, :]
        q[..., i, :] = sT[..., i, :] * p[..., i, :]
    return np.swapaxes(p, -1, -2)


def well_mixed_population_geometric(S, feed, phi, gamma, beta, ratio: float, tau=1.0, d=None) -> np.ndarray:
    """Eq. 3 with the eq. 6 breakage of a geometric grid, in O(N) per member: (*L, N).

    On a grid with a fixed ratio R = x_k/x_{k+1} the eq. 6 distribution depends on
    i - j only: B_ij = phi c1^m + (1 - phi) c2^m with m = i - 1 - j, c1 = R^-gamma,
    c2 = R^-beta. The breakage sum of eq. 3 then follows two first-order recurrences
    instead of a dot product over all coarser classes,

        H_i = c H_{i-1} + q_{i-1} (H_0 = 0),  sum_{j<i} b_ij q_j = phi (1 - c1) H1_i
        + (1 - phi)(1 - c2) H2_i  (i < N),  and phi H1_N + (1 - phi) H2_N for the sink,

    with q_j = s_j p_j: the same products as :func:`well_mixed_population` with the
    b of :func:`millflow.breakage.distributions.breakage_population`, to rounding
    (every term is non-negative, nothing cancels), at a cost of O(N) instead of O(N^2).
    It is :func:`well_mixed_population_separable` with the weights phi S and (1 - phi) S.

    Parameters
    ----------
    S : (*L, N) rates [1/s]; feed : (*Lf, N) feed flows; phi, gamma, beta : eq. 6
        parameters broadcasting to L (phi = 1 for B = r^gamma); ratio : the grid's
        ratio x_k/x_{k+1} (> 1); tau, d : as :func:`well_mixed_population`.
    """
    S = np.asarray(S, dtype=float)
    phi, gamma, beta = (np.asarray(v, dtype=float) for v in (phi, gamma, beta))
    log_r = -np.log(float(ratio))
    with np.errstate(over="ignore", invalid="ignore"):
        c1, c2 = np.exp(gamma * log_r), np.exp(beta * log_r)
        # the upper-edge transfer S_j B_ij = S_j [phi c1^(i-1-j) + (1 - phi) c2^(i-1-j)]: weights phi S, (1 - phi) S
        w1, w2 = phi[..., np.newaxis] * S, (1.0 - phi)[..., np.newaxis] * S
    p = well_mixed_population_separable(S, feed, w1, c1, w2, c2, tau, d)
    ok = np.broadcast_to((phi >= 0) & (phi <= 1) & (gamma >= 0) & (beta >= 0), p.shape[:-1])
    if not ok.all():
        p = np.where(ok[..., np.newaxis], p, np.nan)  # outside eq. 6's domain, as breakage_population
    return p


def well_mixed_population_separable(S, feed, w1, c1, w2, c2, tau=1.0, d=None) -> np.ndarray:
    """Eq. 3 in O(N) per member for breakage whose transfer separates on a geometric grid: (*L, N).

    For class-averaged eqs. 6/8 on a grid of fixed ratio (:func:`millflow.breakage.averaged.
    averaged_power_terms`) the broken flow out of class j that is finer than edge x_i is
    T_ij = c1^(i-j) a1_j + c2^(i-j) a2_j per unit of u_j = tau p_j / d_j*, so that
    sum_{j<i} b_ij s_j p_j = sum_{j<i} (T_ij - T_{i+1,j}) u_j follows two first-order
    recurrences,

        H_i = c H_{i-1} + w_{i-1} u_{i-1} (H_0 = 0, w_j = c a_j),
        sum_{j<i} b_ij s_j p_j = (1 - c1) H1_i + (1 - c2) H2_i  (i < N),  H1_N + H2_N (sink),

    and p_i = (f_i + that sum) / (1 + s_i), s_i = tau S_i / d_i*. With w1 = phi S,
    w2 = (1 - phi) S it is :func:`well_mixed_population_geometric` (Austin's upper edges).
    Every term is non-negative: nothing cancels.

    Parameters
    ----------
    S : (*L, N) leaving rates [1/s]; feed : (*Lf, N) feed flows;
    w1, w2 : (*L, N) weights [1/s] (last entry unused); c1, c2 : ratios R^-gamma, R^-beta
        broadcasting to L (in [0, 1]); tau, d : as :func:`well_mixed_population`.
    """
    S = np.asarray(S, dtype=float)
    tau = np.asarray(tau, dtype=float)
    dd = 1.0 if d is None else np.asarray(d, dtype=float)
    t_d = (tau[..., np.newaxis] if tau.ndim else float(tau)) / dd
    s = S * t_d
    n = s.shape[-1]
    f = np.asarray(feed, dtype=float)
    w1, w2 = np.asarray(w1, dtype=float), np.asarray(w2, dtype=float)
    c1, c2 = np.asarray(c1, dtype=float), np.asarray(c2, dtype=float)
    shape = np.broadcast_shapes(s.shape[:-1], f.shape[:-1], w1.shape[:-1], w2.shape[:-1], np.shape(t_d)[:-1],
                                c1.shape, c2.shape)
    lead = shape or (1,)

    def classes_first(v):
        # (N, *v's own leading shape), contiguous per class: broadcast against lead where used
        # (a feed shared by all members is not copied for each)
        v = np.asarray(v, dtype=float)
        return np.ascontiguousarray(np.moveaxis(np.broadcast_to(v, v.shape[:-1] + (n,)), -1, 0))

    with np.errstate(over="ignore", invalid="ignore"):
        sT, fT, tT = classes_first(s), classes_first(f), classes_first(t_d)
        w1T, w2T = classes_first(w1), classes_first(w2)
        c1, c2 = np.broadcast_to(c1, lead), np.broadcast_to(c2, lead)
        e1, e2 = 1.0 - c1, 1.0 - c2
        dT = 1.0 + sT
        pT = np.empty((n,) + lead)
        h1, h2, acc, u = np.zeros(lead), np.zeros(lead), np.empty(lead), np.empty(lead)
        np.divide(fT[0], dT[0], out=pT[0])
        np.multiply(tT[0], pT[0], out=u)
        for i in range(1, n):
            h1 *= c1
            h1 += w1T[i - 1] * u
            h2 *= c2
            h2 += w2T[i - 1] * u
            if i == n - 1:
                np.add(h1, h2, out=acc)
            else:
                np.multiply(e1, h1, out=acc)
                acc += e2 * h2
            acc += fT[i]
            np.divide(acc, dT[i], out=pT[i])
            np.multiply(tT[i], pT[i], out=u)
        p = np.moveaxis(pT, 0, -1)
    return p.reshape(shape + (n,))
