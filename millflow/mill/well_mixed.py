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

__all__ = ["solve_well_mixed", "well_mixed_population"]


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
