"""The mill benchmark suite runs and its rows keep the contract of docs/CONTRACTS.md."""
import math

from millflow.bench import mill


def test_bench_mill_quick_rows():
    rows = mill.run(quick=True)
    assert isinstance(mill.DESCRIPTION, str) and mill.format_table(rows)
    for row in rows:
        assert {"case", "method", "runtime_s"} <= set(row)
    paths = [r for r in rows if r["table"] == "paths"]
    assert {r["method"] for r in paths} == {"well_mixed", "cells", "plug_flow", "segregated", "composed"}
    for r in paths:  # every path agrees with its independent exact route (where there is one)
        assert math.isnan(r["max_abs_error"]) or r["max_abs_error"] < 1e-10
        assert r["mass_balance_error"] < 1e-12 and r["error_estimate"] < 1e-12
    axial = [r for r in rows if r["table"] == "axial" and r["method"] == "fv single grid"]
    orders = [r["observed_order"] for r in axial if not math.isnan(r["observed_order"])]
    assert all(abs(q - 2) < 0.1 for q in orders)
