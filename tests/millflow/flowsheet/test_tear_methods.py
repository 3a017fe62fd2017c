"""Tear methods: Newton finds what Wegstein finds, a stalled Wegstein falls back to Newton
and says so, and a tear at the rounding floor of its units counts as converged."""
import importlib

import numpy as np
import pytest

from millflow.flowsheet import load, solve
from tests import paths

solve_module = importlib.import_module("millflow.flowsheet.solve")  # the package exports solve() by that name

STIRRED = paths.FLOWSHEETS / "stirred_mill_recirculation.toml"


def test_newton_converges_on_the_stirred_mill_circuit():
    # the tear map does not depend on the torn throughput here: hybr found the root at its
    # fifth evaluation, wandered off and was reported as not converged
    fs = load(STIRRED)
    a, b = solve(fs, method="newton"), solve(fs, method="wegstein")
    assert a.solver["tear"]["converged"]
    np.testing.assert_allclose(a.flows, b.flows, rtol=1e-12, atol=1e-15 * np.abs(b.flows).max())


def test_newton_returns_the_best_point_it_evaluated():
    # g(x) = 5 for every x: the fixed point is 5 whatever the solver's own last iterate
    x, its, hist, ok = solve_module._newton(lambda x: np.full_like(x, 5.0), np.array([1.0]), 1e-13, 50)
    assert ok and x[0] == pytest.approx(5.0, rel=1e-15)


def test_wegstein_at_the_rounding_floor_is_converged():
    # a map whose fixed point is only reached to 1.6e-13 relative (rounding noise):
    # three successive changes below the floor are convergence, not a failure
    rng = np.random.default_rng(1)

    def g(x):
        return np.array([2.0 * (1 + 1.6e-13 * rng.standard_normal())]) + 0 * x

    x, its, hist, ok = solve_module._wegstein(g, np.array([1.0]), 1e-16, 50)
    assert ok and abs(x[0] - 2.0) < 1e-12


def test_stalled_wegstein_falls_back_to_newton_and_says_so(monkeypatch):
    # a Wegstein that cannot converge (one iteration allowed) hands over to Newton
    real = solve_module._wegstein

    def stalled(g, x0, tol, maxiter, **kw):
        return real(g, x0, tol, 1, **kw)

    monkeypatch.setitem(solve_module.TEAR_METHODS, "wegstein", stalled)
    monkeypatch.setattr(solve_module, "_wegstein", stalled)
    sol = solve(load(STIRRED), method="wegstein")
    assert sol.solver["tear"]["converged"]
    assert "newton on the tear from there converged" in sol.solver["tear"]["fallback"]
