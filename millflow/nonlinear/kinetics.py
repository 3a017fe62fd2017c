"""Non-linear grinding kinetics: breakage with rates that depend on the population or slow
down with time, plus aggregation, as one right-hand side with its analytic Jacobian.

    dM/dt = R(M) = (b - I) diag(S[M]) M  +  A(M)            (eq. 4 with non-linear terms)

- population-dependent rates (Bilgili-Scarlett type): S_i[M] = k_i Phi_i(M),
  Phi_i = (1 + sum_j w_ij M_j)^lambda, w an (N, N) interaction matrix (positive w_ij with
  lambda < 0: fines j cushion the breakage of i; lambda > 0: nipping). lambda = 0 or
  w = 0 gives Phi = 1 exactly: the linear model of eq. 4 bit for bit.
- A(M): fixed-pivot aggregation (:mod:`.aggregation`), with the overflow above the top
  class as state component N + 1.
- slowing-down as a function of the fines, S_i = S_i0 kappa(F), F = mass fraction of the
  fine classes (Austin), kappa and its derivative given by the user (:class:`FinesSlowing`);
- time-dependent slowing-down S_i(t) = S_i0 kappa(t) (Austin): dM/dt = kappa(t) K M,
  solved exactly as the linear solution at theta(t) = int_0^t kappa (:func:`slowing_down`).

State vector y = (M_1..M_N, overflow): its sum is conserved.
"""
from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy.integrate import quad

from millflow import checks
from millflow.batch import BatchResult, batch_solve
from millflow.errors import InputError, SolverError
from millflow.nonlinear.aggregation import Aggregation, AggregationOperator

__all__ = ["PopulationRate", "FinesSlowing", "Kinetics", "kinetics", "slowing_down", "theta_of"]


@dataclass(frozen=True, eq=False)
class PopulationRate:
    """S_i[M] = k_i (1 + sum_j w_ij M_j)^lambda; ``w`` (N, N), ``lam`` finite."""

    w: np.ndarray
    lam: float

    @classmethod
    def make(cls, w, lam, n: int) -> "PopulationRate":
        if not (isinstance(lam, (int, float)) and math.isfinite(lam)):
            raise InputError(f"lambda = {lam!r}: expected a finite exponent")
        w = np.asarray(w, float)
        if w.shape != (n, n):
            raise InputError(f"w has shape {w.shape}; expected ({n}, {n}) (classes x classes)")
        if not np.isfinite(w).all():
            raise InputError("w: expected finite interaction coefficients")
        return cls(w, float(lam))

    def phi(self, M) -> tuple[np.ndarray, np.ndarray]:
        """(Phi, base) with base = 1 + w M (> 0 required)."""
        base = 1.0 + self.w @ M
        if np.any(base <= 0):
            i = int(np.flatnonzero(base <= 0)[0])
            raise SolverError(f"population rate: 1 + sum_j w_ij M_j = {base[i]:.6g} <= 0 in class {i + 1}; "
                              "Phi = (1 + w M)^lambda is undefined there")
        return base ** self.lam, base


@dataclass(frozen=True, eq=False)
class FinesSlowing:
    """Austin's slowing-down as a function of the fines: S_i = S_i0 kappa(F), F = sum_j
    mask_j M_j the mass fraction of the fines (mask 1 on the fine classes), ``kappa`` a
    callable of F (>= 0, finite) and ``dkappa`` its derivative (the analytic Jacobian)."""

    mask: np.ndarray
    kappa: Callable
    dkappa: Callable

    def values(self, M) -> tuple[float, float]:
        F = float(self.mask @ M)
        k, dk = float(self.kappa(F)), float(self.dkappa(F))
        if not (math.isfinite(k) and k >= 0 and math.isfinite(dk)):
            raise SolverError(f"fines slowing-down: kappa({F:.6g}) = {k!r}, kappa'({F:.6g}) = {dk!r}; "
                              "expected kappa finite >= 0 and a finite derivative")
        return k, dk


@dataclass(frozen=True, eq=False)
class Kinetics:
    """Breakage (k = S, b), optional population-dependent rates and aggregation.

    ``rate(y)`` and ``jacobian(y)`` act on y = (M, overflow), N + 1 components.
    """

    S: np.ndarray
    b: np.ndarray
    population: PopulationRate | None = None
    aggregation: AggregationOperator | None = None
    fines: FinesSlowing | None = None

    @property
    def n(self) -> int:
        return self.S.size

    @property
    def is_linear(self) -> bool:
        """True when nothing non-linear is declared (the exact linear path applies)."""
        return self.population is None and self.aggregation is None and self.fines is None

    def describe(self) -> str:
        parts = ["breakage"]
        if self.population is not None:
            parts.append(f"population-dependent rates (lambda {self.population.lam:g})")
        if self.fines is not None:
            parts.append("slowing-down kappa(fines)")
        if self.aggregation is not None:
            parts.append(f"aggregation ({self.aggregation.kernel_name} kernel)")
        return " + ".join(parts)

    def rates(self, M) -> np.ndarray:
        S = self.S if self.population is None else self.S * self.population.phi(M)[0]
        return S if self.fines is None else S * self.fines.values(M)[0]

    def rate(self, y) -> np.ndarray:
        """R(y), (N + 1,) [1/s]."""
        n = self.n
        M = y[:n]
        flux = self.rates(M) * M
        out = np.empty(n + 1)
        out[:n] = self.b @ flux - flux
        out[n] = 0.0
        if self.aggregation is not None:
            out += self.aggregation.rate(M)
        return out

    def jacobian(self, y) -> np.ndarray:
        """dR/dy, (N + 1, N + 1) dense [1/s]."""
        n = self.n
        M = y[:n]
        Jm = np.zeros((n + 1, n + 1))
        Bm = self.b - np.eye(n)
        if self.population is None and self.fines is None:
            Jm[:n, :n] = Bm * self.S[None, :]
        else:
            S, dS = self.S.copy(), np.zeros((n, n))
            if self.population is not None:
                phi, base = self.population.phi(M)
                # dS_i/dM_m = k_i lambda base_i^(lambda-1) w_im
                dS = (self.S * self.population.lam * base ** (self.population.lam - 1.0))[:, None] * self.population.w
                S = S * phi
            if self.fines is not None:
                k, dk = self.fines.values(M)
                # product rule: d(S_i kappa(F))/dM_m = dS_i/dM_m kappa + S_i kappa'(F) mask_m
                dS = dS * k + dk * S[:, None] * self.fines.mask[None, :]
                S = S * k
            Jm[:n, :n] = Bm * S[None, :] + Bm @ (M[:, None] * dS)
        if self.aggregation is not None:
            Jm[:, :n] += self.aggregation.jacobian(M)
        return Jm


def kinetics(S, b, *, w=None, lam: float = 0.0, aggregation=None, grid=None, fines_mask=None, kappa=None,
             dkappa=None) -> Kinetics:
    """Checked :class:`Kinetics`: rates S [1/s] (N,), b (N, N) as eq. 4 (None with S = 0: no
    breakage); ``w``, ``lam`` of the
    population-dependent rates (None: first order); ``aggregation`` an
    :class:`~.aggregation.Aggregation` (needs ``grid``) or an operator on N pivots;
    ``fines_mask`` (N,) of 0/1, ``kappa`` and ``dkappa`` (callables of the fines fraction F):
    slowing-down S_i0 kappa(F) (:class:`FinesSlowing`)."""
    if b is None:  # pure aggregation: no breakage; a placeholder b that S = 0 never uses
        S = np.asarray(S, float)
        if S.ndim != 1 or np.any(S != 0):
            raise InputError("b is None (no breakage): expected S of zeros")
        b = np.eye(S.size, k=-1)
    S, b = checks.kernel(S, b)
    pop = None if w is None else PopulationRate.make(w, lam, S.size)
    if w is None and lam != 0.0:
        raise InputError(f"lambda = {lam!r} given without w; expected w (N, N) with lambda")
    op = aggregation
    if isinstance(aggregation, Aggregation):
        if grid is None:
            raise InputError("aggregation: give grid= (the size grid the pivots are built on)")
        op = aggregation.on(grid)
    if op is not None:
        if not isinstance(op, AggregationOperator):
            raise InputError(f"aggregation: expected Aggregation or AggregationOperator, got {type(op).__name__}")
        if op.n != S.size:
            raise InputError(f"aggregation acts on {op.n} classes; the rates have {S.size}")
    fines = None
    if kappa is not None or fines_mask is not None or dkappa is not None:
        if kappa is None or dkappa is None or fines_mask is None:
            raise InputError("fines slowing-down: give fines_mask, kappa and dkappa together")
        if not (callable(kappa) and callable(dkappa)):
            raise InputError("kappa and dkappa: expected callables of the fines fraction F")
        mask = np.asarray(fines_mask, float)
        if mask.shape != (S.size,) or not np.all((mask == 0) | (mask == 1)):
            raise InputError(f"fines_mask: expected ({S.size},) zeros and ones (1 on the fine classes)")
        fines = FinesSlowing(mask, kappa, dkappa)
    return Kinetics(S, b, pop, op, fines)


def theta_of(t, kappa) -> np.ndarray:
    """theta(t) = int_0^t kappa [s] by adaptive quadrature (relative tolerance 1e-12)."""
    t = np.atleast_1d(np.asarray(t, float))
    out = []
    for tk in t:
        with warnings.catch_warnings():  # a bad integral is checked and raised below
            warnings.simplefilter("ignore")
            val, err = quad(kappa, 0.0, float(tk), epsabs=0.0, epsrel=1e-12, limit=200)
        if not (np.isfinite(val) and val >= 0 and err <= 1e-10 * max(abs(val), 1e-300)):
            raise SolverError(f"slowing-down: int_0^{float(tk)!r} kappa = {val!r} (error estimate {err!r}); "
                              "expected a finite integral >= 0 to 1e-10")
        out.append(val)
    return np.array(out)


def slowing_down(S0, b, feed, t, kappa=None, *, theta=None) -> BatchResult:
    """Batch grinding with S(t) = S0 kappa(t): the exact linear solution at theta(t).

    ``kappa`` a callable of t [s] (kappa >= 0), integrated by :func:`theta_of`; or
    ``theta``, the transformed times theta(t) = int_0^t kappa [s] when they are known in
    closed form (one of the two). The result's ``info`` holds theta.
    """
    if (kappa is None) == (theta is None):
        raise InputError("slowing_down: give kappa (a callable of t) or theta (the transformed times), not both")
    start = time.perf_counter()
    th = theta_of(t, kappa) if theta is None else np.atleast_1d(np.asarray(theta, float))
    res = batch_solve(S0, b, feed, th)
    info = {**res.info, "theta_s": th, "equation": "M(t) = exp(K theta(t)) feed, theta = int_0^t kappa"}
    return BatchResult(res.M, np.atleast_1d(np.asarray(t, float)), "exact (theta)", res.error_estimate,
                       res.mass_balance_error, time.perf_counter() - start, info)
