"""The ``model-error`` benchmark suite: found by its hyphenated name, and its target rows
reach the accuracies the issue states (run times are reported, never asserted)."""
from millflow.bench import model_error
from millflow.commands.bench import load_suite


def test_suite_is_found_by_the_hyphenated_name():
    assert load_suite("model-error") is model_error


def test_target_rows_reach_their_accuracy():
    rows = {(r["case"], r["method"]): r for r in model_error.targets(quick=True)}
    batch = rows[("batch_aggregation", model_error.BATCH_METHOD)]
    assert batch["max_abs_error"] <= 1e-8  # the accuracy against the reference solve
    assert batch["mass_balance_error"] < 1e-13
    linear = next(r for (c, _), r in rows.items() if c == "batch_linear_same_api")
    assert linear["method"] == "exact" and linear["max_abs_error"] == 0.0  # the same exact path
    for case in ("well_mixed_nonlinear", "tanks10_nonlinear"):
        r = next(r for (c, _), r in rows.items() if c == case)
        assert r["residual"] <= 1e-12 and r["mass_balance_error"] < 1e-13
