"""Tests of millflow.fitting: data checks, forward models, global estimation, eq. 9 statistics.

Synthetic problems come from millflow.synthetic.make_batch_problem (batch grinding, eq. 5
rates, eq. 6 breakage, known parameters, 1 % noise on cumulative passing).
"""
import json
import math

import numpy as np
import pandas as pd
import pytest

from millflow.batch import batch_grind
from millflow.synthetic import BOUNDS, TRUTH, make_batch_problem
from millflow.breakage import NormalizedBreakage, PowerLawRate, b_from_B, normalized_B, power_law_rates
from millflow.breakage.averaged import averaged_breakage, class_average
from millflow.errors import InputError
from millflow.fitting.data import psd_data_from_frames, read_psd_table
from millflow.fitting.estimate import compare_models, fit
from millflow.fitting.models import ForwardModel, ModelSpec, Parameter, default_parameters
from millflow.fitting.statistics import f_test, information_criteria, jacobian, parameter_statistics
from millflow.grid import SizeGrid
from millflow.mill.well_mixed import solve_well_mixed


# ----------------------------------------------------------------------------- data
def _frame(values=None, **extra):
    feed = pd.DataFrame({"condition": "c", "location": "feed", "time_min": 0.0, "size_mm": [4, 2, 1, 0.5],
                         "passing": [1.0, 0.0, 0.0, 0.0]})
    vals = values if values is not None else [1.0, 0.6, 0.3, 0.1]
    samp = pd.DataFrame({"condition": "c", "location": "mill", "time_min": 1.0, "size_mm": [4, 2, 1, 0.5],
                         "passing": vals})
    return pd.concat([feed, samp], ignore_index=True)


def test_long_table_units_and_sorting():
    d = psd_data_from_frames(_frame())
    s = d.samples()
    assert list(s.size_m) == pytest.approx([4e-3, 2e-3, 1e-3, 0.5e-3])
    assert s.time_s.iloc[0] == 60.0
    assert d.conditions == ["c"]


@pytest.mark.parametrize("mutate, match", [
    (lambda f: f.drop(columns="location"), "location"),
    (lambda f: f.rename(columns={"size_mm": "size_inch"}), r"column 'size_inch': unknown unit 'inch'.*expected one of"),
    (lambda f: f.assign(passing=f.passing * 100), "percent"),
    (lambda f: f.assign(passing=[1, 0, 0, 0, 0.2, 0.6, 0.3, 0.1]), "rises"),
    (lambda f: f.assign(size_mm=["4", "x", 1, 0.5, 4, 2, 1, 0.5]), "size_mm"),
])
def test_long_table_errors_name_the_column(mutate, match):
    with pytest.raises(InputError, match=match):
        psd_data_from_frames(mutate(_frame()))


def test_all_zero_data_is_refused():
    with pytest.raises(InputError, match="zero"):
        psd_data_from_frames(_frame([0.0, 0.0, 0.0, 0.0]))


def test_read_csv_and_process_table(tmp_path):
    _frame().to_csv(tmp_path / "psd.csv", index=False)
    pd.DataFrame({"condition": ["c"], "speed": [0.7]}).to_csv(tmp_path / "proc.csv", index=False)
    d = read_psd_table(tmp_path / "psd.csv", tmp_path / "proc.csv")
    assert d.process.loc["c", "speed"] == 0.7
    pd.DataFrame({"condition": ["other"], "speed": [0.7]}).to_csv(tmp_path / "bad.csv", index=False)
    with pytest.raises(InputError, match="bad.csv.*no process parameters"):
        read_psd_table(tmp_path / "psd.csv", tmp_path / "bad.csv")


# --------------------------------------------------------------------- forward model
def test_batch_model_matches_core_solver():
    """The vectorised batch path equals millflow.batch.batch_grind on the grid, with the core's
    class-averaged S and b (millflow.breakage.averaged, an independent O(N^2) quadrature)."""
    model, params, truth = make_batch_problem(n_times=3, n_sieves=10, n_grid=25, noise=0.0)
    theta = np.array([truth[n] for n in model.param_names])
    M = model.predict_grid(theta[None])[0]
    S, b = averaged_breakage(PowerLawRate(math.exp(truth["ln_A0"]), truth["alpha"], 1e-3),
                             NormalizedBreakage(truth["phi"], truth["gamma"], truth["beta"]), model.grid)
    ref = batch_grind(S, b, model._feeds[0], model.times)
    np.testing.assert_allclose(M, ref, atol=1e-12)  # both exact: rounding only


def test_batch_model_on_an_upper_edge_grid_matches_austins_discrete_model():
    """scheme = "upper_edge": S and b at the upper class edges (eqs. 5 and 6 as Austin writes them)."""
    model, params, truth = make_batch_problem(n_times=3, n_sieves=10, n_grid=25, noise=0.0)
    model = model.with_grid(model.grid.with_scheme("upper_edge"))
    theta = np.array([truth[n] for n in model.param_names])
    M = model.predict_grid(theta[None])[0]
    x = model.grid.x
    S = power_law_rates(x, math.exp(truth["ln_A0"]), truth["alpha"], 1e-3)
    b = b_from_B(normalized_B(x, truth["phi"], truth["gamma"], truth["beta"]))
    ref = batch_grind(S, b, model._feeds[0], model.times)
    np.testing.assert_allclose(M, ref, atol=1e-12)  # both exact: rounding only


def test_well_mixed_model_matches_core_solver_and_holdup():
    x = SizeGrid.geometric(4e-3, 2 ** 0.5, 12).x
    rows = [pd.DataFrame({"condition": "*", "location": "feed", "size_m": x[:2], "passing": [1.0, 0.0]})]
    for loc in ("product", "holdup"):
        rows.append(pd.DataFrame({"condition": "c", "location": loc, "size_m": x, "passing": np.linspace(1, 0, 12)}))
    d = psd_data_from_frames(pd.concat(rows), pd.DataFrame({"condition": ["c"], "screen_mm": [1.0]}))
    spec = ModelSpec(mode="well_mixed", breakage="normalized", classification="screen")
    m = ForwardModel(spec, d, SizeGrid(x))
    theta = np.array([0.5, 1.0, 0.4, 0.8, 3.0, 0.0, 1.5])  # ln_A0 alpha phi gamma beta ln_c50 ln_sharp
    M = m.predict_grid(theta[None])[0]
    S, b = averaged_breakage(PowerLawRate(math.exp(0.5), 1.0, 1e-3), NormalizedBreakage(0.4, 0.8, 3.0), m.grid)
    dstar = class_average(lambda y: 1 / (1 + (y / 1e-3) ** math.exp(1.5)), m.grid)
    prod = solve_well_mixed(S, b, m._feeds[0], 1.0, dstar)
    g = {loc: k for k, (_, loc, _) in enumerate(m.groups)}
    np.testing.assert_allclose(M[g["product"]], prod, atol=1e-13)
    assert prod.sum() == pytest.approx(1.0, abs=1e-12)  # mass conserved
    hold = prod / dstar
    np.testing.assert_allclose(M[g["holdup"]], hold / hold.sum(), atol=1e-13)


def test_interpolation_is_exact_at_grid_edges():
    model, _, truth = make_batch_problem(n_times=2, n_sieves=6, n_grid=11, noise=0.0)
    theta = np.array([truth[n] for n in model.param_names])
    M = model.predict_grid(theta[None])[0]
    P = np.cumsum(M[:, ::-1], axis=1)[:, ::-1]
    # sieves are every second edge of this grid: values are P there exactly
    np.testing.assert_allclose(model.predict(theta).reshape(2, 6), P[:, ::2], atol=1e-14)


# ------------------------------------------------------------- checks before fitting
def test_more_parameters_than_data():
    model, params, _ = make_batch_problem(n_times=1, n_sieves=4, n_grid=10)
    with pytest.raises(InputError, match="5 varying parameters but only 4 measured values"):
        fit(model, params)


def test_model_not_evaluable_at_bounds():
    model, params, _ = make_batch_problem(n_times=2, n_sieves=8, n_grid=15)
    params["phi"] = Parameter("phi", 0.4, 0.0, 1.5)  # phi > 1: eq. 6 is not a distribution
    with pytest.raises(InputError, match="non-finite values at a corner of the bounds.*phi=1.5"):
        fit(model, params)


def test_unknown_parameter_and_form_names():
    with pytest.raises(InputError, match="expected one of"):
        ModelSpec(rate="linear")
    with pytest.raises(InputError, match="not parameters of this model"):
        default_parameters(ModelSpec(), {"delta": {"value": 1}})


# --------------------------------------------------------------------------- global
def test_local_start_from_poor_guess_lands_wrong_global_finds_truth():
    bounds = {"ln_A0": (-9.0, 6.0)}
    model, params, truth = make_batch_problem(n_sieves=25, n_grid=49, seed=3, bounds=bounds)
    # rates far too fast: every sample is ground into the sink, the residuals do not change
    # with the parameters there, and the local search stops on that plateau (SSR ~ 100)
    poor = dict(ln_A0=5.5, alpha=0.25, phi=0.5, gamma=1.0, beta=4.0)
    guess = {n: Parameter(n, poor[n], *{**BOUNDS, **bounds}[n]) for n in params}
    local = fit(model, guess, global_search=False, starts=1, grid_check=False)
    glob = fit(model, guess, starts=8, popsize=10, grid_check=False)
    assert local.ssr > 100 * glob.ssr
    assert abs(local.params["ln_A0"].value - truth["ln_A0"]) > 5
    for name in truth:  # the global answer covers the truth
        lo, hi = glob.stats["params"][name]["ci95"]
        assert lo - 0.05 < truth[name] < hi + 0.05, name
    assert glob.starts == 8 and glob.spread < 1e-3


def test_spread_reveals_non_unique_parameters():
    """Eq. 6 is symmetric under (phi, gamma, beta) -> (1 - phi, beta, gamma): with bounds
    that allow both branches the starts reach equal SSR at different parameters."""
    bounds = {"gamma": (0.1, 8.0), "beta": (0.1, 8.0)}
    model, params, _ = make_batch_problem(n_times=4, n_sieves=12, n_grid=23, seed=2, bounds=bounds)
    res = fit(model, params, starts=12, popsize=8, maxiter=60, grid_check=False)
    assert res.spread > 0.5


def test_jacobian_and_covariance_of_a_linear_model():
    """For r = X p - y, J = X exactly and C = s^2 (X^T X)^-1."""
    rng = np.random.default_rng(0)
    X = rng.normal(size=(40, 3))
    y = X @ [1.0, -2.0, 0.5] + 0.1 * rng.normal(size=40)
    p_hat = np.linalg.lstsq(X, y, rcond=None)[0]
    J = jacobian(lambda P: P @ X.T - y, p_hat, np.full(3, -10.0), np.full(3, 10.0))
    np.testing.assert_allclose(J, X, rtol=1e-8, atol=1e-8)
    ssr = float(np.sum((X @ p_hat - y) ** 2))
    st = parameter_statistics(["a", "b", "c"], p_hat, J, ssr, 40)
    C = ssr / 37 * np.linalg.inv(X.T @ X)
    np.testing.assert_allclose(st["covariance"], C, rtol=1e-6)
    assert all(st["params"][n]["significant"] for n in "ab")


def test_information_criteria_and_f_test():
    ic = information_criteria(2.0, 100, 3)
    assert ic["aic"] == pytest.approx(100 * math.log(0.02) + 6)
    assert ic["bic"] == pytest.approx(100 * math.log(0.02) + 3 * math.log(100))
    assert f_test(2.0, 3, 1.0, 4, 100)["F"] == pytest.approx(96.0)


def test_compare_models_ranks_true_form_and_f_test():
    model, params, truth = make_batch_problem(n_times=4, n_sieves=15, n_grid=29, seed=4)
    single = ForwardModel(ModelSpec(mode="batch", breakage="single"), model.data, model.grid)
    out = compare_models({"normalized": model, "single": single},
                         {"normalized": params, "single": default_parameters(single.spec)},
                         starts=3, popsize=8, maxiter=60, grid_check=False)
    assert out["table"][0]["model"] == "normalized"
    (t,) = out["f_tests"]
    assert t["small"] == "single" and t["p_value"] < 1e-6


@pytest.mark.slow
def test_interval_coverage_100_seeds():
    """Issue 6: 95 % intervals cover the truth in >= 90 % of 100 seeded repeats
    (batch, 8 times x 25 sieves, eqs. 5 and 6, 1 % noise). Local fits from the truth:
    this checks the intervals, not the search."""
    hits = {n: 0 for n in TRUTH}
    for seed in range(100):
        # numerical grid = the sieves (the model is exact here; the test is about intervals)
        model, params, truth = make_batch_problem(n_times=8, n_sieves=25, n_grid=25, seed=seed)
        res = fit(model, params, global_search=False, starts=1, grid_check=False)
        for n in truth:
            lo, hi = res.stats["params"][n]["ci95"]
            hits[n] += lo <= truth[n] <= hi
    assert min(hits.values()) >= 90, hits


def test_grid_check_reports_refinement():
    model, params, _ = make_batch_problem(n_times=3, n_sieves=10, n_grid=19, seed=5)
    res = fit(model, params, global_search=False, starts=1)
    g = res.grid_check
    assert g["n_refined"] == 2 * g["n"] - 1
    assert g["relative_change_refit"] < 0.05


def test_to_dict_is_json():
    model, params, _ = make_batch_problem(n_times=3, n_sieves=10, n_grid=19, seed=6)
    out = json.loads(json.dumps(fit(model, params, global_search=False, starts=2).to_dict()))
    for key in ("params", "ssr", "ser", "n_data", "n_params", "starts", "spread"):
        assert key in out
    assert set(out["params"]["alpha"]) >= {"value", "se", "p_value", "ci95"}


def test_tanks_in_series_tend_to_plug_flow():
    """n equal well-mixed tanks (tau/n each) approach plug flow, the batch grind at tau,
    with an error O(1/n)."""
    x = SizeGrid.geometric(4e-3, 2 ** 0.5, 10).x
    rows = [pd.DataFrame({"condition": "*", "location": "feed", "size_m": x[:2], "passing": [1.0, 0.0]}),
            pd.DataFrame({"condition": "c", "location": "product", "size_m": x, "passing": np.linspace(1, 0, 10)})]
    d = psd_data_from_frames(pd.concat(rows))
    theta = np.array([0.3, 1.0, 0.4, 0.8, 3.0])
    plug = ForwardModel(ModelSpec(mode="plug_flow"), d, SizeGrid(x)).predict_grid(theta[None])[0, 0]
    errs = [np.abs(ForwardModel(ModelSpec(mode="well_mixed", n_tanks=n), d, SizeGrid(x))
                   .predict_grid(theta[None])[0, 0] - plug).max() for n in (50, 100)]
    assert errs[1] < 0.6 * errs[0] and errs[1] < 5e-3


def test_hybrid_fit_with_fixed_breakage_and_fractional_objective():
    model, params, truth = make_batch_problem(n_times=4, n_sieves=15, n_grid=29, seed=7)
    for n in ("phi", "gamma", "beta"):
        params[n] = Parameter(n, truth[n], vary=False)
    res = fit(model, params, global_search=False, starts=3)
    assert res.n_params == 2 and set(res.to_dict()["fixed"]) == {"phi", "gamma", "beta"}
    assert abs(res.params["alpha"].value - truth["alpha"]) < 4 * res.stats["params"]["alpha"]["se"]
    frac = ForwardModel(ModelSpec(mode="batch", objective="fractional"), model.data, model.grid)
    theta = np.array([truth[n] for n in frac.param_names])
    y = frac.predict(theta).reshape(4, 15)
    P = frac.predict_cum(theta).reshape(4, 15)
    # retained on each sieve: differences of cumulative passing; they add up to 1 - P(finest)
    np.testing.assert_allclose(y[:, 1:], P[:, :-1] - P[:, 1:], atol=1e-15)
    np.testing.assert_allclose(y.sum(axis=1), 1.0 - P[:, -1], atol=1e-14)


def test_benchmark_global_5p_fit_recovers_truth():
    """Issue 6 benchmark case (5-parameter global fit, 8 times x 30 sieves, 60-class
    grid, 20 starts) runs and recovers the truth. Its time (target < 10 s) is reported
    by `millflow bench fit`, not asserted: a timed test fails on a loaded machine."""
    from millflow.bench.fit import run

    (row,) = run(quick=False, knife=False)
    assert row["runtime_s"] > 0 and "20 LSQ starts" in row["method"], row
    assert row["max_abs_error"] < 0.1
