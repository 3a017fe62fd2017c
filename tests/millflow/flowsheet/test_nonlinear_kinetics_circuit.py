"""A mill with non-linear kinetics (aggregation, fines cushioning) inside a recycle
circuit, declared in TOML: the solver tears the mill's inlet flow vector."""
import numpy as np
import pytest

from millflow.errors import InputError
from millflow.flowsheet import load, loads, solve
from tests.paths import FLOWSHEETS

FILE = FLOWSHEETS / "closed_circuit_aggregating_mill.toml"
LINEAR = FLOWSHEETS / "closed_circuit_ball_mill.toml"


def linear_circuit():
    """The closed-circuit example (the same ore, rates per energy, hold-up and power) on the
    aggregating example's grid: the aggregating circuit without its kinetics table."""
    import re

    ratio = re.search(r"(?m)^ratio = (\S+)", FILE.read_text()).group(1)
    return loads(re.sub(r"(?m)^ratio = .*$", f"ratio = {ratio}", LINEAR.read_text()))


def test_circuit_solves_and_closes_its_balances():
    sol = solve(load(FILE), tol=1e-12)
    fresh = 250 / 3.6  # 250 t/h in kg/s
    assert abs(sol.flow("overflow").sum() - fresh) < 1e-9 * fresh  # everything fed leaves as product
    # the mill's balance is the tear's: its inlet (from the last pass) against the torn vector it
    # was solved for, 1e-12 relative change times the loop's gain (~3-10)
    assert all(r["mass_balance_error"] < 1e-11 for r in sol.units.values())
    assert sol.solver["tear"]["torn"] == "inlet flow vector" and sol.solver["tear"]["converged"]
    assert sol.units["ball_mill"]["residual"] <= 1e-12  # the mill's own Newton
    # cushioning slows breakage: a higher circulating load than the linear circuit's
    assert sol.flow("underflow").sum() > solve(linear_circuit()).flow("underflow").sum() * 1.05


def test_tear_methods_agree():
    fs = load(FILE)
    ref = solve(fs, method="newton", tol=1e-12).flows
    for method in ("wegstein", "substitution"):
        flows = solve(fs, method=method, tol=1e-12).flows
        # tear tolerance 1e-12 relative to the total flow, times the loop gain (~3)
        assert np.abs(flows - ref).max() < 1e-9 * ref.sum()


def test_linear_physics_through_the_kinetic_path_equals_the_linear_circuit():
    text = FILE.read_text().replace("aggregation_beta0_per_s = 1e-4", "aggregation_beta0_per_s = 0") \
        .replace("cushion_lambda = -1.0", "cushion_lambda = 0.0")
    sol = solve(loads(text), tol=1e-13)
    lin = solve(linear_circuit())
    assert sol.solver["tear"] is not None
    # the mill's Newton (1e-12) and the tear (1e-13 of the total) against one sparse solve
    assert np.abs(sol.flows - lin.flows).max() < 1e-9 * lin.flows.sum()


@pytest.mark.parametrize("edit, match", [
    (('aggregation = "constant"', 'aggregation = "brownian"'), "units.ball_mill.kinetics.aggregation = 'brownian'"),
    (("x_ref_um = 10\n", ""), r"units.ball_mill.kinetics: missing parameter x_ref_<unit>"),
    (("fines_um = 75", "fines_um = 75\ncolour = 2"), "units.ball_mill.kinetics.colour: unknown key"),
    (("aggregation_beta0_per_s = 1e-4", "aggregation_beta0_per_s = 1e-4\naggregation_beta0_E_t_per_kWh = 1e-3"),
     "aggregation_beta0 given per time and per energy"),
])
def test_bad_kinetics_tables(edit, match):
    with pytest.raises(InputError, match=match):
        loads(FILE.read_text().replace(*edit))


CELLS = ('transport = {model = "tanks_in_series", n = 3}\npower_kW = 3800',
         'transport = {model = "recirculating_cells", n = 3, r = 1.0}\npower_kW = 3800\n'
         'classification = {curve = "screen", d50_um = 1500}')


def test_classified_recirculating_mill_with_linear_physics_equals_the_linear_circuit():
    """The kinetic path (Newton on all cells, classified exit) with zero aggregation and
    cushioning against the linear circuit with the same cells and screen (one sparse solve)."""
    text = FILE.read_text().replace(*CELLS)
    zero = text.replace("aggregation_beta0_per_s = 1e-4", "aggregation_beta0_per_s = 0") \
        .replace("cushion_lambda = -1.0", "cushion_lambda = 0.0")
    sol = solve(loads(zero), tol=1e-13)
    start = text.index("[units.ball_mill.kinetics]")
    linear = text[:start] + text[text.index("[units.cyclones]"):]
    lin = solve(loads(linear))
    assert "discharge classification" in sol.units["ball_mill"]["method"]
    assert np.abs(sol.flows - lin.flows).max() < 1e-9 * lin.flows.sum()
    # the non-linear mill: balances close, and the screen changes the circuit
    nl = solve(loads(text), tol=1e-12)
    fresh = 250 / 3.6
    assert abs(nl.flow("overflow").sum() - fresh) < 1e-9 * fresh
    # the mill is torn on its throughput (rates per energy, tau = H / F): its balance holds
    # to the tear's tolerance: 1e-12 is the relative change of the accelerated (Wegstein)
    # iterates; the residual g(X) - X it leaves is larger by the loop gain (measured ~13 here)
    assert all(r["mass_balance_error"] < 5e-11 for r in nl.units.values())
    open_mill = solve(loads(text.replace('\nclassification = {curve = "screen", d50_um = 1500}', "")), tol=1e-12)
    assert abs(nl.flow("underflow").sum() - open_mill.flow("underflow").sum()) > 1e-3 * fresh
