"""A mill with non-linear kinetics in the same circuit as units torn on their throughput
(a predicted hydrocyclone, a slurry-volume mill): one tear over the inlet flow vectors and
the throughputs, water and recoveries (it used to be refused as "not supported"); Wegstein
falls back to Newton where it stalls, and says so."""
import re
import sys

import numpy as np
import pytest

from millflow.errors import SolverError
from millflow.flowsheet import loads, solve
from millflow.flowsheet.results import mass_balance
from tests import paths

solve_mod = sys.modules["millflow.flowsheet.solve"]

WET = (paths.FLOWSHEETS / "closed_circuit_wet_cyclones.toml").read_text()
KINETICS = """
[units.ball_mill.kinetics]
aggregation = "constant"
aggregation_beta0_per_s = BETA
x_ref_um = 10
cushion_lambda = LAMBDA
fines_um = 75

"""


def _wet(beta="1e-4", lam="-1.0", coarse=True):
    text = WET
    if coarse:  # 2^(1/8) instead of 2^(1/20): the same circuit, a quarter of the classes
        text = re.sub(r"^ratio = .*$", "ratio = 1.0905077326652577", text, count=1, flags=re.M)
    i = text.index("[units.sump]")
    return text[:i] + KINETICS.replace("BETA", beta).replace("LAMBDA", lam) + text[i:]


def test_shipped_wet_circuit_with_non_linear_kinetics_runs():
    sol = solve(loads(_wet()))
    tear = sol.solver["tear"]
    assert tear["converged"] and tear["torn_units"] == ["ball_mill", "cyclones"]
    assert "corrected recovery C of cyclones" in tear["torn"] and "water of ball_mill, cyclones" in tear["torn"]
    mb = mass_balance(sol)
    assert mb["overall"] < 1e-9 and mb["water"] < 1e-9
    # the predicted cyclone's reported operation is the one at the converged flows
    assert 0 < sol.units["cyclones"]["d50c_m"] < 1e-3


def test_null_kinetics_reproduce_the_linear_circuit():
    # aggregation with beta0 = 0 and no cushioning: the non-linear path must give the linear
    # flowsheet's answer (solved without any tear of the inlet vectors) to the tear's tolerance
    lin = solve(loads(_wet().split("[units.ball_mill.kinetics]")[0] + "[units.sump]"
                      + _wet().split("[units.sump]")[1]))
    text = _wet(beta="0", lam="0.0")
    nl = solve(loads(text))
    assert "non-linear kinetics" in nl.units["ball_mill"]["method"]
    scale = lin.flows.sum(axis=1, keepdims=True)
    np.testing.assert_allclose(nl.flows / scale, lin.flows / scale, rtol=0, atol=1e-8)


def test_wegstein_stall_falls_back_to_newton_and_says_so(monkeypatch):
    monkeypatch.setattr(solve_mod, "_NOTED", set())
    with pytest.warns(UserWarning, match="Wegstein tear on the inlet flows stalled; Newton"):
        sol = solve(loads(_wet()))
    assert "newton on the tear from there converged" in sol.solver["tear"]["fallback"]


def test_both_failing_names_the_tear_method_option(monkeypatch):
    with pytest.raises(SolverError, match=r"did not converge \(substitution, 3 iterations.*--tear-method newton"):
        solve(loads(_wet()), method="substitution", maxiter=3)

    def stuck(g, x0, tol, maxiter, **kw):
        return x0, 1, [1.0], False

    monkeypatch.setattr(solve_mod, "_vector_newton", stuck)
    with pytest.raises(SolverError, match=r"wegstein, then newton from where it stalled.*--tear-method newton"):
        solve(loads(_wet()))


def test_vector_newton_accepts_only_what_tol_asks():
    # a fixed point reached to 1e-10 only (g carries 1e-10 of noise): accepted at tol 1e-9, not
    # at 1e-13 (it used to accept 100 x max(tol, 1e-12))
    rng = np.random.default_rng(1)

    def g(x):
        return 0.5 * x + np.array([1.0, 2.0]) + 1e-10 * rng.standard_normal(2)

    x, its, hist, ok = solve_mod._vector_newton(g, np.array([1.0, 1.0]), 1e-13, 50)
    assert not ok and min(hist) > 1e-13
    x, its, hist, ok = solve_mod._vector_newton(g, np.array([1.0, 1.0]), 1e-9, 50)
    assert ok and np.allclose(x, [2.0, 4.0], atol=1e-8)
