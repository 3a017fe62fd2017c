"""millflow bench nonlinear_batch: its rows check accuracy (and the error estimate), never time."""
from millflow.bench import nonlinear_batch


def test_nonlinear_batch_rows_accuracy_not_time():
    rows = nonlinear_batch.run(quick=True)
    plain, est = rows
    assert plain["method"].startswith("batch_nonlinear (LSODA)")
    assert plain["max_abs_error"] < 1e-9  # rtol 1e-8 on O(1) masses
    assert est["error_estimate"] >= est["max_abs_error"]  # an estimate is at least the actual error
    assert "met" in nonlinear_batch.format_table(rows)
