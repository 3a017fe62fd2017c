"""Compartment networks: well-mixed cells joined by flows, as a linear system.

A network of n well-mixed cells has tracer amounts m (n,) obeying dm/dt = A m, with A
the system matrix built from the cell volumes and the flow matrix. A unit pulse split
over the cells by ``inlet`` leaves through ``outlet``, so

    E(t)     = (1 - b) w^T expm(A t) u + b delta(t),     w = outlet / volumes, u = inlet,
    F(t)     = b + (1 - b) [1 - 1^T expm(A t) u],
    E_hat(s) = b + (1 - b) w^T (s I - A)^-1 u,

b the bypass fraction: E(t) by matrix exponential, the transform by one linear solve per
s. The mill reuses the structure (volumes, flows, system matrix) to put breakage inside
every cell. ``RecirculatingCells`` is the usual cells-in-series model with back-mixing,
dead volume and bypass, built on such a network.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from rtd.base import (ParameterError, RTDModel, _as_float, as_s, as_time, check_fraction, check_memory,
                      check_positive)


def _frozen(a) -> np.ndarray:
    arr = np.array(a, dtype=float)
    arr.setflags(write=False)
    return arr


def expm_batch(a: np.ndarray, t: np.ndarray) -> np.ndarray:
    """expm(a t_k) for every t_k, shape (len(t), n, n), by scaling and squaring.

    Taylor polynomial of degree 12 on a t_k / 2^j_k with ||a t_k / 2^j_k||_1 <= 1/4
    (truncation < 0.25^13/13! ~ 2e-18), then j_k squarings. Vectorised over t, unlike
    scipy.linalg.expm whose per-call overhead dominates for small matrices.
    """
    t = np.asarray(t, dtype=float).ravel()
    n = a.shape[0]
    norm = np.abs(a).sum(axis=0).max() * np.abs(t)
    with np.errstate(divide="ignore"):
        j = np.maximum(0, np.ceil(np.log2(norm / 0.25))).astype(int)
    x = a[None] * (t / 2.0**j)[:, None, None]
    eye = np.broadcast_to(np.eye(n), x.shape)
    out = eye.copy()
    for k in range(12, 0, -1):  # Horner: I + x/1 (I + x/2 (I + ...))
        out = eye + np.matmul(x, out) / k
    for step in range(int(j.max(initial=0))):
        sel = j > step
        out[sel] = np.matmul(out[sel], out[sel])
    return out


@dataclass(frozen=True, eq=False)
class CompartmentNetwork:
    """Well-mixed cells with volumes and flows between them.

    Parameters
    ----------
    volumes : array (n,)
        Volume of each cell [any volume unit], > 0.
    flows : array (n, n)
        ``flows[i, j]`` = volumetric flow from cell j into cell i [volume/time], >= 0,
        zero diagonal.
    inlet : array (n,)
        Fraction of the (non-bypassed) feed entering each cell, >= 0, sum 1.
    outlet : array (n,)
        Volumetric flow from each cell to the exit [volume/time], >= 0, not all zero.
    bypass : float
        Fraction of the total feed that goes straight to the exit (an atom of E at
        t = 0, not part of ``pdf``), in [0, 1).

    Notes
    -----
    Volume balance of every cell is checked: sum_j flows[i, j] + inlet_i Q_c =
    sum_k flows[k, i] + outlet_i, with Q_c = sum(outlet) the flow through the cells
    (total feed Q = Q_c / (1 - bypass)). The system matrix, acting on tracer amounts per
    cell (dm/dt = A m), is A[i, j] = flows[i, j]/volumes[j] (i != j),
    A[i, i] = -(sum_k flows[k, i] + outlet_i)/volumes[i]. Mean residence time of the
    whole vessel: sum(volumes) / Q for a network in which every cell is flushed.
    """

    volumes: np.ndarray
    flows: np.ndarray
    inlet: np.ndarray
    outlet: np.ndarray
    bypass: float = 0.0

    def __post_init__(self):
        for name in ("volumes", "flows", "inlet", "outlet"):
            object.__setattr__(self, name, _frozen(getattr(self, name)))
        object.__setattr__(self, "bypass",
                           check_fraction("CompartmentNetwork", "bypass", self.bypass, True))
        self._validate()

    def _validate(self):
        v, f, u, o = self.volumes, self.flows, self.inlet, self.outlet
        n = v.size
        name = "CompartmentNetwork"
        if v.ndim != 1 or n == 0 or f.shape != (n, n) or u.shape != (n,) or o.shape != (n,):
            raise ParameterError(f"{name}: shapes volumes {v.shape}, flows {f.shape}, inlet "
                                 f"{u.shape}, outlet {o.shape}; expected (n,), (n, n), (n,), (n,)")
        for key, arr in (("volumes", v), ("flows", f), ("inlet", u), ("outlet", o)):
            if not np.all(np.isfinite(arr)) or np.any(arr < 0):
                raise ParameterError(f"{name}: {key} has negative or non-finite entries; expected >= 0")
        if np.any(v <= 0):
            raise ParameterError(f"{name}: volumes must be > 0 (cell {int(np.argmin(v))})")
        if np.any(np.diag(f) != 0):
            raise ParameterError(f"{name}: flows must have a zero diagonal")
        if abs(u.sum() - 1) > 1e-9:
            raise ParameterError(f"{name}: inlet sums to {u.sum()!r}; expected 1")
        qc = o.sum()
        if qc <= 0:
            raise ParameterError(f"{name}: outlet is all zero; expected some flow to the exit")
        imbalance = f.sum(axis=1) + u * qc - f.sum(axis=0) - o
        scale = max(qc, f.max(initial=0.0))
        bad = np.flatnonzero(np.abs(imbalance) > 1e-9 * scale)
        if bad.size:
            i = int(bad[0])
            raise ParameterError(f"{name}: cell {i} gains {imbalance[i]!r} volume/time (in - out); "
                                 "expected a volume balance in every cell")

    @property
    def n(self) -> int:
        """Number of cells."""
        return self.volumes.size

    @property
    def feed_flow(self) -> float:
        """Total feed flow Q = sum(outlet)/(1 - bypass) [volume/time]."""
        return float(self.outlet.sum()) / (1.0 - self.bypass)

    def system_matrix(self) -> np.ndarray:
        """A (n, n) [1/time] with dm/dt = A m for tracer amounts m per cell (class doc)."""
        a = self.flows / self.volumes[None, :]
        out = self.flows.sum(axis=0) + self.outlet
        return a - np.diag(out / self.volumes)

    def _w(self) -> np.ndarray:
        return self.outlet / self.volumes

    #: Cells from which a tridiagonal network (a chain) is inverted from its transform
    #: (O(n) per frequency) when its eigenvectors are ill-conditioned (a strongly
    #: advective chain), instead of one expm per time (O(n^3) each); from
    #: CHAIN_ALWAYS_CELLS on always (the eigen-decomposition itself then costs more).
    CHAIN_MIN_CELLS = 64
    CHAIN_ALWAYS_CELLS = 160

    def _chain(self) -> bool:
        if self.n < self.CHAIN_MIN_CELLS or self._bands is None:
            return False
        return self.n >= self.CHAIN_ALWAYS_CELLS or self._modes is None

    def pdf(self, t):
        """E(t) [1/time] without the bypass atom at t = 0."""
        t = as_time(t)
        if self._chain():
            return self._chain_inverse(t, integral=False)
        flat = np.maximum(t.ravel(), 0.0)
        expm_u = self._expm_u(flat)
        out = (1 - self.bypass) * (expm_u @ self._w())
        return np.where(t.ravel() >= 0, out, 0.0).reshape(t.shape)

    def cdf(self, t):
        """F(t) [-], including the bypass atom at t = 0."""
        t = as_time(t)
        if self._chain():
            return self._chain_inverse(t, integral=True)
        flat = np.maximum(t.ravel(), 0.0)
        remaining = self._expm_u(flat).sum(axis=1)
        out = self.bypass + (1 - self.bypass) * (1 - remaining)
        return np.where(t.ravel() >= 0, np.clip(out, 0, 1), 0.0).reshape(t.shape)

    @functools.cached_property
    def _bands(self):
        """(sub, diagonal, super) of A when A is tridiagonal (a chain of cells), else None."""
        a = self.system_matrix()
        if self.n < 3 or np.any(np.triu(a, 2)) or np.any(np.tril(a, -2)):
            return None
        return np.diag(a, -1).copy(), np.diag(a).copy(), np.diag(a, 1).copy()

    def _resolvent(self, s: np.ndarray, left: np.ndarray | None = None) -> np.ndarray:
        """Transfer function w^T (s I - A)^-1 u of a tridiagonal A at complex s.

        w^T (s I - A)^-1 u for a tridiagonal A at complex s (1-D): the Thomas algorithm,
        vectorised over s, O(n) per s. s I - A is diagonally dominant for Re s >= 0 (each
        cell's outflow covers its inflow), so no pivoting is needed there. ``left``
        replaces w (ones: the transform of the tracer still inside).
        """
        lo, di, up = self._bands
        n, u = self.n, self.inlet
        w = self._w() if left is None else np.asarray(left, dtype=float)
        if not np.any(w[:-1]):  # exit from the last cell only: x_n from the forward sweep alone
            cp = -up[0] / (s - di[0])
            dp = u[0] / (s - di[0])
            for k in range(1, n):
                den = (s - di[k]) + lo[k - 1] * cp
                dp = (u[k] + lo[k - 1] * dp) / den if u[k] else (lo[k - 1] * dp) / den
                if k < n - 1:
                    cp = -up[k] / den
            return w[-1] * dp
        check_memory(32.0 * n * s.size, f"{type(self).__name__} chain of {n} cells at {s.size} frequencies")
        cp = np.empty((n, s.size), complex)
        dp = np.empty((n, s.size), complex)
        den = s - di[0]
        cp[0], dp[0] = -up[0] / den, u[0] / den
        for k in range(1, n):
            den = (s - di[k]) + lo[k - 1] * cp[k - 1]
            cp[k] = -up[k] / den if k < n - 1 else 0.0
            dp[k] = (u[k] + lo[k - 1] * dp[k - 1]) / den
        x = dp[n - 1]
        acc = w[n - 1] * x
        for k in range(n - 2, -1, -1):
            x = dp[k] - cp[k] * x
            acc = acc + w[k] * x
        return acc

    def _chain_inverse(self, t: np.ndarray, integral: bool) -> np.ndarray:
        """E(t) or F(t) of a long chain by Fourier inversion of its exact transform.

        E(t) or F(t) of a long chain by Fourier inversion of its exact transform
        (:func:`rtd.inversion.fourier_inverse`: aliasing below e^-45, nodes until
        |E_hat| < 1e-17): the eigenvectors of a strongly advective chain are too
        ill-conditioned for the eigen route, and one expm per time is O(n^3).
        """
        from rtd.inversion import fourier_inverse

        flat = t.ravel()
        part = fourier_inverse(self._resolvent, np.maximum(flat, 0.0), self.analytic_for_re_s_greater_than,
                               integral=integral)
        if integral:
            out = self.bypass + (1 - self.bypass) * part
            return np.where(flat >= 0, np.clip(out, 0, 1), 0.0).reshape(t.shape)
        return np.where(flat >= 0, (1 - self.bypass) * part, 0.0).reshape(t.shape)

    @functools.cached_property
    def _modes(self):
        """(eigenvalues, eigenvectors, V^-1 u) of A, or None if A is not safely diagonal."""
        lam, vec = np.linalg.eig(self.system_matrix())
        # the eigen route is exact and fast when A is diagonalisable and well conditioned;
        # tanks in series give a defective A, handled by one expm per time
        if np.linalg.cond(vec) < 1e6:
            return lam, vec, np.linalg.solve(vec, self.inlet.astype(complex))
        return None

    def _expm_u(self, t: np.ndarray) -> np.ndarray:
        """expm(A t_k) u for every t_k, shape (len(t), n)."""
        if self._modes is not None:
            lam, vec, coef = self._modes
            return ((np.exp(np.outer(t, lam)) * coef[None, :]) @ vec.T).real
        check_memory(8.0 * t.size * self.n * self.n,
                     f"{type(self).__name__} with {self.n} cells at {t.size} times (expm at every time)")
        return expm_batch(self.system_matrix(), t) @ self.inlet

    def laplace(self, s):
        """E_hat(s) = b + (1 - b) w^T (s I - A)^-1 u for real or complex s (any shape)."""
        s, real = as_s(s)
        flat = s.ravel().astype(complex)
        if self._bands is not None and self.n >= self.CHAIN_MIN_CELLS:
            out = (self.bypass + (1 - self.bypass) * self._resolvent(flat)).reshape(s.shape)
            return (out.real if real else out)[()]
        a = self.system_matrix()
        m = flat[:, None, None] * np.eye(self.n)[None] - a[None]
        x = np.linalg.solve(m, np.broadcast_to(self.inlet, (flat.size, self.n))[..., None])[..., 0]
        out = (self.bypass + (1 - self.bypass) * (x @ self._w())).reshape(s.shape)
        return (out.real if real else out)[()]  # 0-d array -> numpy scalar

    #: ``survival_laplace`` is a closed form (no cancellation), see :class:`rtd.RTDModel`.
    exact_survival = True

    def survival_laplace(self, s):
        """G(s) = (1 - E_hat(s))/s = (1 - b) 1^T (s I - A)^-1 u [time], the transform of 1 - F.

        The tracer still inside (1 - F(t) = 1^T m(t), the bypass having left at t = 0): since
        1^T A = -w^T, s 1^T (s I - A)^-1 u = 1 - w^T (s I - A)^-1 u. One solve, no
        cancellation (the plain (1 - E_hat)/s loses eps/(|s| mean)).
        """
        s, real = as_s(s)
        flat = s.ravel().astype(complex)
        ones = np.ones(self.n)
        if self._bands is not None and self.n >= self.CHAIN_MIN_CELLS:
            out = ((1 - self.bypass) * self._resolvent(flat, ones)).reshape(s.shape)
            return (out.real if real else out)[()]
        a = self.system_matrix()
        m = flat[:, None, None] * np.eye(self.n)[None] - a[None]
        x = np.linalg.solve(m, np.broadcast_to(self.inlet, (flat.size, self.n))[..., None])[..., 0]
        out = ((1 - self.bypass) * x.sum(axis=1)).reshape(s.shape)
        return (out.real if real else out)[()]

    def _moment(self, k: int) -> float:
        """k-th raw moment k! w^T (-A)^-(k+1) u times (1 - b)."""
        x = self.inlet.copy()
        if self._bands is not None:  # a chain: banded solves, O(n)
            from scipy.linalg import solve_banded

            lo, di, up = self._bands
            ab = np.zeros((3, self.n))
            ab[0, 1:], ab[1], ab[2, :-1] = -up, -di, -lo
            for _ in range(k + 1):
                x = solve_banded((1, 1), ab, x)
        else:
            a = -self.system_matrix()
            for _ in range(k + 1):
                x = np.linalg.solve(a, x)
        return (1 - self.bypass) * math.factorial(k) * float(self._w() @ x)

    @property
    def mean(self) -> float:
        """Mean residence time [time]."""
        return self._moment(1)

    @property
    def variance(self) -> float:
        """Variance of the residence time [time^2]."""
        return self._moment(2) - self.mean**2

    @property
    def analytic_for_re_s_greater_than(self) -> float:
        """Largest real part of the poles (eigenvalues of A).

        Largest real part of the poles (eigenvalues of A). A chain's A has the
        characteristic polynomial of the symmetric tridiagonal matrix with off-diagonals
        sqrt(sub * super) (only those products enter it): real eigenvalues, computed
        stably by scipy.linalg.eigvalsh_tridiagonal.
        """
        if self._bands is not None:
            from scipy.linalg import eigvalsh_tridiagonal

            lo, di, up = self._bands
            return float(eigvalsh_tridiagonal(di, np.sqrt(lo * up), select="i",
                                              select_range=(self.n - 1, self.n - 1))[0])
        return float(np.linalg.eigvals(self.system_matrix()).real.max())

    @property
    def atom_at_zero(self) -> float:
        """Probability mass leaving at t = 0 (bypass); not part of ``pdf``."""
        return self.bypass

    @classmethod
    def tanks_in_series(cls, tau: float, n: int) -> "CompartmentNetwork":
        """N equal cells in a row, feed flow 1, each of volume tau/n."""
        tau = check_positive("CompartmentNetwork.tanks_in_series", "tau", tau)
        if int(n) != n or n < 1:
            raise ParameterError(f"tanks_in_series: n = {n!r}; expected an integer >= 1")
        check_memory(8.0 * n * n, f"tanks_in_series with {int(n)} cells (an {int(n)} x {int(n)} flow matrix)")
        return cls.cells_in_series(np.full(int(n), tau / n), forward=1.0, backward=0.0)

    @classmethod
    def cells_in_series(cls, volumes, forward: float, backward: float,
                        bypass: float = 0.0) -> "CompartmentNetwork":
        """Cells in a row: flow ``forward`` from cell i to i+1, ``backward`` from i+1 to i.

        The flow through the cells is forward - backward (it enters cell 0 and leaves
        the last cell).
        """
        v = np.asarray(volumes, dtype=float)
        n = v.size
        check_memory(8.0 * n * n, f"cells_in_series with {n} cells (an {n} x {n} flow matrix)")
        q = forward - backward
        f = np.zeros((n, n))
        idx = np.arange(n - 1)
        f[idx + 1, idx] = forward
        f[idx, idx + 1] = backward
        u = np.zeros(n)
        u[0] = 1.0
        o = np.zeros(n)
        o[-1] = q
        return cls(v, f, u, o, bypass)


@dataclass(frozen=True)
class RecirculatingCells(RTDModel):
    """``n`` well-mixed cells in a row with back-mixing, dead volume and bypass.

    Feed flow Q (taken as 1); a fraction ``bypass`` of it goes straight to the exit, the
    rest Q_c = (1 - bypass) Q passes the cells. Between neighbours the forward flow is
    (1 + r) Q_c and the back-mixing flow r Q_c. A fraction ``dead`` of the total volume
    V = tau Q is stagnant; the active volume (1 - dead) V is split equally between
    the cells. Mean residence time (1 - dead) tau (independent of the bypass); with
    r = dead = bypass = 0 it is ``TanksInSeries(tau, n)``; n = 1 is perfect mixing.

    Parameters
    ----------
    tau : float
        V / Q [time], nominal mean residence time including dead volume, > 0.
    n : int
        Number of cells, >= 1 (kept fixed by :func:`rtd.fit`).
    r : float
        Back-mixing (recirculation) ratio [-], >= 0.
    dead, bypass : float
        Fractions in [0, 1).
    """

    tau: float
    n: int
    r: float = 0.0
    dead: float = 0.0
    bypass: float = 0.0
    param_names: ClassVar[tuple[str, ...]] = ("tau", "n", "r", "dead", "bypass")
    fixed_by_default: ClassVar[tuple[str, ...]] = ("n", "dead", "bypass")

    def __post_init__(self):
        name = "RecirculatingCells"
        object.__setattr__(self, "tau", check_positive(name, "tau", self.tau))
        n = _as_float(name, "n", self.n, "an integer >= 1")
        if not math.isfinite(n) or n != round(n) or n < 1:
            raise ParameterError(f"{name}: n = {self.n!r}; expected an integer >= 1")
        object.__setattr__(self, "n", int(round(n)))
        r = _as_float(name, "r", self.r, "a number >= 0")
        if not (math.isfinite(r) and r >= 0):
            raise ParameterError(f"{name}: r = {r!r}; expected a number >= 0")
        object.__setattr__(self, "r", r)
        object.__setattr__(self, "dead", check_fraction(name, "dead", self.dead, True))
        object.__setattr__(self, "bypass", check_fraction(name, "bypass", self.bypass, True))

    def network(self) -> CompartmentNetwork:
        """The compartment network (feed flow 1, volumes in units of tau)."""
        return _recirculating_network(self.tau, self.n, self.r, self.dead, self.bypass)

    def pdf(self, t):
        """E(t), the exit-age density [1/time], at times ``t`` (0 before t = 0)."""
        return self.network().pdf(t)

    def cdf(self, t):
        """F(t), the fraction [-] of the tracer that has left by times ``t``."""
        return self.network().cdf(t)

    def laplace(self, s):
        """E_hat(s), the Laplace transform of E, at real or complex ``s`` [1/time]."""
        return self.network().laplace(s)

    exact_survival: ClassVar[bool] = True

    def survival_laplace(self, s):
        """G(s) = (1 - E_hat(s))/s [time] from the network, without cancellation."""
        return self.network().survival_laplace(s)

    @property
    def mean(self) -> float:
        """Mean residence time [time]."""
        return self.tau * (1 - self.dead)

    @property
    def variance(self) -> float:
        """Variance of the residence time [time^2]."""
        return self.network().variance

    @property
    def atom_at_zero(self) -> float:
        """Probability mass leaving at t = 0 (bypass); not part of ``pdf``."""
        return self.bypass

    @property
    def analytic_for_re_s_greater_than(self) -> float:
        """Abscissa [1/time]: ``laplace`` is analytic for Re s above it."""
        return self.network().analytic_for_re_s_greater_than

    @classmethod
    def from_moments(cls, mean: float, variance: float, n: int = 3, dead: float = 0.0,
                     bypass: float = 0.0) -> "RecirculatingCells":
        """Initial guess: tau from the mean, r from the variance (n, dead, bypass given)."""
        tau = mean / (1 - dead)

        def excess(r):
            return cls(tau, n, r, dead, bypass).variance - variance

        if n == 1 or excess(0.0) >= 0:
            return cls(tau, n, 0.0, dead, bypass)
        if excess(1e4) <= 0:
            return cls(tau, n, 1e4, dead, bypass)
        from scipy import optimize  # here: scipy.optimize is a large share of start-up

        r = optimize.brentq(lambda x: excess(math.expm1(x)), 0.0, math.log1p(1e4), xtol=1e-10)
        return cls(tau, n, math.expm1(r), dead, bypass)


@functools.lru_cache(maxsize=64)
def _recirculating_network(tau: float, n: int, r: float, dead: float, bypass: float) -> CompartmentNetwork:
    """RecirculatingCells' network, cached.

    RecirculatingCells' network, cached: networks are immutable (read-only arrays)
    and building and validating one costs more than a mill's solve with it.
    """
    qc = 1.0 - bypass
    v = np.full(n, tau * (1 - dead) / n)
    return CompartmentNetwork.cells_in_series(v, (1 + r) * qc, r * qc, bypass)
