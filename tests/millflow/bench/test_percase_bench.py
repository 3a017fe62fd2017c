"""millflow bench percase: rows carry ratios measured in the same run; the numbers the rows
compare are checked (same values), never the times."""
import numpy as np

from millflow.bench import percase


def test_percase_rows_and_same_numbers(monkeypatch):
    monkeypatch.setattr(percase, "_sweep_case_row", lambda rounds, load: {
        "case": "sweep", "method": "solve_case", "runtime_s": 1.0, "baseline": "solve", "ratio_vs_baseline": 1.0,
        "target_ratio": 1.2, "met": True, "load_average": load, "ratio_vs_solve_work": 1.0, "max_rel_diff": 0.0})
    rows = percase.run(quick=True)
    by = {r["method"]: r for r in rows}
    assert by["percentile_sizes"]["max_rel_diff"] < 1e-11  # the same reading built plainly (roots to ~1e-14)
    for r in rows:
        assert np.isfinite(r["ratio_vs_baseline"]) and r["ratio_vs_baseline"] > 0
    assert {"steady_mill (Dataset)", "Mill.product (fast path)"} <= set(by)
    pops = [r for r in rows if r["method"] == "steady_population"]
    assert len(pops) == 7 and all(r["mills_per_s"] > 0 and r["baseline_mills_per_s"] > 0 for r in pops)
    # the population's products are steady_mill's: rounding of the substitutions (~1e-15),
    # of the eigenbasis (cancellation estimate <= 1e-13) for the segregated transports
    assert all(r["max_rel_diff"] < 1e-12 for r in pops)
    assert "met" in percase.format_table(rows)
