"""Residence time distribution models with closed-form E(t), F(t) and transforms.

Each model is a small frozen dataclass holding its parameters by name. It gives the
exit-age density E(t) (``pdf``), its integral F(t) (``cdf``), the Laplace transform
E_hat(s) = int_0^inf E(t) exp(-s t) dt (``laplace``, real or complex s, scalar or array),
the first two moments (``mean``, ``variance``) and the half plane in which the transform
is analytic (``analytic_for_re_s_greater_than``), which contour integrals in the mill
need to avoid poles and branch points. Times are in any unit used consistently
(tau and t in the same unit). Implemented here: perfect mixing, plug flow, tanks in
series (gamma form, real n >= 1); axial dispersion lives in :mod:`rtd.axial`, networks of cells in
:mod:`rtd.compartments`, and the compositions ``Series`` and ``Parallel`` in
:mod:`rtd.compose`.

References: Levenspiel, Chemical Reaction Engineering (1999), ch. 11-14; Wehner and
Wilhelm, Chem. Eng. Sci. 6 (1956) 89.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np


from rtd.base import (  # noqa: F401  (re-exported: rtd.models is where users found them)
    ParameterError,
    RTDError,
    RTDModel,
    as_s,
    as_time,
    check_fraction,
    check_positive,
)
from rtd.compartments import CompartmentNetwork


@dataclass(frozen=True)
class PerfectMixing(RTDModel):
    """One perfectly mixed vessel (CSTR) with mean residence time ``tau`` [time].

    E(t) = exp(-t/tau)/tau, F(t) = 1 - exp(-t/tau), E_hat(s) = 1/(1 + s tau);
    mean tau, variance tau^2; pole at s = -1/tau.
    """

    tau: float
    param_names: ClassVar[tuple[str, ...]] = ("tau",)

    def __post_init__(self):
        object.__setattr__(self, "tau", check_positive("PerfectMixing", "tau", self.tau))

    def pdf(self, t):
        """E(t), the exit-age density [1/time], at times ``t`` (0 before t = 0)."""
        t = as_time(t)
        return np.where(t >= 0, np.exp(-np.maximum(t, 0) / self.tau) / self.tau, 0.0)

    def cdf(self, t):
        """F(t), the fraction [-] of the tracer that has left by times ``t``."""
        t = as_time(t)
        return np.where(t >= 0, -np.expm1(-np.maximum(t, 0) / self.tau), 0.0)

    def laplace(self, s):
        """E_hat(s), the Laplace transform of E, at real or complex ``s`` [1/time]."""
        s, _ = as_s(s)
        return 1.0 / (1.0 + s * self.tau)

    @property
    def mean(self) -> float:
        """Mean residence time [time]."""
        return self.tau

    @property
    def variance(self) -> float:
        """Variance of the residence time [time^2]."""
        return self.tau**2

    @property
    def analytic_for_re_s_greater_than(self) -> float:
        """Abscissa [1/time]: ``laplace`` is analytic for Re s above it."""
        return -1.0 / self.tau

    def network(self):
        """The equivalent one-cell :class:`rtd.CompartmentNetwork` (flow 1, volume tau)."""
        return _tanks_network(self.tau, 1)

    @classmethod
    def from_moments(cls, mean: float, variance: float) -> "PerfectMixing":
        """Initial guess: tau = mean."""
        return cls(mean)


@dataclass(frozen=True)
class PlugFlow(RTDModel):
    """Plug flow with delay ``tau`` [time]: E = delta(t - tau), E_hat = exp(-s tau).

    ``pdf`` returns 0 everywhere (the delta cannot be sampled); ``cdf`` is the unit
    step at tau. For large Re s the transform underflows cleanly to 0; it is entire.
    """

    tau: float
    param_names: ClassVar[tuple[str, ...]] = ("tau",)

    def __post_init__(self):
        object.__setattr__(self, "tau", check_positive("PlugFlow", "tau", self.tau))

    def pdf(self, t):
        """E(t), the exit-age density [1/time], at times ``t`` (0 before t = 0)."""
        return np.zeros_like(as_time(t))

    def cdf(self, t):
        """F(t), the fraction [-] of the tracer that has left by times ``t``."""
        return np.where(as_time(t) >= self.tau, 1.0, 0.0)

    def laplace(self, s):
        """E_hat(s), the Laplace transform of E, at real or complex ``s`` [1/time]."""
        s, _ = as_s(s)
        return np.exp(-s * self.tau)

    @property
    def mean(self) -> float:
        """Mean residence time [time]."""
        return self.tau

    @property
    def variance(self) -> float:
        """Variance of the residence time [time^2]."""
        return 0.0

    @property
    def analytic_for_re_s_greater_than(self) -> float:
        """Abscissa [1/time]: ``laplace`` is analytic for Re s above it."""
        return -math.inf

    @classmethod
    def from_moments(cls, mean: float, variance: float) -> "PlugFlow":
        """Plug flow with the given mean [time]; the variance is not used (it is 0)."""
        return cls(mean)


@dataclass(frozen=True)
class TanksInSeries(RTDModel):
    """``n`` equal perfect mixers in series, total mean residence time ``tau`` [time].

    Gamma form, valid for real n >= 1:
    E(t) = (n/tau)^n t^(n-1) exp(-n t/tau) / Gamma(n),  F(t) = P(n, n t/tau)
    (regularised lower incomplete gamma),  E_hat(s) = (1 + s tau/n)^(-n);
    mean tau, variance tau^2/n. For non-integer n the transform has a branch point at
    s = -n/tau (principal branch, cut along the real axis to the left of it).
    """

    tau: float
    n: float
    param_names: ClassVar[tuple[str, ...]] = ("tau", "n")

    def __post_init__(self):
        object.__setattr__(self, "tau", check_positive("TanksInSeries", "tau", self.tau))
        n = float(self.n)
        if not (math.isfinite(n) and n >= 1.0):
            raise ParameterError(f"TanksInSeries: n = {n!r}; expected a number >= 1")
        object.__setattr__(self, "n", n)

    def pdf(self, t):
        """E(t), the exit-age density [1/time], at times ``t`` (0 before t = 0)."""
        from scipy import special  # here: scipy.special is a large share of start-up

        t = as_time(t)
        x = self.n * np.maximum(t, 0) / self.tau
        # log form: (n/tau) x^(n-1) e^-x / Gamma(n) overflows piecewise for large n
        with np.errstate(divide="ignore"):
            logp = (math.log(self.n / self.tau) + special.xlogy(self.n - 1, x) - x
                    - special.gammaln(self.n))
        out = np.exp(logp)
        return np.where(t > 0, out, (1.0 / self.tau if self.n == 1 else 0.0) * (t == 0))

    def cdf(self, t):
        """F(t), the fraction [-] of the tracer that has left by times ``t``."""
        from scipy import special

        t = as_time(t)
        return special.gammainc(self.n, self.n * np.maximum(t, 0) / self.tau)

    def laplace(self, s):
        """E_hat(s), the Laplace transform of E, at real or complex ``s`` [1/time]."""
        s, real = as_s(s)
        x = s * self.tau / self.n
        if real:
            # left of the branch point only integer n gives a real value (nan otherwise)
            with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
                return np.where(x > -1, np.exp(-self.n * np.log1p(np.maximum(x, -1.0))),
                                np.power(1 + x, -self.n))
        return np.exp(-self.n * np.log1p(x))

    @property
    def mean(self) -> float:
        """Mean residence time [time]."""
        return self.tau

    @property
    def variance(self) -> float:
        """Variance of the residence time [time^2]."""
        return self.tau**2 / self.n

    @property
    def analytic_for_re_s_greater_than(self) -> float:
        """Abscissa [1/time]: ``laplace`` is analytic for Re s above it."""
        return -self.n / self.tau

    def network(self):
        """The equivalent :class:`rtd.CompartmentNetwork` (integer n only)."""
        if self.n != round(self.n):
            raise ParameterError(f"TanksInSeries.network: n = {self.n!r}; expected an integer")
        return _tanks_network(self.tau, int(round(self.n)))

    @classmethod
    def from_moments(cls, mean: float, variance: float) -> "TanksInSeries":
        """Initial guess: tau = mean, n = mean^2/variance (at least 1)."""
        return cls(mean, max(1.0, mean**2 / variance) if variance > 0 else 50.0)


@functools.lru_cache(maxsize=64)
def _tanks_network(tau: float, n: int):
    """N equal cells in a row as a CompartmentNetwork, cached.

    N equal cells in a row as a CompartmentNetwork, cached: networks are immutable
    and validating one costs more than the mill's solve with it.
    """
    net = CompartmentNetwork.tanks_in_series(tau, n)
    for value in vars(net).values():  # shared between callers: nobody may write into it
        if isinstance(value, np.ndarray):
            value.flags.writeable = False
    return net
