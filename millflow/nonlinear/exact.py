"""Exact solutions for validating the non-linear kinetics, as mass fractions per class.

All are for an exponential distribution in volume (volumes in units of x_ref^3), total mass 1,
and are evaluated by cell: the mass between the class edges (lower, upper] in volume.

- :func:`scott_constant`: constant kernel beta0, initial n0(v) = N0/v0 exp(-v/v0) (N0 v0 = 1).
  Scott (1968), J. Atmos. Sci. 25, 54: n(v, t) = 4 N0 / (v0 (T+2)^2) exp(-2v / (v0 (T+2))),
  T = beta0 N0 t. Mass in (a, b]: G(a/c) - G(b/c), G(z) = (1 + z) e^(-z), c = v0 (T+2)/2.
- :func:`golovin_sum`: sum kernel beta0 (u + v), same initial state. Golovin (1963); Scott (1968):
  n(v, t) = N0 (1-tau) / (v sqrt(tau)) exp(-(1+tau) v/v0) I1(2 sqrt(tau) v/v0),
  tau = 1 - exp(-beta0 N0 v0 t). Cell masses by adaptive quadrature (scaled Bessel ive).
- :func:`patil_andrews_steady`: constant aggregation beta0 with binary breakage at rate
  S0 v into uniformly distributed fragments (b(v|u) = 2/u). The steady state is the
  exponential n = A exp(-a v), A = 2 S0 / beta0, a = sqrt(A / m1) (Patil and Andrews 1998,
  Chem. Eng. Sci. 53, 599; substitute: aggregation birth (beta0/2) A^2 v e^(-av) and
  breakage loss S0 v A e^(-av) cancel when A = 2 S0/beta0, the two loss-gain pairs
  independent of v cancel for the same A). :func:`uniform_binary_breakage` gives its
  breakage on pivots by fixed pivots (number and mass kept), in millflow's (S, b) form.
"""
from __future__ import annotations

import warnings

import numpy as np
from scipy.integrate import quad
from scipy.special import ive

from millflow.errors import InputError, SolverError
from millflow.grid import as_sizes

__all__ = ["volume_edges", "scott_constant", "golovin_sum", "patil_andrews_steady", "uniform_binary_breakage"]


def volume_edges(grid, x_ref_m: float) -> tuple[np.ndarray, np.ndarray]:
    """(lower, upper) volume edges of every class in units of x_ref^3 (sink lower edge 0)."""
    x = as_sizes(grid) / x_ref_m
    return np.append(x[1:], 0.0) ** 3, x ** 3


def _G(z):
    return (1.0 + z) * np.exp(-z)


def scott_constant(lower, upper, beta0: float, t: float, v0: float = 1.0) -> np.ndarray:
    """Cell masses at time t [s] under the constant kernel (N0 = 1/v0)."""
    T = beta0 * t / v0
    c = v0 * (T + 2.0) / 2.0
    return _G(np.asarray(lower) / c) - _G(np.asarray(upper) / c)


def golovin_sum(lower, upper, beta0: float, t: float, v0: float = 1.0) -> np.ndarray:
    """Cell masses at time t [s] under the sum kernel beta0 (u + v) (N0 = 1/v0)."""
    tau = -np.expm1(-beta0 * t)  # beta0 N0 v0 t with N0 v0 = 1
    if tau == 0.0:
        return scott_constant(lower, upper, beta0, 0.0, v0)
    s = np.sqrt(tau)

    def f(x):
        return ive(1, 2.0 * s * x) * np.exp(-(1.0 - s) ** 2 * x)

    out = []
    for a, b in zip(np.asarray(lower, float) / v0, np.asarray(upper, float) / v0):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            val, err = quad(f, a, b, epsabs=1e-16, epsrel=1e-13, limit=200)
        if not np.isfinite(val) or err > 1e-10:
            raise SolverError(f"golovin_sum: quadrature over ({a:g}, {b:g}] did not converge (error {err:g})")
        out.append(val)
    return (1.0 - tau) / s * np.array(out)


def patil_andrews_steady(lower, upper, beta0: float, S0: float) -> np.ndarray:
    """Steady cell masses (total 1) of constant aggregation + uniform binary breakage S0 v."""
    if beta0 <= 0 or S0 <= 0:
        raise InputError("patil_andrews_steady: beta0 and S0 must be > 0")
    a = np.sqrt(2.0 * S0 / beta0)
    return _G(a * np.asarray(lower)) - _G(a * np.asarray(upper))


def uniform_binary_breakage(v, S0: float) -> tuple[np.ndarray, np.ndarray]:
    """(S [1/s], b) of binary breakage at rate S0 v_j into uniform fragments, on pivots v
    (decreasing), by fixed pivots: fragment number 2/u per unit volume on (0, u) shared
    between neighbouring pivots keeping number and mass; below the smallest pivot, mass
    only. The part that lands back on the parent's own pivot is removed exactly by
    S_j' = S_j (1 - b_jj), b_ij' = b_ij / (1 - b_jj). The sink (last pivot) does not break."""
    v = np.asarray(v, float)
    n = v.size

    def lin(lo, hi, p, q):  # int_lo^hi (v - p)/(q - p) dv, for lo <= hi
        return ((hi - p) ** 2 - (lo - p) ** 2) / (2.0 * (q - p))

    S = np.zeros(n)
    b = np.zeros((n, n))
    for j in range(n - 1):
        u = v[j]
        mass = np.zeros(n)
        for i in range(j, n):
            num = 0.0
            if i > j:  # fragments between v_i and the pivot above, v_{i-1}, capped at u
                hi = min(v[i - 1], u)
                num += lin(v[i], hi, v[i - 1], v[i]) if hi > v[i] else 0.0
            if i < n - 1:  # fragments between v_{i+1} and v_i
                num += lin(v[i + 1], v[i], v[i + 1], v[i])
                mass[i] = v[i] * num * 2.0 / u
            else:  # the smallest pivot also takes all mass below it
                mass[i] = v[i] * num * 2.0 / u + (v[i] ** 2 / 2.0) * 2.0 / u
        frac = mass / u
        self_part = frac[j]
        S[j] = S0 * u * (1.0 - self_part)
        b[j + 1:, j] = frac[j + 1:] / (1.0 - self_part)
    return S, b
