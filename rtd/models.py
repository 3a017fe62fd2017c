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
    _as_float,
    as_s,
    as_time,
    check_fraction,
    check_positive,
    clog1p,
)
from rtd.compartments import CompartmentNetwork


@dataclass(frozen=True)
class PerfectMixing(RTDModel):
    """One perfectly mixed vessel (CSTR) with mean residence time ``tau`` [time].

    E(t) = exp(-t/tau)/tau, F(t) = 1 - exp(-t/tau), E_hat(s) = 1/(1 + s tau);
    mean tau, variance tau^2; pole at s = -1/tau.

    Parameters
    ----------
    tau : float
        Mean residence time [time, any unit; s inside millflow], > 0.

    References
    ----------
    O. Levenspiel, Chemical Reaction Engineering, 3rd ed. (Wiley, 1999), ch. 11;
    P. V. Danckwerts, Continuous flow systems: distribution of residence times,
    Chem. Eng. Sci. 2 (1953) 1-13.

    Examples
    --------
    >>> m = PerfectMixing(tau=5.0)
    >>> round(float(m.cdf(5.0)), 6)  # 1 - 1/e of a pulse has left after one mean residence time
    0.632121
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

    exact_survival: ClassVar[bool] = True

    def survival_laplace(self, s):
        """G(s) = (1 - E_hat(s))/s = tau/(1 + s tau) [time], the transform of 1 - F(t)."""
        s, real = as_s(s)
        out = self.tau / (1.0 + s * self.tau)
        return (out.real if real else out)[()]

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

    Parameters
    ----------
    tau : float
        Delay (mean residence time) [time], > 0.

    References
    ----------
    O. Levenspiel, Chemical Reaction Engineering, 3rd ed. (Wiley, 1999), ch. 11;
    P. V. Danckwerts, Continuous flow systems: distribution of residence times,
    Chem. Eng. Sci. 2 (1953) 1-13.

    Examples
    --------
    >>> PlugFlow(tau=2.0).cdf([1.9, 2.0])
    array([0., 1.])
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

    exact_survival: ClassVar[bool] = True

    def survival_laplace(self, s):
        """G(s) = (1 - exp(-s tau))/s = -tau expm1(-x)/x, x = s tau [time]; tau at s = 0."""
        s, real = as_s(s)
        x = s * self.tau
        safe = np.where(x == 0, 1.0, x)
        out = np.where(x == 0, self.tau, -self.tau * np.expm1(-safe) / safe)
        return (out.real if real else out)[()]

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

    Parameters
    ----------
    tau : float
        Total mean residence time [time], > 0.
    n : float
        Number of tanks [-], >= 1 (real: the gamma form of a fitted tracer curve).

    References
    ----------
    O. Levenspiel, Chemical Reaction Engineering, 3rd ed. (Wiley, 1999), ch. 14 (the tanks-in-series model);
    P. V. Danckwerts, Continuous flow systems: distribution of residence times,
    Chem. Eng. Sci. 2 (1953) 1-13.

    Examples
    --------
    >>> m = TanksInSeries(tau=6.0, n=3)
    >>> round(float(m.laplace(0.5)), 12), m.variance  # (1 + s tau/n)^-n = 1/8; tau^2/n
    (0.125, 12.0)
    """

    tau: float
    n: float
    param_names: ClassVar[tuple[str, ...]] = ("tau", "n")

    def __post_init__(self):
        object.__setattr__(self, "tau", check_positive("TanksInSeries", "tau", self.tau))
        n = _as_float("TanksInSeries", "n", self.n, "a number >= 1")
        if not (math.isfinite(n) and n >= 1.0):
            raise ParameterError(f"TanksInSeries: n = {n!r}; expected a number >= 1")
        object.__setattr__(self, "n", n)

    def pdf(self, t):
        """E(t), the exit-age density [1/time], at times ``t`` (0 before t = 0)."""
        from scipy import special  # here: scipy.special is a large share of start-up

        t = as_time(t)
        if self.n > LARGE_N:
            # d = (t - tau)/tau: t - tau is exact near the peak, where E's condition number is n d
            return np.where(t > 0, _gamma_pdf_large(self.n, (t - self.tau) / self.tau) / self.tau, 0.0)
        # t beyond ~1e308/n overflows x: E there is 0 (e^-x wins over every power of x)
        x = np.minimum(np.maximum(t, 0) / self.tau, 1e300 / self.n) * self.n
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
        if self.n > LARGE_N:
            return _gamma_cdf_large(self.n, (np.maximum(t, 0) - self.tau) / self.tau)
        return special.gammainc(self.n, np.minimum(np.maximum(t, 0) / self.tau, 1e300 / self.n) * self.n)

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

    exact_survival: ClassVar[bool] = True

    def survival_laplace(self, s):
        """G(s) = (1 - E_hat(s))/s = -tau expm1(-n log1p(x))/(n x), x = s tau/n [time].

        No cancellation for small |s| tau (expm1 and log1p); tau at s = 0.
        """
        s, real = as_s(s)
        x = s * self.tau / self.n
        safe = np.where(x == 0, 1.0, x)
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            if real:  # left of the branch point as laplace: integer n only
                lg = np.where(safe > -1, np.log1p(np.maximum(safe, -1.0)), np.log(np.abs(1 + safe)))
                out = -np.expm1(-self.n * lg) / (self.n * safe) * self.tau
                out = np.where(safe > -1, out, (1 - np.power(1 + safe, -self.n)) / (self.n * safe) * self.tau)
            else:
                out = -np.expm1(-self.n * clog1p(safe)) / (self.n * safe) * self.tau
        out = np.where(x == 0, self.tau, out)
        return (out.real if real else out)[()]

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


#: Above this n the gamma density and distribution of tanks in series are evaluated in
#: the form of their large-n asymptotics (:func:`_gamma_pdf_large`, :func:`_gamma_cdf_large`):
#: the plain log form loses |n log n| eps (0.4 % at n = 1e12) and scipy's gammainc drifts
#: (2e-7 at n = 1e20, 0.5 instead of 0.84 at 1e300).
LARGE_N = 1e4


def _log1pmx(d):
    """The difference d - log(1 + d) >= 0 for d > -1, without the cancellation of the plain difference.

    Series sum_(k>=2) (-1)^k d^k / k for |d| < 0.25 (30 terms: 0.25^30 / 30 < 1e-19),
    the plain expression elsewhere (no cancellation there).
    """
    d = np.asarray(d, dtype=float)
    small = np.abs(d) < 0.25
    ds = np.where(small, d, 0.0)
    acc = np.zeros_like(ds)
    for k in range(31, 1, -1):  # Horner: sum_(k=2)^31 (-1)^k d^(k-2) / k, times d^2
        acc = acc * ds + (1.0 if k % 2 == 0 else -1.0) / k
    with np.errstate(divide="ignore", invalid="ignore"):
        plain = d - np.log1p(d)
    return np.where(small, acc * ds * ds, plain)


def _stirling_tail(n: float) -> float:
    """Stirling's remainder ln Gamma(n) - [(n - 1/2) ln n - n + ln(2 pi)/2] for n >= 100.

    1/(12 n) - 1/(360 n^3) + 1/(1260 n^5), error < 1/(1680 n^7).
    """
    inv = 1.0 / n
    return inv / 12.0 - inv**3 / 360.0 + inv**5 / 1260.0


def _gamma_pdf_large(n: float, d) -> np.ndarray:
    """The density tau E(t) of tanks in series at d = t/tau - 1 for large n, in log form without cancellation.

    ln(tau E) = ln(n) + (n - 1) ln(n u) - n u - ln Gamma(n)
              = ln(n)/2 - ln(2 pi)/2 - n (d - ln(1 + d)) - ln(u) - stirling(n),  d = u - 1:
    every term is O(1) where E is not negligible, so the result keeps full relative accuracy
    at any n (the plain form subtracts terms of size n ln n).
    """
    d = np.asarray(d, dtype=float)
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
        logp = (0.5 * math.log(n) - 0.5 * math.log(2 * math.pi) - n * _log1pmx(d)
                - np.log1p(d) - _stirling_tail(n))
        out = np.exp(logp)
    return np.where(d > -1, out, 0.0)


def _gamma_cdf_large(n: float, d) -> np.ndarray:
    """P(n, n (1 + d)), the regularised lower incomplete gamma function, for large n (Temme).

    Temme's uniform expansion: P = erfc(-eta sqrt(n/2))/2 - R, eta = sign(u - 1)
    sqrt(2 (d - ln(1 + d))), d = u - 1, R = exp(-n eta^2/2)/sqrt(2 pi n) (c0(eta) +
    c1(eta)/n), c0 = 1/(u - 1) - 1/eta (series -1/3 + eta/12 - 2 eta^2/135 + eta^3/864 near
    eta = 0), c1(0) = -1/540; the omitted terms are O(n^-5/2): below 1e-12 for n >= 1e4.
    Temme, Special functions (1996), sec. 11.2.
    """
    from scipy import special  # here: scipy.special is a large share of start-up

    d = np.asarray(d, dtype=float)
    u = 1.0 + d
    eta = np.sign(d) * np.sqrt(2.0 * _log1pmx(d))
    near = np.abs(eta) < 1e-3
    # far tails: R's factor exp(-n eta^2/2) underflows, so c0, c1 (which overflow for huge d)
    # do not matter; clip d, eta there to keep the powers finite
    far = np.abs(eta) > 50.0
    d = np.where(far, 1.0, d)
    u = np.where(far, 2.0, u)
    eta_c = np.where(far, 1.0, eta)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore", under="ignore"):
        c0 = np.where(near, -1.0 / 3 + eta_c / 12 - 2 * eta_c**2 / 135 + eta_c**3 / 864,
                      1.0 / np.where(near, 1.0, d) - 1.0 / np.where(near, 1.0, eta_c))
        c1 = np.where(near, -1.0 / 540 - eta_c / 288,
                      _temme_c1(np.where(near, 1.0, eta_c), np.where(near, 2.0, u)))
        r = np.where(far, 0.0, np.exp(-0.5 * n * eta**2) / math.sqrt(2 * math.pi * n) * (c0 + c1 / n))
    out = 0.5 * special.erfc(-eta * math.sqrt(0.5 * n)) - r
    return np.where(u > 0, np.clip(out, 0.0, 1.0), 0.0)


def _temme_c1(eta, u):
    """c1(eta) of Temme's expansion: (1/eta^3 - 1/(u - 1)^3 - 1/(u - 1)^2 - 1/(12 (u - 1)))."""
    d = u - 1.0
    return 1.0 / eta**3 - 1.0 / d**3 - 1.0 / d**2 - 1.0 / (12.0 * d)


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
