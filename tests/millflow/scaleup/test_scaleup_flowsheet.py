"""Flowsheet mills given by dimensions and operation (millflow.scaleup.flowsheet)."""
import math

import pytest

from millflow.errors import InputError
from millflow.flowsheet import loads, solve
from millflow.flowsheet.results import summary
from millflow.scaleup import MillDesign
from tests.closed_circuit import per_time_text

CLOSED = per_time_text()  # rates per time: a lab table scales them
OLD = 'tau_min = 3.5\ntransport = {model = "tanks_in_series", n = 3}\npower_kW = 3800'
DIMS = ('diameter_m = 4.0\nlength_m = 6.0\nball_filling = 0.35\ncritical_speed_fraction = 0.75\n'
        'ball_size_mm = 50\nsolid_density_kg_m3 = 2700\npower_model = "austin"\n'
        'transport = {model = "tanks_in_series", n = 3}')


def test_mill_by_dimensions_computes_power_holdup_and_tau():
    assert OLD in CLOSED
    fs = loads(CLOSED.replace(OLD, DIMS))
    mill = fs.units["ball_mill"]
    d = MillDesign(4.0, 6.0, 0.35, 0.75, 50.0, solid_density_kg_m3=2700)
    assert mill.holdup == pytest.approx(d.holdup(), rel=1e-14) and mill.tau is None
    assert mill.power == pytest.approx(d.power()["net_kW"] * 1e3, rel=1e-14)
    sol = solve(fs)
    rep = summary(sol)["units"]["ball_mill"]
    # the report shows the computed power and kWh/t = P / (mill throughput)
    assert rep["power_kW"] == pytest.approx(d.power()["net_kW"], rel=1e-12)
    assert rep["specific_energy_kWh_per_t"] > 0 and math.isfinite(rep["specific_energy_kWh_per_t"])
    assert summary(sol)["mass_balance_error"] < 1e-10


def test_lab_table_scales_the_rate_by_specific_power():
    lab = '\n[units.ball_mill.lab]\npower_kW = 0.03\nholdup_kg = 1.4\n'
    fs = loads(CLOSED.replace(OLD, DIMS + lab))
    mill = fs.units["ball_mill"]
    d = MillDesign(4.0, 6.0, 0.35, 0.75, 50.0, solid_density_kg_m3=2700)
    assert mill.rate.factor == pytest.approx((d.power()["net_kW"] / d.holdup()) / (0.03 / 1.4), rel=1e-14)


@pytest.mark.parametrize("old,new,match", [
    ("diameter_m = 4.0", "diameter = 4.0", "units.ball_mill.diameter: units of measure missing; write diameter_<unit>"),
    ("diameter_m = 4.0", "diameter_fathom = 4.0", "units.ball_mill.diameter_fathom: unknown unit 'fathom'"),
    ("critical_speed_fraction = 0.75", "critical_speed_fraction = 1.2", "critical_speed_fraction = 1.2"),
    ("ball_filling = 0.35", "ball_filling = 0.0", "ball_filling = 0.0"),
    ("length_m = 6.0\n", "", "needs length_<unit>"),
    ("solid_density_kg_m3 = 2700", "solid_density_kg_m3 = 2700\nsolids_density_t_m3 = 2.7",
     "solid_density_kg_m3 and solids_density_<unit> both given"),
])
def test_bad_dimensions_are_named(old, new, match):
    with pytest.raises(InputError, match=match):
        loads(CLOSED.replace(OLD, DIMS.replace(old, new)))


@pytest.mark.parametrize("old,new", [
    ("diameter_m = 4.0", "diameter_mm = 4000"),
    ("diameter_m = 4.0", f"diameter_ft = {4.0 / 0.3048!r}"),
    ("ball_size_mm = 50", f"ball_size_in = {50 / 25.4!r}"),
    ("solid_density_kg_m3 = 2700", "solids_density_t_m3 = 2.7"),
])
def test_mill_by_dimensions_reads_any_known_unit(old, new):
    """Dimensions are read through millflow.inputs: any unit of the dimension, converted at the
    edge (the conversions are exact to a few eps)."""
    ref = loads(CLOSED.replace(OLD, DIMS)).units["ball_mill"]
    got = loads(CLOSED.replace(OLD, DIMS.replace(old, new))).units["ball_mill"]
    assert got.holdup == pytest.approx(ref.holdup, rel=1e-13) and got.power == pytest.approx(ref.power, rel=1e-13)


def test_mill_without_its_own_density_takes_the_slurry_density():
    """One name for one quantity: a mill by dimensions in a wet flowsheet takes [slurry]
    solids_density_<unit> when it gives none of its own."""
    text = CLOSED.replace(OLD, DIMS.replace("solid_density_kg_m3 = 2700\n", ""))
    assert "[slurry]" not in text
    wet = text + "\n[slurry]\nsolids_density_t_m3 = 3.1\n"
    mill = loads(wet).units["ball_mill"]
    d = MillDesign(4.0, 6.0, 0.35, 0.75, 50.0, solid_density_kg_m3=3100)
    assert mill.holdup == pytest.approx(d.holdup(), rel=1e-13)
