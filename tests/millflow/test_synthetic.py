"""The synthetic closed circuit (millflow.synthetic) is the shipped example flowsheet."""
import tomllib

from millflow.synthetic import CLOSED_CIRCUIT_TOML, closed_circuit_case, shipped_circuit_case
from tests.closed_circuit import FILE, per_time_text


def test_closed_circuit_is_the_example_in_its_per_time_form():
    # the circuit written out in millflow.synthetic is the example file with another grid and 10 cells
    a = tomllib.loads(CLOSED_CIRCUIT_TOML)
    b = tomllib.loads(per_time_text())  # the example in its per-time form
    b["units"]["ball_mill"]["transport"]["n"] = 10
    assert a["units"] == b["units"] and a["streams"] == b["streams"] and a["materials"] == b["materials"]


def test_shipped_circuit_is_the_example_as_the_file_drives_it():
    fs = shipped_circuit_case(30, cells=4)
    doc = fs.meta["document"]
    ref = tomllib.loads(FILE.read_text(encoding="utf-8"))
    ref["units"]["ball_mill"]["transport"]["n"] = 4
    assert doc["units"] == ref["units"] and doc["materials"] == ref["materials"]
    assert fs.grid.n == 30


def test_cases_take_their_grid_and_cells():
    fs = closed_circuit_case(25, cells=2)
    assert fs.grid.n == 25 and fs.meta["document"]["units"]["ball_mill"]["transport"] == {
        "model": "tanks_in_series", "n": 2}
    assert abs(fs.grid.x[0] - 8e-3) < 1e-18
