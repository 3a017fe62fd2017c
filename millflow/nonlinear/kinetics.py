"""Non-linear grinding kinetics as one right-hand side with its analytic Jacobian.

Non-linear grinding kinetics: breakage with rates that depend on the population or slow
down with time, plus aggregation, as one right-hand side with its analytic Jacobian.

    dM/dt = R(M) = (b - I) diag(S[M]) M  +  A(M)            (eq. 4 with non-linear terms)

- population-dependent rates (Bilgili-Scarlett type): S_i[M] = k_i Phi_i(M),
  Phi_i = (1 + sum_j w_ij M_j)^lambda, w an (N, N) interaction matrix (positive w_ij with
  lambda < 0: fines j cushion the breakage of i; lambda > 0: nipping). lambda = 0 or
  w = 0 gives Phi = 1 exactly: the linear model of eq. 4 bit for bit.
- A(M): fixed-pivot aggregation (:mod:`.aggregation`), with the overflow above the top
  class as state component N + 1.
- slowing-down as a function of the fines, S_i = S_i0 kappa(F), F = sum_j m_j M_j the
  mass fraction of the fines (Austin), m_j the share of class j below the fines size
  (:func:`fines_fraction`: 1 below, 0 above, its share in ln x for the class that
  straddles it), kappa and its derivative given by the user (:class:`FinesSlowing`);
- time-dependent slowing-down S_i(t) = S_i0 kappa(t) (Austin): dM/dt = kappa(t) K M,
  solved exactly as the linear solution at theta(t) = int_0^t kappa (:func:`slowing_down`);
  in a continuous mill kappa acts on each particle's age (:class:`AgeSlowing`, solved by
  segregated flow in :mod:`millflow.mill.nonlinear`, or with classification in cells by the
  age-structured balance of :mod:`millflow.mill.age_cells`).

State vector y = (M_1..M_N, overflow): its sum is conserved. :meth:`Kinetics.rate_many`
and :meth:`Kinetics.jacobian_many` evaluate R and dR/dy for many states at once (the
nodes of an axial grid, the cells of a mill): the same formulas, vectorised. Rank-one
interaction matrices (w_ij = u_i v_j, e.g. every class cushioned by the same fines) and
the fines slowing-down give Jacobian terms (B - I) diag(M) dS/dM of rank one, built in
O(N^2) instead of a matrix product.
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

__all__ = ["PopulationRate", "FinesSlowing", "AgeSlowing", "Kinetics", "kinetics", "slowing_down", "theta_of",
           "fines_fraction"]


@dataclass(frozen=True, eq=False)
class PopulationRate:
    """S_i[M] = k_i (1 + sum_j w_ij M_j)^lambda; ``w`` (N, N), ``lam`` finite."""

    w: np.ndarray
    lam: float
    #: (u, v) with w = outer(u, v) exactly, or None (a general w).
    factors: tuple | None = None

    @classmethod
    def make(cls, w, lam, n: int) -> "PopulationRate":
        """Checked population-dependent rates: interaction matrix ``w`` (n, n), exponent ``lam``."""
        if not (isinstance(lam, (int, float)) and math.isfinite(lam)):
            raise InputError(f"lambda = {lam!r}: expected a finite exponent")
        w = np.asarray(w, float)
        if w.shape != (n, n):
            raise InputError(f"w has shape {w.shape}; expected ({n}, {n}) (classes x classes)")
        if not np.isfinite(w).all():
            raise InputError("w: expected finite interaction coefficients")
        return cls(w, float(lam), _rank_one(w))

    def phi(self, M) -> tuple[np.ndarray, np.ndarray]:
        """(Phi, base) with base = 1 + w M (> 0 required); M (N,) or (m, N) (then (m, N) each)."""
        if self.factors is not None:  # w = u v^T: base_i = 1 + u_i (v . M), O(N)
            u, v = self.factors
            base = 1.0 + np.multiply.outer(M @ v, u)
        else:
            base = 1.0 + M @ self.w.T
        if np.any(base <= 0):
            i = int(np.flatnonzero(np.ravel(base) <= 0)[0]) % self.w.shape[0]
            raise SolverError(f"population rate: 1 + sum_j w_ij M_j = {np.ravel(base)[np.ravel(base) <= 0][0]:.6g} "
                              f"<= 0 in class {i + 1}; Phi = (1 + w M)^lambda is undefined there")
        return base ** self.lam, base


def _rank_one(w):
    """The factors (u, v) of a rank-one interaction matrix, else None.

    (u, v) with w == outer(u, v) exactly (a rank-one interaction matrix, e.g. the same
    fines cushioning every class), else None.
    """
    if not w.any():
        return None
    i0, j0 = np.unravel_index(np.argmax(np.abs(w)), w.shape)
    u, v = w[:, j0].copy(), w[i0, :] / w[i0, j0]
    return (u, v) if np.array_equal(np.outer(u, v), w) else None


@dataclass(frozen=True, eq=False)
class FinesSlowing:
    """Austin's slowing-down as a function of the fines.

    S_i = S_i0 kappa(F), F = sum_j mask_j M_j the mass fraction of the fines (mask 1 on the
    fine classes), ``kappa`` a callable of F (>= 0, finite) and ``dkappa`` its derivative
    (the analytic Jacobian).
    """

    mask: np.ndarray
    kappa: Callable
    dkappa: Callable

    def values(self, M) -> tuple[float, float]:
        """Kappa and its derivative at the fines fraction of the state ``M``."""
        F = float(self.mask @ M)
        k, dk = float(self.kappa(F)), float(self.dkappa(F))
        if not (math.isfinite(k) and k >= 0 and math.isfinite(dk)):
            raise SolverError(f"fines slowing-down: kappa({F:.6g}) = {k!r}, kappa'({F:.6g}) = {dk!r}; "
                              "expected kappa finite >= 0 and a finite derivative")
        return k, dk

    def values_many(self, M) -> tuple[np.ndarray, np.ndarray]:
        """(kappa, kappa') (m,) for the states M (m, N)."""
        out = np.array([self.values(row) for row in M]).reshape(-1, 2)
        return out[:, 0], out[:, 1]


@dataclass(frozen=True, eq=False)
class AgeSlowing:
    """Austin's slowing-down in the age of the material.

    Austin's slowing-down in time, S_i = S_i0 kappa(t) with t the age of the material
    (its time in the mill): ``kappa`` a callable of t [s] (>= 0), or ``theta`` the
    transformed time theta(t) = int_0^t kappa [s] in closed form (a callable; then
    ``kappa`` may be None). A batch grind is the linear solution at theta(t)
    (:func:`slowing_down`); a continuous mill averages it over the exit ages
    (segregated flow, exact without classification: each particle breaks at the rate of
    its own age, independently of the others).
    """

    kappa: Callable | None
    theta: Callable | None = None

    def theta_at(self, t) -> np.ndarray:
        """theta(t) [s] for t (T,)."""
        t = np.atleast_1d(np.asarray(t, float))
        if self.theta is not None:
            th = np.array([float(self.theta(float(tk))) for tk in t])
            if not (np.all(np.isfinite(th)) and np.all(th >= 0)):
                raise SolverError(f"age slowing-down: theta(t) = {th!r}; expected finite values >= 0")
            return th
        return theta_of(t, self.kappa)


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
    age: AgeSlowing | None = None

    @property
    def n(self) -> int:
        """Number of classes."""
        return self.S.size

    @property
    def is_linear(self) -> bool:
        """True when nothing non-linear is declared (the exact linear path applies)."""
        return self.population is None and self.aggregation is None and self.fines is None and self.age is None

    @property
    def state_dependent(self) -> bool:
        """True when R depends on the state beyond first order (population, fines, aggregation)."""
        return self.population is not None or self.aggregation is not None or self.fines is not None

    def describe(self) -> str:
        """What these kinetics hold, in words."""
        parts = ["breakage"]
        if self.population is not None:
            parts.append(f"population-dependent rates (lambda {self.population.lam:g})")
        if self.fines is not None:
            parts.append("slowing-down kappa(fines)")
        if self.age is not None:
            parts.append("slowing-down kappa(t) in the material's age")
        if self.aggregation is not None:
            parts.append(f"aggregation ({self.aggregation.kernel_name} kernel)")
        return " + ".join(parts)

    def _no_age(self):
        if self.age is not None:
            raise InputError("kinetics with kappa(t) (slowing-down in the material's age) have no rate R(M) of the "
                             "state alone; expected a batch grind (slowing_down) or a continuous mill (segregated flow "
                             "over the exit ages, or the age-structured cell balance with classification)")

    def rates(self, M) -> np.ndarray:
        """The rates S_i(M) in 1/s for M (N,) or (m, N)."""
        S = self.S if self.population is None else self.S * self.population.phi(M)[0]
        if self.fines is None:
            return S
        if np.ndim(M) == 1:
            return S * self.fines.values(M)[0]
        return S * self.fines.values_many(M)[0][:, None]

    def rate(self, y) -> np.ndarray:
        """R(y), (N + 1,) [1/s]."""
        self._no_age()
        n = self.n
        M = y[:n]
        flux = self.rates(M) * M
        out = np.empty(n + 1)
        out[:n] = self.b @ flux - flux
        out[n] = 0.0
        if self.aggregation is not None:
            out += self.aggregation.rate(M)
        return out

    def rate_many(self, Y) -> np.ndarray:
        """R of every row of Y (m, N + 1): (m, N + 1) [1/s]."""
        self._no_age()
        n = self.n
        M = Y[:, :n]
        flux = self.rates(M) * M
        out = np.zeros(Y.shape)
        out[:, :n] = flux @ self.b.T - flux
        if self.aggregation is not None:
            out += self.aggregation.rate_many(M)
        return out

    def _rate_terms(self, M):
        """The state-dependent rates and their derivatives as rank-one terms.

        (S[M] (m, N), terms, full): the state-dependent rates and dS_i/dM_m as a sum of
        rank-one terms c_i r_m (``terms``: [(c (m, N), r (N,))]) plus ``full`` (m, N, N)
        for a general w (else None).
        """
        m = M.shape[0]
        S = np.broadcast_to(self.S, (m, self.n)).copy()
        terms, full = [], None
        if self.population is not None:
            pop = self.population
            phi, base = pop.phi(M)
            c = self.S * pop.lam * base ** (pop.lam - 1.0)  # dS_i/dM_m = c_i w_im
            if pop.factors is not None:
                u, v = pop.factors
                terms.append((c * u, v))
            else:
                full = c[:, :, None] * pop.w[None, :, :]
            S = S * phi
        if self.fines is not None:
            k, dk = self.fines.values_many(M)
            # product rule: d(S_i kappa(F))/dM_m = dS_i/dM_m kappa + S_i kappa'(F) mask_m
            terms = [(c * k[:, None], r) for c, r in terms]
            if full is not None:
                full = full * k[:, None, None]
            terms.append((S * dk[:, None], self.fines.mask))
            S = S * k[:, None]
        return S, terms, full

    def jacobian_chunks(self, Y):
        """The Jacobian dR/dy at the rows of Y, in chunks.

        dR/dy at the rows of Y (m, N + 1), in chunks: yields (first row, (c, N + 1, N + 1)),
        each chunk below ~120 kB (larger temporaries are fresh memory from the system at
        every call, which costs more than the vectorisation saves).
        """
        c = max(1, 15000 // (self.n + 1) ** 2)
        for s0 in range(0, Y.shape[0], c):
            yield s0, (self.jacobian(Y[s0])[None] if c == 1 else self._jacobian_block(Y[s0:s0 + c]))

    def jacobian_many(self, Y) -> np.ndarray:
        """dR/dy at every row of Y (m, N + 1): (m, N + 1, N + 1) [1/s]."""
        out = np.empty((Y.shape[0], self.n + 1, self.n + 1))
        for s0, J in self.jacobian_chunks(Y):
            out[s0:s0 + J.shape[0]] = J
        return out

    def _jacobian_block(self, Y) -> np.ndarray:
        self._no_age()
        n = self.n
        m = Y.shape[0]
        M = Y[:, :n]
        J = np.zeros((m, n + 1, n + 1))
        if self.population is None and self.fines is None:
            J[:, :n, :n] = self.b * self.S[None, :]
            J[:, np.arange(n), np.arange(n)] -= self.S
        else:
            S, terms, full = self._rate_terms(M)
            J[:, :n, :n] = self.b[None, :, :] * S[:, None, :]
            J[:, np.arange(n), np.arange(n)] -= S
            for c, r in terms:  # (b - I) diag(M) c r^T = ((b - I)(M c)) r^T
                g = (M * c) @ self.b.T - M * c
                J[:, :n, :n] += g[:, :, None] * r[None, None, :]
            if full is not None:
                J[:, :n, :n] += np.einsum("ij,mjk->mik", self.b, M[:, :, None] * full) - M[:, :, None] * full
        if self.aggregation is not None:
            J[:, :, :n] += self.aggregation.jacobian_many(M)
        return J

    def jacobian(self, y) -> np.ndarray:
        """dR/dy, (N + 1, N + 1) dense [1/s]."""
        self._no_age()
        n = self.n
        M = y[:n]
        if self.population is None and self.fines is None:
            S, terms, full = self.S, (), None
        else:
            S, terms, full = self._rate_terms(M[None, :])
            S = S[0]
        Jm = np.empty((n + 1, n + 1))
        Jm[:, n] = 0.0
        top = Jm[:n, :n]
        if self.aggregation is not None:  # (b S) and aggregation in one pass over the block
            self.aggregation.jacobian(M, out=Jm[:, :n], add=self.b * S[None, :])
        else:
            np.multiply(self.b, S[None, :], out=top)
            Jm[n, :n] = 0.0
        top[np.arange(n), np.arange(n)] -= S
        for c, r in terms:  # (b - I) diag(M) c r^T = ((b - I)(M c)) r^T
            mc = M * c[0]
            top += np.multiply.outer(self.b @ mc - mc, r)
        if full is not None:
            X = M[:, None] * full[0]
            top += self.b @ X - X
        return Jm


def kinetics(S, b, *, w=None, lam: float = 0.0, aggregation=None, grid=None, fines_mask=None, kappa=None,
             dkappa=None, kappa_t=None, theta_t=None) -> Kinetics:
    """Checked :class:`Kinetics` from rates, breakage and the non-linear terms.

    Checked :class:`Kinetics`: rates S [1/s] (N,), b (N, N) as eq. 4 (None with S = 0: no
    breakage); ``w``, ``lam`` of the
    population-dependent rates (None: first order); ``aggregation`` an
    :class:`~.aggregation.Aggregation` (needs ``grid``) or an operator on N pivots;
    ``fines_mask`` (N,) of weights in [0, 1] (the share of each class below the fines
    size, :func:`fines_fraction`), ``kappa`` and ``dkappa`` (callables of the fines
    fraction F): slowing-down S_i0 kappa(F) (:class:`FinesSlowing`); ``kappa_t`` (a
    callable of the age t [s]) or ``theta_t`` (theta(t) = int_0^t kappa in closed form):
    slowing-down in the material's age (:class:`AgeSlowing`; alone, without the other
    non-linear terms).
    """
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
        if mask.shape != (S.size,) or not np.all((mask >= 0) & (mask <= 1)):
            raise InputError(f"fines_mask: expected ({S.size},) weights in [0, 1] (the share of each class below "
                             "the fines size: 1 on the fine classes, 0 on the coarse ones)")
        fines = FinesSlowing(mask, kappa, dkappa)
    age = None
    if kappa_t is not None or theta_t is not None:
        if not all(f is None or callable(f) for f in (kappa_t, theta_t)):
            raise InputError("kappa_t, theta_t: expected callables of the age t [s]")
        if pop is not None or op is not None or fines is not None:
            raise InputError("kappa_t (slowing-down in the material's age) combines with no other non-linear term; "
                             "expected first-order breakage with kappa_t alone, or population/fines/aggregation terms")
        age = AgeSlowing(kappa_t, theta_t)
    return Kinetics(S, b, pop, op, fines, age)


def fines_fraction(grid, fines_m: float) -> np.ndarray:
    """The share of each class below ``fines_m`` [m].

    The share of each class (N,) below ``fines_m`` [m]: 1 for a class whose upper size is
    at or below it, 0 for one whose lower size is at or above it, and for the class that
    straddles it its share in ln x, (ln fines - ln x_lower) / (ln x_upper - ln x_lower)
    (the sink's lower edge taken one grid ratio below its upper edge, as for the pivots).
    A size at a grid edge (to 1e-9 relative: sieves and edges computed by different
    products of one ratio differ in the last digits) gives 0/1 exactly; the weights vary
    continuously with ``fines_m`` in between, so a result does not jump when the fines
    size crosses an edge.
    """
    from millflow.grid import as_sizes

    x = as_sizes(grid)
    if not (isinstance(fines_m, (int, float)) and math.isfinite(fines_m) and fines_m > 0):
        raise InputError(f"fines_m = {fines_m!r}: expected a size > 0 [m]")
    lower = np.append(x[1:], x[-1] ** 2 / x[-2]) if x.size > 1 else x / 2.0
    tol = 1e-9
    out = np.where(x <= fines_m * (1 + tol), 1.0, 0.0)
    cut = (lower < fines_m * (1 - tol)) & (x > fines_m * (1 + tol))
    out[cut] = np.log(fines_m / lower[cut]) / np.log(x[cut] / lower[cut])
    return out


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
