"""Shared helpers for the rtd tests: quadrature of a density times a weight.

Composite Gauss-Legendre (20 nodes per panel) on panels that are uniform over the body
of the distribution (0 to mean + 12 sd, 250 panels: >= 3 per standard deviation even for
Pe = 1e4), geometric towards t = 0 (boundary layers of small Pe) and geometric beyond
the body out to mean + 80 sd + 50 mean (tails of heavy-tailed models). All nodes go to
the model in one vectorised call. Checked against scipy's adaptive quad to ~1e-14.
"""
import math

import numpy as np
import pytest

_X, _W = np.polynomial.legendre.leggauss(20)


def _nodes(model, breaks=()):
    mean, sd = model.mean, math.sqrt(model.variance)
    body = mean + 12 * sd
    far = mean + 80 * sd + 50 * mean
    edges = np.unique(np.concatenate([
        [0.0], np.geomspace(body * 1e-8, body, 60), np.linspace(0, body, 251),
        np.geomspace(body, far, 120), np.asarray(breaks, float)]))
    a, b = edges[:-1, None], edges[1:, None]
    t = 0.5 * (a + b) + 0.5 * (b - a) * _X[None, :]
    w = 0.5 * (b - a) * _W[None, :]
    return t.ravel(), w.ravel()


def _integrate_density(model, weight=lambda t: np.ones_like(t), complex_weight=False, breaks=()):
    """int_0^inf E(t) weight(t) dt plus the atom at t = 0 times weight(0)."""
    if hasattr(model, "parts"):  # plug-flow delays in compositions are kinks of E
        breaks = tuple(breaks) + (sum(getattr(p, "tau", 0.0) for p in model.parts
                                      if type(p).__name__ == "PlugFlow"),)
    t, w = _nodes(model, breaks)
    total = np.sum(w * model.pdf(t) * weight(t)) + model.atom_at_zero * weight(np.zeros(1))[0]
    return complex(total) if complex_weight else float(np.real(total))


@pytest.fixture(name="integrate_density")
def integrate_density_fixture():
    """The quadrature function (a fixture, so tests need no import of conftest)."""
    return _integrate_density
