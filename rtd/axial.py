"""Axial dispersion model (Wehner-Wilhelm), closed and open vessel, for Pe in [1e-2, 1e4].

The transform is closed-form everywhere; the density E(t) of the closed vessel is not,
and each regime gets the method that is accurate there (theta = t/tau, q = Pe/2):

- eigenfunction (residue) series E(theta) = sum_k c_k exp(q + p_k theta) over the poles
  p_k = -(q/2)(1 + beta_k^2) of E_hat, with 2 arctan(beta_k) + q beta_k = k pi and
  c_k = -2 Pe beta_k^2 / D'(i beta_k), D(a) = (1+a)^2 e^{aq} - (1-a)^2 e^{-aq}. The terms
  carry exp(q + p_k theta); when Pe > 16 and theta < 2 they are huge and cancel, so the
  series is used only for Pe <= 16 (any theta) or theta >= 2 (any Pe);
- Fourier inversion on Re s = 0 (trapezoid rule, which is the Fourier series of the
  periodised E): for Pe > 16 and theta < 2. There |E_hat(i w)| decays at least like
  exp(-sqrt(Pe w / 2)) (like a Gaussian for large Pe), so a few hundred nodes give
  ~1e-13 absolute accuracy; the period is chosen so that E(theta + T) < 1e-28.

For Pe < 1 the poles and residues are computed in the angle eps_k = q beta_k/2 - (k-1) pi/2
(:func:`_eigen_small`), which keeps full accuracy down to Pe = 1e-250; below that the
vessel is one perfect mixer to relative O(Pe) and E, F are exp(-theta), 1 - exp(-theta).

Where E is below ~e^-700 (very early times; late times for Pe > 1000) it is returned
as 0, which also keeps the number of series terms to a few hundred. For Pe -> 0 E
approaches exp(-theta)/tau (one perfect mixer), for
Pe -> inf a Gaussian of variance 2/Pe around theta = 1 (plug flow).
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from rtd.base import ParameterError, RTDModel, as_s, as_time, check_positive

#: Below this Peclet number the closed vessel is one perfect mixer to relative O(Pe), far
#: below rounding: its poles beyond the first are at p < -1e250.
PE_MIXED = 1e-250
SERIES_MAX_PE = 16.0   # below: series cancellation costs < exp(Pe/4) ~ 55 ulp
SERIES_MIN_THETA = 2.0  # above: every series term is <= O(1), no cancellation
_CHUNK = 1024
#: Most Fourier nodes of the closed density (~ sqrt(41 Pe) T / (2 pi)): a block of
#: _CHUNK times x nodes complex numbers is 1024 x 2e5 x 16 B = 3.3 GB at the limit; the
#: blocks are cut to :data:`_BLOCK_BYTES` below it.
MAX_FOURIER_NODES = 200_000
MAX_DENSITY_PE = 1e9
_BLOCK_BYTES = 2**26


# ----------------------------------------------------------------------------- closed
def closed_transform(p, pe: float):
    """E_hat(p) of the closed vessel, p = s tau (complex array), without overflow.

    E_hat = 4 a exp(q (1 - a)) / [(1 + a)^2 - (1 - a)^2 exp(-2 q a)], a = sqrt(1 + 4p/Pe),
    with q (1 - a) = -2p / (1 + a) (no cancellation when 4p/Pe is small at large Pe):
    Wehner-Wilhelm divided through by exp(a q); Re a >= 0 keeps every exponential <= e^q.
    """
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):  # 4p/Pe -> inf: _mixed_limit
        return _closed_transform(np.asarray(p), pe)


def _closed_transform(p, pe: float):
    q = 0.5 * pe
    if not np.iscomplexobj(p) and p.size and (1 + 4 * p.min() / pe) > 0:
        # real p > -Pe/4: a is real and positive, den > 0; the same formula in float64
        # (a third of the cost of the complex one, and what a segregated mill evaluates)
        a = np.sqrt(1 + 4 * p.astype(float) / pe)
        with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
            # the ratio directly (a few ulp; the logs of large a lose |log a| ulp), den/a
            # written (1 + a)(1 + 1/a)(-expm1(-2 q a)) + 4 exp(-2 q a) so a^2 never overflows
            e = np.exp(-2 * q * a)
            out = 4 * np.exp(-2 * p / (1 + a)) / ((1 + a) * (1 + 1 / a) * -np.expm1(-2 * q * a) + 4 * e)
            big = ~np.isfinite(out)  # exp(-2p/(1+a)) overflows near p = -Pe/4 at huge Pe
            if np.any(big):
                out = np.where(big, np.exp(np.log(4 * a) - 2 * p / (1 + a) - np.log(_closed_den(a, q))), out)
        return _mixed_limit(out, p, a)
    p = p.astype(complex)
    a = np.sqrt(1 + 4 * p / pe)
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        den = _closed_den(a, q)
        # one exponential of the summed logs: an overflowing factor exp(q (1 - a)) times
        # a finite one would give inf * 0j = nan in complex arithmetic
        out = np.exp(np.log(4 * a) - 2 * p / (1 + a) - np.log(den))
    # at a = 0 (p = -Pe/4) the expression is 0/0; the limit is 4 e^q/(4 + 2q)
    out = np.where(a == 0, 4 * math.exp(q) / (4 + 2 * q) if q < 700 else np.inf, out)
    return _mixed_limit(out, p, a)


def _closed_den(a, q):
    """(1 + a)^2 - (1 - a)^2 exp(-2 q a) without cancellation.

    Written as -(1 + a)^2 expm1(-2 q a) + 4 a exp(-2 q a): for real a > 0 both terms are
    positive. The plain difference cancels when Pe -> 0 (a ~ sqrt(4p/Pe) large, 2 q a
    small): its relative error grows like eps a, 1e-8 at Pe = 1e-16 and O(1) at 1e-32.
    """
    e = np.exp(-2 * q * a)
    return -(1 + a) ** 2 * np.expm1(-2 * q * a) + 4 * a * e


def _mixed_limit(out, p, a):
    """Use the perfect-mixing transform where 4p/Pe overflows.

    Where 4p/Pe overflows (Pe below ~1e-300 p) the vessel is one perfect mixer to
    relative O(Pe): E_hat = 1/(1 + p).
    """
    bad = ~np.isfinite(a)
    if np.any(bad):
        out = np.where(bad, 1.0 / (1.0 + p), out)
    return out


@functools.lru_cache(maxsize=128)
def _eigen(pe: float, k_max: int) -> tuple[np.ndarray, np.ndarray]:
    """Poles p_k (in p = s tau) and residue factors c_k, k = 1..k_max."""
    if pe < 1.0:
        return _eigen_small(pe, k_max)
    q = 0.5 * pe
    k = np.arange(1, k_max + 1, dtype=float)
    lo, hi = (k - 1) * np.pi / q, k * np.pi / q
    beta = hi.copy()
    # f = 2 atan(b) + q b - k pi is increasing and concave: Newton from the right
    # undershoots once, then climbs monotonically to the root
    done = 0
    for _ in range(100):
        f = 2 * np.arctan(beta) + q * beta - k * np.pi
        step = f / (2 / (1 + beta**2) + q)
        beta = np.clip(beta - step, lo, hi)
        # quadratic convergence: one more step after 1e-10 reaches round-off
        done = done + 1 if np.all(np.abs(step) <= 1e-10 * beta) else 0
        if done == 2:
            break
    z = (1 + 1j * beta) * (2 + q * (1 + 1j * beta)) * np.exp(1j * beta * q)
    dprime = 2 * z.real
    c = -2 * pe * beta**2 / dprime
    p = -0.5 * q * (1 + beta**2)
    return p, c


def _eigen_small(pe: float, k_max: int) -> tuple[np.ndarray, np.ndarray]:
    """Poles and residue factors for Pe < 1, written in eps_k = q beta_k / 2 - (k - 1) pi / 2.

    With phi = q beta / 2 the root condition 2 arctan(beta) + q beta = k pi reads
    eps = arctan(q / (2 phi)), phi = (k - 1) pi / 2 + eps, eps in (0, pi/2]; then
    p_k = -q/2 - 2 phi^2 / q and, since e^(2 i phi) and 1 + i beta reduce to rotations,
    D'(i beta_k) = -/+ (4 + 2 q / sin^2 eps) and c_k = (-1)^(k+1) Pe cos^2(eps) /
    (2 sin^2(eps) + q): no cancellation as q -> 0, where the beta form subtracts
    q beta^2 ~ 2 from 2 + q (its relative error grows like eps_mach / Pe: 3e-6 in F at
    Pe = 1e-20).
    """
    q = 0.5 * pe
    k = np.arange(1, k_max + 1, dtype=float)
    sign = np.where(k % 2 == 1, 1.0, -1.0)
    if pe < PE_MIXED:  # p_1 = -1 - Pe/6 + O(Pe^2), c_1 = 1 - Pe/6 ...; p_k -> -inf for k >= 2
        return np.r_[-1.0, np.full(k_max - 1, -np.inf)], np.r_[1.0, 2.0 * sign[1:]]
    lo = (k - 1) * (0.5 * np.pi)
    with np.errstate(divide="ignore"):
        eps = np.where(k == 1, min(math.sqrt(0.5 * q), 1.0), np.arctan(q / (2 * lo)))
    # h(eps) = eps - arctan(q / (2 (lo + eps))) is increasing and concave: Newton from the
    # left climbs monotonically to the root (after at most one step from the right)
    for _ in range(100):
        phi = lo + eps
        h = eps - np.arctan(q / (2 * phi))
        step = h / (1 + 2 * q / (4 * phi * phi + q * q))
        new = np.clip(eps - step, 0.0, 0.5 * np.pi)
        if np.all(np.abs(new - eps) <= 1e-15 * new):
            eps = new
            break
        eps = new
    phi = lo + eps
    with np.errstate(over="ignore"):
        p = -0.5 * q - 2 * phi * phi / q
    c = sign * pe * np.cos(eps) ** 2 / (2 * np.sin(eps) ** 2 + q)
    return p, c


def _n_terms(pe: float, theta_min: float) -> int:
    """Terms so that |c_k| exp(q + p_k theta_min) < e^-42 for the last one."""
    q = 0.5 * pe
    # beta q / pi with beta = sqrt(2 (q + 42) / (q theta_min)), written without dividing by q
    k = int(math.sqrt(2 * (q + 42) * q / theta_min) / math.pi) + 3
    return 1 << max(4, (k - 1).bit_length())  # power of 2: few distinct cache entries


def _negligible(theta: np.ndarray, pe: float) -> np.ndarray:
    """Where E < ~e^-700: early times, and for Pe > 1000 late times as well.

    Early: the open-vessel bound exp(-Pe (1-theta)^2/(4 theta) + Pe theta/4). Late: the
    reflections of the closed vessel carry exp(-m Pe), negligible for Pe > 1000, and the
    direct front is Gaussian-like, exp(-Pe (theta-1)^2/(4 theta)) times powers of Pe.
    """
    with np.errstate(divide="ignore"):
        spread = pe * (1 - theta)**2 / (4 * theta)
    early = (theta < 1) & (spread - pe * theta / 4 > 700)
    late = (theta > 1) & (pe > 1000) & (spread > 800)
    return early | late


def _closed_series(theta: np.ndarray, pe: float, integral: bool) -> np.ndarray:
    """E(theta) (or F(theta) when ``integral``) by the residue series, theta > 0."""
    out = np.empty_like(theta)
    if theta.size == 0:
        return out
    p, c = _eigen(pe, _n_terms(pe, float(theta.min())))
    q = 0.5 * pe
    w = c / p if integral else c
    for i in range(0, theta.size, _CHUNK):
        th = theta[i:i + _CHUNK, None]
        out[i:i + _CHUNK] = np.exp(q + p[None, :] * th) @ w
    return 1.0 + out if integral else out


@functools.lru_cache(maxsize=64)
def _fourier_nodes(pe: float) -> tuple[float, np.ndarray, np.ndarray]:
    """Period T (in theta), angular nodes w_k = 2 pi k / T, k >= 1, and E_hat(i w_k)."""
    period = SERIES_MIN_THETA + 2.0 + 200.0 / pe
    w_max = 1.0
    while abs(closed_transform(1j * w_max, pe)) > 1e-18 and w_max < 1e9:
        w_max *= 1.25
    n = int(math.ceil(w_max * period / (2 * math.pi)))
    # |E_hat(i w)| ~ exp(-w^2/Pe): the nodes grow like sqrt(Pe); each evaluation holds a
    # block of (times x nodes) complex numbers, so refuse before allocating
    if abs(closed_transform(1j * w_max, pe)) > 1e-18 or n > MAX_FOURIER_NODES:
        raise ParameterError(
            f"AxialDispersion: E(t) of the closed vessel at Pe = {pe:.3g} is a spike of relative width "
            f"sqrt(2/Pe) = {math.sqrt(2 / pe):.2g}; its density needs more than {MAX_FOURIER_NODES:,} Fourier "
            f"nodes (accurate for Pe <= {MAX_DENSITY_PE:.0e}); use rtd.PlugFlow, or the transform (laplace)")
    w = 2 * math.pi * np.arange(1, n + 1) / period
    return period, w, closed_transform(1j * w, pe)


def _closed_fourier(theta: np.ndarray, pe: float, integral: bool) -> np.ndarray:
    """E(theta) or F(theta) from the Fourier series of the periodised density.

    E = (1/T)[1 + 2 Re sum_k E_hat(i w_k) e^{i w_k theta}],
    F = theta/T + (2/T) Re sum_k E_hat(i w_k) (e^{i w_k theta} - 1)/(i w_k).
    """
    if theta.size == 0:
        return np.empty_like(theta)
    period, w, eh = _fourier_nodes(pe)
    coef = eh / (1j * w) if integral else eh
    out = np.empty_like(theta)
    rows = max(1, min(_CHUNK, _BLOCK_BYTES // (16 * w.size)))  # a block of ~64 MB at most
    for i in range(0, theta.size, rows):
        th = theta[i:i + rows, None]
        ph = np.exp(1j * w[None, :] * th)
        if integral:
            ph = ph - 1.0
        out[i:i + rows] = 2 * (ph @ coef).real
    return (theta + out) / period if integral else (1.0 + out) / period


def closed_density(theta, pe: float, integral: bool = False) -> np.ndarray:
    """E(theta) (dimensionless, = tau E(t)) or F(theta) of the closed vessel."""
    theta = np.asarray(theta, dtype=float)
    flat = theta.ravel()
    out = np.zeros_like(flat)
    pos = flat > 0
    zero = pos & _negligible(flat, pe)
    series = pos & ~zero & ((pe <= SERIES_MAX_PE) | (flat >= SERIES_MIN_THETA))
    fourier = pos & ~zero & ~series
    if integral:  # negligible density: F is 0 before the front and 1 after it
        out[zero & (flat > 1)] = 1.0
    out[series] = _closed_series(flat[series], pe, integral)
    out[fourier] = _closed_fourier(flat[fourier], pe, integral)
    # round-off of the Fourier sums (~1e-13) may dip below 0 or above 1
    out = np.clip(out, 0.0, 1.0) if integral else np.maximum(out, 0.0)
    return out.reshape(theta.shape)


def closed_variance(pe: float) -> float:
    """variance/tau^2 = 2/Pe - 2 (1 - exp(-Pe))/Pe^2 (series for small Pe)."""
    if pe < 1e-3:
        return 1 - pe / 3 + pe**2 / 12 - pe**3 / 60
    return 2 / pe + 2 * math.expm1(-pe) / pe / pe  # pe**2 would overflow for pe > 1e154


# ------------------------------------------------------------------------------- open
def open_density(theta, pe: float) -> np.ndarray:
    """E(theta) = sqrt(Pe/(4 pi theta)) exp(-Pe (1 - theta)^2/(4 theta))."""
    th = np.maximum(np.asarray(theta, dtype=float), 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        e = np.sqrt(pe / (4 * np.pi * th)) * np.exp(-pe * (1 - th)**2 / (4 * th))
    return np.where(th > 0, e, 0.0)


def open_cdf(theta, pe: float) -> np.ndarray:
    """F = Phi(z (theta - 1)) - exp(Pe) Phi(-z (theta + 1)), z = sqrt(Pe/(2 theta))."""
    from scipy import special  # here: scipy.special is a large share of start-up

    th = np.maximum(np.asarray(theta, dtype=float), 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.sqrt(pe / (2 * th))
        # exp(Pe) Phi(.) combined in logs: exp(Pe) alone overflows for Pe > 709
        f = special.ndtr(z * (th - 1)) - np.exp(pe + special.log_ndtr(-z * (th + 1)))
    return np.where(th > 0, np.clip(f, 0.0, 1.0), 0.0)


# ------------------------------------------------------------------------------ model
@dataclass(frozen=True)
class AxialDispersion(RTDModel):
    """Axial dispersion with space time ``tau`` = L/u [time] and Peclet ``pe`` = u L/D.

    ``bc="closed"`` (Danckwerts boundaries, Wehner-Wilhelm):
    E_hat(s) = 4 a e^{Pe/2} / [(1+a)^2 e^{a Pe/2} - (1-a)^2 e^{-a Pe/2}],
    a = sqrt(1 + 4 s tau/Pe); mean tau, variance tau^2 [2/Pe - 2(1 - e^{-Pe})/Pe^2].
    E_hat is meromorphic with poles on the negative real axis, the first at
    s = -(Pe/4)(1 + beta_1^2)/tau. E(t) by eigen-series or Fourier inversion (module doc).

    ``bc="open"``: E(theta) = sqrt(Pe/(4 pi theta)) exp(-Pe (1-theta)^2/(4 theta))/tau,
    E_hat = exp[(Pe/2)(1 - a)]/a, mean tau (1 + 2/Pe), variance tau^2 (2/Pe + 8/Pe^2),
    branch point at s = -Pe/(4 tau).

    Parameters
    ----------
    tau : float
        L/u [time], > 0 (the mean residence time of the closed vessel).
    pe : float
        Peclet number u L / D [-], > 0; accurate for 1e-2 <= pe <= 1e4 (tested).
    bc : {"closed", "open"}
        Boundary conditions: closed (Danckwerts: no dispersion across the inlet and outlet)
        or open (the line extends both ways; the flux measured at z = 1).

    References
    ----------
    P. V. Danckwerts, Continuous flow systems: distribution of residence times,
    Chem. Eng. Sci. 2 (1953) 1-13; J. F. Wehner and R. H. Wilhelm, Boundary conditions of
    flow reactor, Chem. Eng. Sci. 6 (1956) 89-93; O. Levenspiel, Chemical Reaction
    Engineering, 3rd ed. (Wiley, 1999), ch. 13.

    Examples
    --------
    >>> m = AxialDispersion(tau=10.0, pe=8.0)
    >>> round(float(m.laplace(0.0)), 12), round(m.mean, 9)  # E integrates to 1; the closed vessel's mean is tau
    (1.0, 10.0)
    """

    tau: float
    pe: float
    bc: str = "closed"
    param_names: ClassVar[tuple[str, ...]] = ("tau", "pe")

    def __post_init__(self):
        object.__setattr__(self, "tau", check_positive("AxialDispersion", "tau", self.tau))
        object.__setattr__(self, "pe", check_positive("AxialDispersion", "pe", self.pe))
        if self.bc not in ("closed", "open"):
            raise ParameterError(f"AxialDispersion: bc = {self.bc!r}; expected 'closed' or 'open'")

    def pdf(self, t):
        """E(t) [1/time]."""
        theta = as_time(t) / self.tau
        if self.bc == "open":
            return open_density(theta, self.pe) / self.tau
        return closed_density(theta, self.pe) / self.tau

    def cdf(self, t):
        """F(t) [-]."""
        theta = as_time(t) / self.tau
        if self.bc == "open":
            return open_cdf(theta, self.pe)
        return closed_density(theta, self.pe, integral=True)

    def laplace(self, s):
        """E_hat(s), real or complex s [1/time]; no overflow for large |s| with Re s >= 0."""
        s, real = as_s(s)
        p = s * self.tau
        if self.bc == "open":
            a = np.sqrt(1 + 4 * p / self.pe + 0j)
            # left of Re s = 0 at huge Pe the value exceeds 1e308: inf, whose complex
            # division by a sets a NaN imaginary part that is discarded for real s
            with np.errstate(over="ignore", invalid="ignore"):
                # Pe (1 - a) / 2 = -2p / (1 + a): no cancellation for small 4p/Pe
                out = np.exp(-2 * p / (1 + a)) / a
        else:
            out = closed_transform(p, self.pe)
        return (out.real if real else out)[()]  # 0-d array -> numpy scalar

    exact_survival: ClassVar[bool] = True

    def survival_laplace(self, s):
        """G(s) = (1 - E_hat(s))/s [time], the transform of 1 - F(t), without cancellation.

        With p = s tau, a = sqrt(1 + 4p/Pe), a - 1 = (4p/Pe)/(1 + a), y = 2p/(1 + a):
        open, 1 - E_hat = [(a - 1) - expm1(-y)]/a; closed, E_hat = 4 e^-y / D with
        D = 4 - ((a - 1)^2/a) expm1(-Pe a), so 1 - E_hat = [-4 expm1(-y) - ((a - 1)^2/a)
        expm1(-Pe a)]/D. Every term is >= 0 for real p >= 0 (the plain 1 - E_hat loses
        eps/(s tau)); where 4p/Pe overflows, the perfect mixer tau/(1 + p).
        """
        s, real = as_s(s)
        p = np.asarray(s * self.tau, dtype=complex)
        zero = p == 0
        ps = np.where(zero, 1.0, p)
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            a = np.sqrt(1 + 4 * ps / self.pe)
            am1 = (4 * ps / self.pe) / (1 + a)
            y = 2 * ps / (1 + a)
            if self.bc == "open":
                out = self.tau * (am1 - np.expm1(-y)) / (a * ps)
            else:
                r = am1 * am1 / a
                e = np.expm1(-self.pe * a)
                out = self.tau * (-4 * np.expm1(-y) - r * e) / (ps * (4 - r * e))
            out = np.where(np.isfinite(a), out, self.tau / (1 + ps))
        out = np.where(zero, self.mean, out)
        return (out.real if real else out)[()]

    @property
    def mean(self) -> float:
        """Mean residence time [time]."""
        return self.tau if self.bc == "closed" else self.tau * (1 + 2 / self.pe)

    @property
    def variance(self) -> float:
        """Variance of the residence time [time^2]."""
        if self.bc == "closed":
            return self.tau**2 * closed_variance(self.pe)
        return self.tau**2 * (2 / self.pe + 8 / self.pe / self.pe)

    @property
    def analytic_for_re_s_greater_than(self) -> float:
        """Abscissa [1/time]: ``laplace`` is analytic for Re s above it."""
        if self.bc == "open":
            return -self.pe / (4 * self.tau)
        p, _ = _eigen(self.pe, 16)
        return float(p[0]) / self.tau

    @classmethod
    def from_moments(cls, mean: float, variance: float, bc: str = "closed") -> "AxialDispersion":
        """Initial guess matching mean and variance (Pe clipped to [1e-3, 1e6])."""
        r = variance / mean**2
        if bc == "open":
            # x = 1/Pe: r (1 + 2x)^2 = 2x + 8x^2, a quadratic with one positive root
            a, b, c = 4 * r - 8, 4 * r - 2, r
            disc = b * b - 4 * a * c
            x = (-b - math.sqrt(disc)) / (2 * a) if (a < 0 and disc >= 0) else 1e3
            pe = min(max(1.0 / x, 1e-3), 1e6)
            return cls(mean / (1 + 2 / pe), pe, bc)
        if r >= 1.0:
            return cls(mean, 1e-3, bc)
        if r <= closed_variance(1e6):
            return cls(mean, 1e6, bc)
        from scipy import optimize  # here: scipy.optimize is a large share of start-up

        lpe = optimize.brentq(lambda x: closed_variance(math.exp(x)) - r,
                              math.log(1e-3), math.log(1e6), xtol=1e-12)
        return cls(mean, math.exp(lpe), bc)
