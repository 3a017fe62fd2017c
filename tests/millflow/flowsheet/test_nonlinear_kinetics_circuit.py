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
    text = FILE.read_text().replace("aggregation_beta0_E_t_per_kWh = 0.0045", "aggregation_beta0_E_t_per_kWh = 0") \
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
    (("x_ref_um = 10", "x_ref_um = 10\naggregation_beta0_per_s = 1e-4"),
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
    zero = text.replace("aggregation_beta0_E_t_per_kWh = 0.0045", "aggregation_beta0_E_t_per_kWh = 0") \
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


def _cli_product(tmp_path, text, name):
    """The overflow's cumulative passing [%] from ``millflow run --json`` of ``text``."""
    import json
    import subprocess
    import sys

    path = tmp_path / f"{name}.toml"
    path.write_text(text)
    out = subprocess.run([sys.executable, "-m", "millflow", "run", str(path), "--json", "--no-plots",
                          "--no-grid-check", "--out", str(tmp_path / name)], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    summary = json.loads(out.stdout)
    return np.array(summary["streams"]["overflow"]["cum_passing"], float), summary


def test_equal_specific_energy_gives_an_equal_product_through_the_cli(tmp_path):
    """Breakage and aggregation both per energy (S = S^E P / H, beta0 = beta0^E P / H): the
    mill's state equation depends on P / F only (S tau = S^E P / F, beta0 tau = beta0^E P / F),
    so doubling power and feed, or the hold-up, changes nothing but rounding and the tear
    (tolerance 1e-13 relative change, loop gain ~10: 1e-9 % passing is far above both).
    With beta0 per time the same doubling halves the aggregation per pass: a visible change."""
    base = FILE.read_text()
    ref, summary = _cli_product(tmp_path, base, "base")
    assert summary["units"]["ball_mill"]["specific_energy_kWh_per_t"] > 0
    double = base.replace("solids_tph = 250", "solids_tph = 500").replace("power_kW = 3800", "power_kW = 7600")
    more_holdup = base.replace("holdup_t = 47.5", "holdup_t = 95")
    for name, text in (("double_power_and_feed", double), ("double_holdup", more_holdup)):
        assert text != base
        p, _ = _cli_product(tmp_path, text, name)
        assert np.abs(p - ref).max() < 1e-9, name
    per_time = base.replace("aggregation_beta0_E_t_per_kWh = 0.0045", "aggregation_beta0_per_s = 1e-4")
    p_time, _ = _cli_product(tmp_path, per_time, "per_time")
    assert np.abs(p_time - ref).max() < 1e-9  # the same rate at the design point (0.0045 t/kWh x 80 W/kg)
    p_time2, _ = _cli_product(tmp_path, per_time.replace("solids_tph = 250", "solids_tph = 500")
                              .replace("power_kW = 3800", "power_kW = 7600"), "per_time_double")
    assert np.abs(p_time2 - ref).max() > 1e-4  # per time: the product depends on more than the kWh/t


def test_the_fines_fraction_varies_continuously_across_a_grid_edge():
    """F counts the class that straddles fines_um by its share below it (in ln x): the
    circulating load moves continuously when fines_um crosses a grid edge (with a 0/1 mask
    by the upper edge it jumped 1.4 %), and fines_um = 78 um, inside the class
    (74.3, 81.0] um, lies between its two edges' loads."""
    text = FILE.read_text()
    fs = load(FILE)
    x = fs.grid.x
    lo, hi = (float(v) for v in x[(x > 70e-6) & (x < 90e-6)][::-1][:2])  # the class edges around 78 um

    def load_at(fines_m):
        sol = solve(loads(text.replace("fines_um = 75", f"fines_um = {fines_m * 1e6!r}")))
        return sol.flow("underflow").sum() / sol.flow("fresh").sum()

    at_lo = [load_at(lo * (1 - 1e-7)), load_at(lo * (1 + 1e-7))]
    # 1e-7 relative in the size moves the share by ~1e-6 / ln(ratio): the load by < 1e-6 relative
    assert abs(at_lo[1] - at_lo[0]) < 1e-6 * at_lo[0]
    mid, top = load_at(78e-6), load_at(hi)
    assert min(at_lo[0], top) < mid < max(at_lo[0], top)
    assert abs(top - at_lo[0]) > 1e-3 * at_lo[0]  # the fines size matters (cushioning)


@pytest.mark.parametrize("transport", ['{model = "axial_dispersion", pe = 10}',
                                       # ~20 s: the open vessel's grids and back layer at every tear iteration
                                       pytest.param('{model = "axial_dispersion_open", pe = 10}',
                                                    marks=pytest.mark.slow),
                                       '{model = "series", parts = [{model = "perfect_mixing", tau_fraction = 0.5}, '
                                       '{model = "plug_flow", tau_fraction = 0.5}]}'])
def test_every_transport_of_a_kinetic_mill_meets_the_units_tolerance(transport):
    """The axial grids refine until their estimate meets the units' tolerance (they used to stop
    at 64 volumes with 9e-5), with classification along the axis where it applies."""
    from millflow.flowsheet.units import KINETIC_TOL

    text = FILE.read_text().replace('transport = {model = "tanks_in_series", n = 3}', f"transport = {transport}")
    if "axial_dispersion," in transport:  # (the open vessel with a grate refines to 4096 volumes: slow in a loop)
        text = text.replace("power_kW = 3800", 'power_kW = 3800\nclassification = {curve = "screen", d50_um = 3000, '
                                                'm = 3.0, where = "axis"}')
    sol = solve(loads(text), tol=1e-10)
    mill = sol.units["ball_mill"]
    assert 0 < mill["error_estimate"] <= KINETIC_TOL
    assert ("along the axis" in mill["method"]) == ("axial_dispersion," in transport)
    assert abs(sol.flow("overflow").sum() - 250 / 3.6) < 1e-8 * 250 / 3.6
