"""Compositions of RTD models: vessels in series and flow split in parallel.

Series: E_hat = prod_k E_hat_k (the exit age is the sum of independent ages), mean and
variance add. Its density is computed exactly where the structure allows: plug-flow
parts are a pure delay; parts that are compartment networks (perfect mixers, integer
tanks in series, cells) are chained into one network (matrix exponential). Any other
remainder is inverted numerically from the product transform: by the fixed Talbot
contour (Abate and Valko 2004; ~1e-13 absolute on tested cases) for smooth densities
without a delay-like front, and, when an axial dispersion part has Pe > 30 (a sharp,
delayed front that defeats Talbot), by Fourier inversion on Re s = 0, where that part
makes the product decay fast.
Parallel: E = sum_k w_k E_k with weights summing to 1.
Austin's mill model (plug flow + one large + two small mixers) is
``Series(PlugFlow(tp), PerfectMixing(t1), PerfectMixing(t2), PerfectMixing(t2))``.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from rtd.compartments import CompartmentNetwork
from rtd.inversion import fourier_inverse  # noqa: F401  (re-exported: rtd.compose is where it was)
from rtd.base import survival_of
from rtd.models import ParameterError, PlugFlow, RTDModel, as_s, as_time

TALBOT_M = 24  # nodes; in double precision more nodes lose accuracy to round-off
FOURIER_MIN_PE = 30.0  # axial dispersion parts above this Pe: Fourier route, not Talbot


def talbot_inverse(transform, t, m: int = TALBOT_M) -> np.ndarray:
    """f(t) from its Laplace transform by the fixed Talbot contour, t > 0.

    s_k = r theta_k (cot theta_k + i), r = 2 m / (5 t), theta_k = k pi / m;
    f(t) ~ (r/m) [f_hat(r) e^{r t}/2 + sum_{k=1}^{m-1} Re(e^{t s_k} f_hat(s_k)(1 + i sigma_k))],
    sigma_k = theta_k + (theta_k cot theta_k - 1) cot theta_k.
    """
    t = np.asarray(t, dtype=float)
    flat = t.ravel()
    out = np.zeros_like(flat)
    pos = flat > 0
    tp = flat[pos][:, None]
    theta = (np.arange(1, m) * math.pi / m)[None, :]
    cot = 1.0 / np.tan(theta)
    r = 2.0 * m / (5.0 * tp)
    s = r * theta * (cot + 1j)
    sigma = theta + (theta * cot - 1.0) * cot
    with np.errstate(over="ignore", invalid="ignore"):
        terms = (np.exp(tp * s) * transform(s) * (1 + 1j * sigma)).real
        first = 0.5 * np.exp(r[:, 0] * tp[:, 0]) * np.real(transform(r[:, 0]))
    value = (r[:, 0] / m) * (first + terms.sum(axis=1))
    # the sum cancels from terms ~e^{0.4 m} larger than the result: values below their
    # own round-off (far tails) are noise of either sign and are returned as 0
    noise = 10 * np.finfo(float).eps * (r[:, 0] / m) * (np.abs(first) + np.abs(terms).sum(axis=1))
    out[pos] = np.where(np.abs(value) > noise, value, 0.0)
    return out.reshape(t.shape)


def chain_networks(parts) -> CompartmentNetwork:
    """One network for networks in series (each rescaled to feed flow 1), no bypass."""
    nets = [p if isinstance(p, CompartmentNetwork) else p.network() for p in parts]
    if any(n.bypass for n in nets):
        raise ParameterError("Series: a part with bypass cannot be chained into one network")
    sizes = [n.n for n in nets]
    total = sum(sizes)
    vol, flows = np.zeros(total), np.zeros((total, total))
    start = np.cumsum([0] + sizes)
    for k, net in enumerate(nets):
        q = net.feed_flow
        sl = slice(start[k], start[k + 1])
        vol[sl] = net.volumes / q
        flows[sl, sl] = net.flows / q
        if k + 1 < len(nets):
            nxt = slice(start[k + 1], start[k + 2])
            flows[nxt, sl] += np.outer(nets[k + 1].inlet, net.outlet / q)
    inlet = np.zeros(total)
    inlet[: sizes[0]] = nets[0].inlet
    outlet = np.zeros(total)
    outlet[start[-2]:] = nets[-1].outlet / nets[-1].feed_flow
    return CompartmentNetwork(vol, flows, inlet, outlet)


def _networkable(part) -> bool:
    if part.atom_at_zero:
        return False
    if isinstance(part, CompartmentNetwork):
        return True
    try:
        part.network()
    except (AttributeError, ParameterError):
        return False
    return True


@dataclass(frozen=True, init=False)
class Series(RTDModel):
    """Vessels in series: ``Series(a, b, ...)``; E_hat = product of the parts' transforms."""

    parts: tuple

    def __init__(self, *parts):
        if not parts:
            raise ParameterError("Series: expected at least one part")
        for p in parts:
            if not hasattr(p, "laplace"):
                raise ParameterError(f"Series: part {p!r} is not an RTD model")
        object.__setattr__(self, "parts", tuple(parts))

    def __repr__(self):
        return f"Series({', '.join(map(repr, self.parts))})"

    def _split(self):
        delay = sum(p.tau for p in self.parts if isinstance(p, PlugFlow))
        rest = [p for p in self.parts if not isinstance(p, PlugFlow)]
        return delay, rest

    def _rest_model(self, rest):
        if len(rest) == 1:
            return rest[0]
        if all(_networkable(p) for p in rest):
            return chain_networks(rest)
        return None

    @functools.cached_property
    def _plan(self):
        """(delay, rest, exact model of the rest or None); built once per instance."""
        delay, rest = self._split()
        return delay, rest, (self._rest_model(rest) if rest else None)

    def _evaluate(self, t, which: str):
        t = as_time(t)
        delay, rest, model = self._plan
        if not rest:
            return getattr(PlugFlow(delay), which)(t) if delay > 0 else np.zeros_like(t)
        shifted = t - delay
        if model is not None:
            return getattr(model, which)(shifted)

        def product(s):
            out = np.ones_like(s, dtype=complex)
            for p in rest:
                out = out * p.laplace(s)
            return out

        if any(getattr(p, "pe", 0.0) > FOURIER_MIN_PE for p in rest):
            edge = max(p.analytic_for_re_s_greater_than for p in rest)
            return fourier_inverse(product, shifted, edge, integral=(which == "cdf"))
        if which == "cdf":
            return np.clip(talbot_inverse(lambda s: product(s) / s, shifted), 0.0, 1.0)
        return np.maximum(talbot_inverse(product, shifted), 0.0)

    def pdf(self, t):
        """E(t) [1/time] (plug flow parts shift it; bypass atoms are not in it)."""
        return self._evaluate(t, "pdf")

    def cdf(self, t):
        """F(t), the fraction [-] of the tracer that has left by times ``t``."""
        return self._evaluate(t, "cdf")

    def laplace(self, s):
        """E_hat(s), the Laplace transform of E, at real or complex ``s`` [1/time]."""
        s, real = as_s(s)
        out = np.ones_like(s, dtype=complex)
        for p in self.parts:
            out = out * p.laplace(s)
        return (out.real if real else out)[()]  # 0-d array -> numpy scalar

    @property
    def exact_survival(self) -> bool:
        """Every part's survival transform is a closed form."""
        return all(getattr(p, "exact_survival", False) for p in self.parts)

    def survival_laplace(self, s):
        """G(s) = sum_i G_i(s) prod_(j<i) E_hat_j(s) [time] (telescoping 1 - prod E_hat_j).

        Every term >= 0 for real s >= 0: no cancellation where the parts' G_i have none.
        """
        s, real = as_s(s)
        out = np.zeros_like(s, dtype=complex)
        before = np.ones_like(s, dtype=complex)
        for p in self.parts:
            out = out + survival_of(p, s) * before
            before = before * p.laplace(s)
        return (out.real if real else out)[()]

    @property
    def mean(self) -> float:
        """Mean residence time [time]."""
        return float(sum(p.mean for p in self.parts))

    @property
    def variance(self) -> float:
        """Variance of the residence time [time^2]."""
        return float(sum(p.variance for p in self.parts))

    @property
    def atom_at_zero(self) -> float:
        """Probability mass leaving at t = 0 (bypass); not part of ``pdf``."""
        return float(np.prod([p.atom_at_zero for p in self.parts]))

    @property
    def analytic_for_re_s_greater_than(self) -> float:
        """Abscissa [1/time]: ``laplace`` is analytic for Re s above it."""
        return max(p.analytic_for_re_s_greater_than for p in self.parts)


@dataclass(frozen=True, init=False)
class Parallel(RTDModel):
    """Flow split over parallel vessels: ``Parallel(a, b, weights=(w_a, w_b))``.

    E = sum_k w_k E_k, E_hat = sum_k w_k E_hat_k, weights >= 0 summing to 1.
    """

    parts: tuple
    weights: tuple

    def __init__(self, *parts, weights):
        w = np.asarray(weights, dtype=float)
        if w.shape != (len(parts),) or not parts:
            raise ParameterError(f"Parallel: {len(parts)} parts but weights {weights!r}; "
                                 "expected one weight per part")
        if np.any(~np.isfinite(w)) or np.any(w < 0) or abs(w.sum() - 1) > 1e-9:
            raise ParameterError(f"Parallel: weights = {weights!r}; expected >= 0 summing to 1")
        object.__setattr__(self, "parts", tuple(parts))
        object.__setattr__(self, "weights", tuple(float(x) for x in w))

    def __repr__(self):
        return f"Parallel({', '.join(map(repr, self.parts))}, weights={self.weights})"

    def _mix(self, which, x):
        return sum(w * getattr(p, which)(x) for w, p in zip(self.weights, self.parts))

    def pdf(self, t):
        """E(t), the exit-age density [1/time], at times ``t`` (0 before t = 0)."""
        return self._mix("pdf", as_time(t))

    def cdf(self, t):
        """F(t), the fraction [-] of the tracer that has left by times ``t``."""
        return self._mix("cdf", as_time(t))

    def laplace(self, s):
        """E_hat(s), the Laplace transform of E, at real or complex ``s`` [1/time]."""
        return self._mix("laplace", s)

    @property
    def exact_survival(self) -> bool:
        """Every part's survival transform is a closed form."""
        return all(getattr(p, "exact_survival", False) for p in self.parts)

    def survival_laplace(self, s):
        """G(s) = sum_k w_k G_k(s) [time]."""
        return sum(w * survival_of(p, s) for w, p in zip(self.weights, self.parts))

    @property
    def mean(self) -> float:
        """Mean residence time [time]."""
        return float(sum(w * p.mean for w, p in zip(self.weights, self.parts)))

    @property
    def variance(self) -> float:
        """Variance of the residence time [time^2]."""
        second = sum(w * (p.variance + p.mean**2) for w, p in zip(self.weights, self.parts))
        return float(second - self.mean**2)

    @property
    def atom_at_zero(self) -> float:
        """Probability mass leaving at t = 0 (bypass); not part of ``pdf``."""
        return float(sum(w * p.atom_at_zero for w, p in zip(self.weights, self.parts)))

    @property
    def analytic_for_re_s_greater_than(self) -> float:
        """Abscissa [1/time]: ``laplace`` is analytic for Re s above it."""
        return max(p.analytic_for_re_s_greater_than for p in self.parts)
