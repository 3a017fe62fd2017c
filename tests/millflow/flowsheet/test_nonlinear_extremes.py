"""Mills with non-linear kinetics in flowsheets: slurry hold-up, aggregation beyond the
grid, tanks in series that must be whole."""
import pytest

from millflow.errors import InputError, SolverError
from millflow.flowsheet import loads, solve
from millflow.flowsheet.results import mass_balance
from tests.millflow.flowsheet.test_water import WET

KINETICS = """[units.ball_mill.kinetics]
aggregation = "constant"
aggregation_beta0_per_s = BETA0
x_ref_um = 10
cushion_lambda = -1.0
fines_um = 75
[units.sump]"""


def _text(mill="slurry_volume_m3 = 40", beta0="1e-4", transport=None):
    text = WET.replace("MILL", mill).replace("CYCLONE", "coarse_solids_content_pct = 75")
    text = text.replace("[units.sump]", KINETICS.replace("BETA0", beta0))
    if transport:
        text = text.replace('transport = {model = "tanks_in_series", n = 3}', transport)
    return text


def test_slurry_volume_mill_with_non_linear_kinetics_runs_at_volume_over_flow():
    # tau = V / Q at the solved solids and water flows (the water was left out: tau 754.6 s
    # where V / Q was 262.8 s)
    sol = solve(loads(_text()))
    Q = sol.flow("mill_feed").sum() / 2800 + sol.water_flow("mill_feed") / 1000 + 50 / 3.6 / 1000
    assert sol.units["ball_mill"]["tau_s"] == pytest.approx(40 / Q, rel=1e-10)  # tear tolerance 1e-13 x headroom
    mb = mass_balance(sol)
    assert mb["water"] < 1e-12 and max(mb["units"].values()) < 1e-12


def test_aggregation_beyond_the_grid_top_is_refused_not_put_in_class_one():
    # the product kernel at this rate sends 96 % of the product beyond the 8 mm grid top,
    # which the flowsheet used to count in class 1 without a word
    text = _text(mill="tau_min = 4", beta0="1e-2").replace('"constant"', '"product"')
    with pytest.raises(SolverError, match=r"units.ball_mill: 0.9\d+ of the mill's product aggregates beyond the top"):
        solve(loads(text))


@pytest.mark.parametrize("n", ["2.5", "1.9", "0"])
def test_non_integer_tanks_are_refused_for_non_linear_kinetics(n):
    with pytest.raises(InputError, match=r"units.ball_mill.transport.n"):
        solve(loads(_text(mill="tau_min = 4", transport=f'transport = {{model = "tanks_in_series", n = {n}}}')))


@pytest.mark.parametrize("key", ["solids_content_pct = 95", "coarse_solids_content_pct = 75"])
def test_a_fraction_written_as_percent_is_warned_at_the_key(key):
    # solids_content_pct = 0.96 (meant 96) used to run on and fail later as a Plitt error
    base, value = key.split(" = ")
    text = WET.replace("MILL", "tau_min = 4").replace("CYCLONE", "coarse_solids_content_pct = 75")
    text = text.replace(key, f"{base} = {float(value) / 100}")
    with pytest.warns(UserWarning, match=rf"{base} = {float(value) / 100}: .* implausibly dilute.*{base} = {value}"):
        loads(text)
