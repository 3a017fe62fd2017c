"""The flowsheet benchmark suite runs and its target case agrees with the substitution baseline."""
import tomllib

from millflow.bench import flowsheet as bench
from tests import paths
from tests.closed_circuit import per_time_text

FLOWSHEETS = paths.FLOWSHEETS


def test_bench_case_matches_example_file():
    # the embedded benchmark circuit is the example file with another grid and 10 cells
    a = tomllib.loads(bench.CLOSED_CIRCUIT_TOML)
    b = tomllib.loads(per_time_text())  # the example in its per-time form
    b["units"]["ball_mill"]["transport"]["n"] = 10
    assert a["units"] == b["units"] and a["streams"] == b["streams"] and a["materials"] == b["materials"]


def test_bench_rows():
    rows = bench.run(quick=True)
    target = rows[0]
    assert target["case"] == "closed_circuit_N100_cells10"
    assert {"case", "method", "runtime_s", "max_abs_error", "mass_balance_error", "ratio_vs_baseline"} <= set(target)
    assert target["n_unknowns"] == 500
    assert target["mass_balance_error"] < 1e-12
    # substitution stops at a relative change of 1e-13 per sweep; the loop gain < 1 bounds
    # its remaining error to ~1e-11 of the flows (up to ~100 kg/s)
    assert target["max_abs_error"] < 1e-9
    assert len(rows) >= 2 + 5
    assert "target" in bench.format_table(rows)


def test_growth_rows_cover_both_forms_and_fit_exponents():
    rows = bench.run(quick=True)
    growth = [r for r in rows if "growth_linear" in r]
    assert len(growth) == 1
    g = growth[0]
    sized = [r for r in rows if "n" in r]
    assert sorted({r["n"] for r in sized}) == [100, 200, 400]
    lin = [r["runtime_s"] for r in sized if r["method"].startswith("per-time")]
    assert g["growth_linear"] == bench.growth_exponent([100, 200, 400], lin)
    assert g["ratio_N100"] == next(r["ratio_vs_baseline"] for r in sized if r["n"] == 100
                                   and r["method"].startswith("prebuilt class-by-class"))
    assert any(r["method"].startswith("energy + hold-up: tear") for r in sized)
    assert "fitted exponents" in g["method"] and "N^" in bench.format_table(rows)
