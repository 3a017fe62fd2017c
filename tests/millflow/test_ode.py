"""The one ODE home (millflow.ode): linear systems with exact solutions to their tolerance,
a stiff system at a cost the stiffness does not set, failures as one SolverError line
naming what was solved, tolerances refused before any solve, and no second home: no module
of millflow outside millflow/ode.py and millflow/bench/ (whose plain solve_ivp is the
baseline the benchmarks time) calls scipy's solve_ivp."""
import ast
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.linalg import expm

from millflow.errors import InputError, SolverError
from millflow.ode import METHODS, integrate, integrate_linear

ROOT = Path(__file__).resolve().parents[2]
RTOL, ATOL = 1e-10, 1e-14
# The tolerances bound each step's local error (rtol |y| + atol); the global error is the
# sum of those carried forward, damped by the decay of these systems. Measured: at most
# ~6 rtol on these problems and methods; the bound leaves a factor ~15 for other BLAS/scipy
# builds, and is still 1e-5 of the answers' scale (an off-by-a-step or a wrong Jacobian
# misses it by orders).
TOL = 100 * RTOL


@pytest.mark.parametrize("method", METHODS)
def test_decay_matches_the_exponential(method):
    k, t = 2.0, np.linspace(0.1, 5.0, 12)
    sol = integrate(lambda _t, y: -k * y, (0.0, 5.0), [1.0], jac=lambda _t, y: np.array([[-k]]), method=method,
                    rtol=RTOL, atol=ATOL, t_eval=t, what="decay")
    assert sol.success and np.allclose(sol.t, t)
    assert np.abs(sol.y[0] - np.exp(-k * t)).max() < TOL


@pytest.mark.parametrize("method", METHODS)
def test_stiff_pair_matches_its_closed_form_at_a_cost_the_stiffness_does_not_set(method):
    # y1' = -y1, y2' = y1 - 1e4 y2: rates 1 and 1e4 apart; y2 = (e^-t - e^-1e4t) / (1e4 - 1)
    lam = 1e4
    J = np.array([[-1.0, 0.0], [1.0, -lam]])
    t = np.array([1e-4, 1e-3, 0.1, 1.0, 5.0, 10.0])
    sol = integrate(lambda _t, y: J @ y, (0.0, 10.0), [1.0, 0.0], jac=J, method=method, rtol=RTOL, atol=ATOL,
                    t_eval=t, what="stiff pair")
    exact = np.vstack([np.exp(-t), (np.exp(-t) - np.exp(-lam * t)) / (lam - 1.0)])
    assert np.abs(sol.y - exact).max() < TOL
    # an explicit method's stable step is ~3/1e4 here: ~3e4 steps, ~2e5 right-hand sides
    # (RK45) to t = 10; the implicit ones take the steps the accuracy asks (measured 1,100
    # (LSODA) to 8,800 (Radau: three stages per Newton iteration))
    assert sol.nfev < 20_000


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("sparse", [False, True])
def test_linear_system_with_a_source_matches_the_matrix_exponential(method, sparse):
    # dy/dt = J y + c: y(t) = y* + exp(J t) (y0 - y*), y* = -J^-1 c; a breakage-like
    # lower-triangular J with rates 1e-2 to 1e2, sparse or dense (LSODA gets it dense)
    S = np.logspace(2, -2, 5)
    J = np.diag(-S) + np.diag(0.6 * S[:-1], -1) + np.diag(0.3 * S[:-2], -2)
    c, y0 = np.array([1.0, 0.5, 0.0, 0.0, 0.0]), np.array([0.0, 1.0, 2.0, 0.0, 0.0])
    t = np.array([0.01, 0.5, 3.0, 20.0])
    sol = integrate_linear(sp.csr_matrix(J) if sparse else J, (0.0, 20.0), y0, c=c, method=method, rtol=RTOL,
                           atol=ATOL, t_eval=t, what="linear")
    ystar = -np.linalg.solve(J, c)
    exact = np.stack([ystar + expm(J * ti) @ (y0 - ystar) for ti in t], axis=1)
    assert np.abs(sol.y - exact).max() < TOL * np.abs(exact).max()


def test_terminal_event_and_dense_output_pass_through():
    def below(_t, y):
        return y[0] - 0.5
    below.terminal, below.direction = True, -1
    sol = integrate(lambda _t, y: -y, (0.0, 10.0), [1.0], jac=lambda _t, y: -np.eye(1), method="LSODA", rtol=RTOL,
                    atol=ATOL, events=below, dense_output=True, what="event")
    assert sol.status == 1 and abs(sol.t_events[0][0] - np.log(2.0)) < TOL
    assert abs(sol.sol(0.3)[0] - np.exp(-0.3)) < 1e-6  # the dense output's interpolation error, not the tolerance


@pytest.mark.parametrize("method", ["BDF", "Radau"])
def test_failure_is_one_solver_error_naming_what(method):
    # y' = y^2, y(0) = 1 blows up at t = 1
    with pytest.raises(SolverError, match=rf"^blow-up test: the ODE \({method}, rtol 1e-08\) failed at t = 1: \S"):
        integrate(lambda _t, y: y ** 2, (0.0, 10.0), [1.0], jac=lambda _t, y: np.array([[2.0 * y[0]]]),
                  method=method, rtol=1e-8, atol=1e-12, t_eval=[0.5, 5.0], what="blow-up test")


def test_non_finite_states_are_a_failure_when_asked():
    # LSODA ends "successfully" on a right-hand side that turns NaN
    def rhs(t, y):
        return -y if t < 0.5 else np.full_like(y, np.nan)
    loose = integrate(rhs, (0.0, 1.0), [1.0], jac=None, method="LSODA", rtol=1e-8, atol=1e-12, t_eval=[0.25, 0.75],
                      what="nan")
    assert loose.success and np.isnan(loose.y[0, -1])
    with pytest.raises(SolverError, match=r"^nan rates: the ODE \(LSODA, rtol 1e-08\) failed at t = 0.75: non-finite"):
        integrate(rhs, (0.0, 1.0), [1.0], jac=None, method="LSODA", rtol=1e-8, atol=1e-12, t_eval=[0.25, 0.75],
                  finite=True, what="nan rates")


@pytest.mark.parametrize("rtol", [0.0, -1e-8, np.nan, np.inf, "tight", None])
def test_bad_rtol_is_refused(rtol):
    with pytest.raises(InputError, match=r"^decay: rtol is .*expected a finite number > 0"):
        integrate(lambda _t, y: -y, (0.0, 1.0), [1.0], jac=None, rtol=rtol, atol=1e-12, what="decay")


@pytest.mark.parametrize("atol, match", [(0.0, "atol is 0;"), (np.nan, "atol is nan"),
                                         ([1e-12, -1.0], r"atol\[1\] is -1;"),
                                         ([1e-12, 1e-12, 1e-12], r"atol has shape \(3,\).*shape \(2,\)")])
def test_bad_atol_is_refused(atol, match):
    with pytest.raises(InputError, match=match):
        integrate(lambda _t, y: -y, (0.0, 1.0), [1.0, 2.0], jac=None, rtol=1e-8, atol=atol, what="decay")


def test_an_explicit_method_is_refused():
    with pytest.raises(InputError, match=r"decay: method 'RK45'; expected one of BDF, Radau, LSODA"):
        integrate(lambda _t, y: -y, (0.0, 1.0), [1.0], jac=None, method="RK45", rtol=1e-8, atol=1e-12, what="decay")


def _calls_solve_ivp(tree) -> list[int]:
    """Lines that import, name or call ``solve_ivp`` (scipy.integrate.solve_ivp, any alias)."""
    lines = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and any(a.name == "solve_ivp" for a in node.names):
            lines.append(node.lineno)
        elif isinstance(node, ast.Attribute) and node.attr == "solve_ivp":
            lines.append(node.lineno)
        elif isinstance(node, ast.Name) and node.id == "solve_ivp":
            lines.append(node.lineno)
    return sorted(set(lines))


def test_solve_ivp_has_one_home():
    home, bench = ROOT / "millflow" / "ode.py", ROOT / "millflow" / "bench"
    found = {}
    for path in sorted((ROOT / "millflow").rglob("*.py")):
        if path == home or bench in path.parents:
            continue
        lines = _calls_solve_ivp(ast.parse(path.read_text(encoding="utf-8")))
        if lines:
            found[str(path.relative_to(ROOT))] = lines
    assert found == {}, "call millflow.ode.integrate (or integrate_linear), not scipy's solve_ivp"
    # the check sees a call where there is one
    assert _calls_solve_ivp(ast.parse(home.read_text(encoding="utf-8")))
    assert _calls_solve_ivp(ast.parse("import scipy.integrate as si\nsi.solve_ivp(f, (0, 1), y)"))
