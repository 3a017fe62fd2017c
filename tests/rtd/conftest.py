"""Shared helpers for the rtd tests: adaptive quadrature of a density times a weight."""
import math

import numpy as np
import pytest
from scipy import integrate


def integrate_density(model, weight=lambda t: 1.0, complex_weight=False):
    """int_0^inf E(t) weight(t) dt plus the atom at t = 0, split around the peak.

    quad on [0, inf) misses narrow peaks (Pe = 1e4: width 1.4 % of tau), so the range is
    cut at mean -/+ 12 sd and at a far point where the tail is resolved separately.
    """
    mean, sd = model.mean, math.sqrt(model.variance)
    edges = sorted({0.0, max(mean - 12 * sd, 0.0), mean - 3 * sd if mean > 3 * sd else 0.0,
                    mean, mean + 3 * sd, mean + 12 * sd})
    edges = [e for e in edges if e >= 0]

    def part(fun):
        total = 0.0
        for a, b in zip(edges[:-1], edges[1:]):
            total += integrate.quad(fun, a, b, epsabs=1e-14, epsrel=1e-13, limit=400)[0]
        total += integrate.quad(fun, edges[-1], np.inf, epsabs=1e-15, epsrel=1e-13, limit=400)[0]
        return total

    atom = model.atom_at_zero * weight(0.0)
    if complex_weight:
        re = part(lambda t: float(model.pdf(t)) * np.real(weight(t)))
        im = part(lambda t: float(model.pdf(t)) * np.imag(weight(t)))
        return re + 1j * im + atom
    return part(lambda t: float(model.pdf(t)) * weight(t)) + atom


@pytest.fixture
def quad_density():
    return integrate_density
