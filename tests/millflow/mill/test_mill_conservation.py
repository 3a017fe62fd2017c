"""Issue 10 §2: mass is conserved, or the solve fails loudly.

Mass-balance tolerances: every exact path adds O(N) rounded terms per class, so 1e-12
of the feed (about 5000 ulp) is a safe bound for N <= 60; the issue's failures were
O(1) (axial dispersion at Pe 1e-8 created 68 % extra mass).
"""
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import rtd
from millflow.breakage import NormalizedBreakage, PowerLawRate
from millflow.cli import main
from millflow.errors import AccuracyWarning, SolverError
from millflow.grid import SizeGrid
from millflow.mill import Mill, steady_mill, transfer_matrix
from tests import paths

GRID = SizeGrid.geometric(top_m=2e-3, ratio=2 ** 0.25, n=30)
S = PowerLawRate(A=0.02, alpha=1.0, x0=1e-3)(GRID.x)
S[-1] = 0.0
B = NormalizedBreakage(0.5, 0.8, 3.0).b(GRID.x)
D = np.where(GRID.x > 5e-4, 0.3, 1.0)  # a discharge grate retaining the coarse classes
FEED = np.r_[1.0, np.zeros(29)]
MASS_TOL = 1e-12


@pytest.mark.parametrize("pe", [5e-324, 1e-300, 1e-250, 1e-8, 1e-7, 1e-5, 1e-2, 1.0, 1e3])
def test_axial_dispersion_conserves_at_every_peclet_number(pe):
    ds = steady_mill(S, B, FEED, rtd.AxialDispersion(600.0, pe), d=D)
    p = ds["product"].values
    assert np.all(np.isfinite(p)) and np.all(p >= 0)
    assert abs(p.sum() - 1.0) <= MASS_TOL and ds.attrs["mass_balance_error"] <= MASS_TOL
    # the work, not the time: the refinement stopped on its error estimate before its cap of
    # 16384 volumes (the old 6 s solve refined to the cap); Pe -> 0 is nearly uniform, cheap
    assert ds.attrs["control_volumes"] < 16384
    if pe <= 1e-2:
        assert ds.attrs["control_volumes"] <= 128


@pytest.mark.parametrize("pe", [1e-300, 1e-8, 1e-5])
def test_small_peclet_number_is_perfect_mixing(pe):
    """Pe -> 0 is the perfectly mixed mill with rates S/d; the difference is O(Pe)."""
    mixed = steady_mill(S, B, FEED, rtd.PerfectMixing(600.0), d=D)["product"].values
    axial = steady_mill(S, B, FEED, rtd.AxialDispersion(600.0, pe), d=D)["product"].values
    # observed |difference| ~ 49 Pe for this mill; 1e3 Pe + rounding leaves a factor 20
    assert np.abs(axial - mixed).max() <= 1e3 * pe + 1e-14


def test_transfer_matrix_columns_sum_to_one_at_small_peclet_number():
    P = transfer_matrix(S, B, rtd.AxialDispersion(600.0, 1e-8), D)
    assert np.abs(P.sum(axis=0) - 1.0).max() <= MASS_TOL and P.min() >= 0


@pytest.mark.parametrize("transport", [rtd.PlugFlow(600.0), rtd.RecirculatingCells(600.0, 4, 1.0),
                                       rtd.AxialDispersion(600.0, 6.0)], ids=repr)
@pytest.mark.parametrize("total", [1e-200, 1.0, 598.0, 1e200])
def test_linear_mills_are_scale_invariant(transport, total):
    """The issue: plug flow with a screen gained 1.3e-5 of the mass at a feed of 598 kg/s."""
    unit = steady_mill(S, B, FEED, transport, d=D)
    scaled = steady_mill(S, B, total * FEED, transport, d=D)
    np.testing.assert_allclose(scaled["product"].values / total, unit["product"].values, rtol=1e-12, atol=1e-15)
    assert abs(scaled["product"].values.sum() / total - 1.0) <= MASS_TOL
    fast = Mill(S, B, transport, D).product(total * FEED) / total
    np.testing.assert_allclose(fast, unit["product"].values, rtol=1e-12, atol=1e-15)


def test_a_result_above_its_tolerance_raises_or_warns():
    """Rates 1.7 % apart over a factor 5.6 (alpha = 0.1, N = 100): a forced segregated solve
    cancels in its eigenbasis and its estimate says so."""
    grid = SizeGrid.geometric(1e-2, 2 ** 0.25, 100)
    rates = PowerLawRate(A=1.0 / 60, alpha=0.1, x0=1e-3)(grid.x)
    rates[-1] = 0.0
    b = NormalizedBreakage(0.4, 0.8, 3.0).b(grid.x)
    f = np.eye(100)[0]
    with pytest.raises(SolverError, match=r"steady_mill: segregated: .* above the tolerance"):
        steady_mill(rates, b, f, rtd.TanksInSeries(600.0, 3), method="segregated")
    with pytest.warns(AccuracyWarning):
        ds = steady_mill(rates, b, f, rtd.TanksInSeries(600.0, 3), method="segregated", on_inaccuracy="warn")
    assert ds.attrs["error_estimate"] > 1e-8  # returned, and it says how wrong it may be


def test_open_circuit_flowsheet_at_small_peclet_number_balances(tmp_path, capsys):
    """The issue's case: pe = 1e-8 with a discharge screen took 120 t/h and discharged 1719.7 t/h."""
    text = (paths.FLOWSHEETS / "open_circuit_ball_mill.toml").read_text(encoding="utf-8")
    assert "pe = 6" in text
    f = tmp_path / "open.toml"
    f.write_text(text.replace("pe = 6", "pe = 1e-8"), encoding="utf-8")
    assert main(["run", str(f), "--json", "--no-plots", "--out", str(tmp_path / "o")]) == 0
    import json
    s = json.loads(capsys.readouterr().out)
    assert s["mass_balance_error"] <= MASS_TOL
    assert max(s["unit_mass_balance_error"].values()) <= MASS_TOL


TRANSPORTS = st.sampled_from([
    lambda tau: rtd.PerfectMixing(tau),
    lambda tau: rtd.PlugFlow(tau),
    lambda tau: rtd.TanksInSeries(tau, 3),
    lambda tau: rtd.TanksInSeries(tau, 2.6),
    lambda tau: rtd.RecirculatingCells(tau, 3, 0.5),
    lambda tau: rtd.AxialDispersion(tau, 1e-6),
    lambda tau: rtd.AxialDispersion(tau, 4.0),
    lambda tau: rtd.AxialDispersion(tau, 40.0, bc="open"),
])


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(transport=TRANSPORTS, log_a=st.floats(-6.0, 1.0), alpha=st.floats(0.0, 2.0), tau=st.floats(10.0, 3000.0),
       classify=st.booleans(), total=st.floats(1e-6, 1e6))
def test_random_mills_conserve_or_say_so(transport, log_a, alpha, tau, classify, total):
    """Random valid mills: a result is finite, non-negative and within its tolerance, or
    a SolverError says why (never a silent wrong answer)."""
    grid = SizeGrid.geometric(top_m=4e-3, ratio=2 ** 0.5, n=16)
    rates = PowerLawRate(A=10.0 ** log_a, alpha=alpha, x0=1e-3)(grid.x)
    rates[-1] = 0.0
    b = NormalizedBreakage(0.4, 0.9, 4.0).b(grid.x)
    feed = total * np.r_[0.6, 0.4, np.zeros(14)]
    model = transport(tau)
    d = np.linspace(0.2, 1.0, 16) if classify else None
    try:
        ds = steady_mill(rates, b, feed, model, d=d)
    except SolverError:
        return  # said loudly
    except Exception as exc:  # classification on a transport that cannot carry it: a named InputError
        from millflow.errors import InputError
        assert isinstance(exc, InputError), exc
        return
    p = ds["product"].values
    assert np.all(np.isfinite(p)) and np.all(p >= 0)
    assert abs(p.sum() - feed.sum()) <= 1e-8 * feed.sum()  # the default tol, relative to the feed


def test_very_many_tanks_take_the_exact_segregated_path():
    """TanksInSeries(600, 1e9) built a 1e9-cell network (54 s, 8 GB); it is plug flow to O(1/n)."""
    many = steady_mill(S, B, FEED, rtd.TanksInSeries(600.0, 1e9))
    plug = steady_mill(S, B, FEED, rtd.PlugFlow(600.0))
    assert many.attrs["method"] == "segregated"
    # the TIS/plug difference is O(tau^2 S^2 / n) ~ 1e-10 here; measured 6.4e-11
    assert np.abs(many["product"].values - plug["product"].values).max() < 1e-9


def test_transient_axial_error_estimate_is_honest():
    """Issue 10 §2: the estimate said 3.9e-11 on every grid while the error was 1e-5..4e-8.
    Against a 16x finer grid it now bounds the true error, pessimistic by less than 10x
    (measured 3x: the scheme is second order, the bound assumes first)."""
    from millflow.mill.transient import transient_mill

    grid = SizeGrid.geometric(top_m=2e-3, ratio=2 ** 0.5, n=12)
    rates = PowerLawRate(A=0.02, alpha=1.0, x0=1e-3)(grid.x)
    rates[-1] = 0.0
    b = NormalizedBreakage(0.5, 0.8, 3.0).b(grid.x)
    t = np.linspace(0.0, 3000.0, 31)
    f = np.r_[1.0, np.zeros(11)]
    model = rtd.AxialDispersion(600.0, 10.0)
    ref = transient_mill(rates, b, model, t, feed=f, m_cells=800)["product"].values
    for m in (50, 100):
        ds = transient_mill(rates, b, model, t, feed=f, m_cells=m)
        true = np.abs(ds["product"].values - ref).max()
        assert true <= ds.attrs["error_estimate"] <= 10 * true
