"""The flowsheet benchmark suite runs and its target case agrees with the substitution baseline."""
from millflow.bench import flowsheet as bench


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


def test_growth_exponent_recovers_a_power_law():
    import pytest

    ns = [100, 200, 400, 800]
    assert bench.growth_exponent(ns, [3e-6 * n ** 1.37 for n in ns]) == pytest.approx(1.37, rel=1e-12)
