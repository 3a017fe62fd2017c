"""Fitting non-linear kinetics (millflow.fitting.kinetics): the forward model reproduces
the falsification truths it shares no code path with (exact slowing-down, per-member
batch_nonlinear), reduces to the linear model at zero strength, and recovers a known
non-linear truth within its intervals, from the library and through ``millflow fit``."""
import json
import math

import numpy as np
import pytest

from millflow.cli import main
from millflow.errors import InputError
from millflow.falsify.design import batch_design, continuous_design
from millflow.falsify.nonlinear_truths import AggregationTruth, PopulationTruth
from millflow.falsify.study import study_parameters
from millflow.falsify.truths import BREAKAGE_TRUTH, SlowingDownTruth
from millflow.fitting.estimate import fit
from millflow.fitting.kinetics import StackedKinetics, stacked_batch, theta_slowing
from millflow.fitting.models import ForwardModel, ModelSpec
from millflow.nonlinear import batch_nonlinear

TIMES = [30, 60, 120, 240, 480, 960]
DESIGN = batch_design(TIMES)


def _data(truth, design=DESIGN, sigma=0.0, seed=0):
    M = truth.mass_fractions(design)
    clean = design.passing_at_sieves(M).ravel()
    noisy = clean + sigma * np.random.default_rng(seed).standard_normal(clean.size)
    return design.data(noisy, design.sample_keys()), M


def _theta(spec, extra):
    return np.array([{**BREAKAGE_TRUTH, **extra}[n] for n in spec.param_names])


@pytest.mark.parametrize("truth, form, extra, tol", [
    (SlowingDownTruth(1.0), "slowing_down", {"s_slow": 1.0}, 1e-12),   # both exact (theta), rounding
    (PopulationTruth(1.0), "population", {"lam_pop": -1.0}, 1e-6),     # truth rtol 1e-9, fit rtol 1e-7
    (AggregationTruth(0.01), "aggregation", {"beta0": 0.01}, 1e-6),
])
def test_forward_model_reproduces_the_truths(truth, form, extra, tol):
    data, M = _data(truth)
    spec = ModelSpec(mode="batch", kinetics=(form,))
    m = ForwardModel(spec, data, DESIGN.grid)
    assert np.abs(m.predict_grid(_theta(spec, extra))[0] - M).max() < tol


def test_zero_strength_is_the_linear_model():
    data, _ = _data(SlowingDownTruth(0.0))
    lin = ForwardModel(ModelSpec(mode="batch"), data, DESIGN.grid)
    base = lin.predict(_theta(lin.spec, {}))
    for form, name in (("slowing_down", "s_slow"), ("population", "lam_pop"), ("aggregation", "beta0")):
        spec = ModelSpec(mode="batch", kinetics=(form,))
        m = ForwardModel(spec, data, DESIGN.grid)
        assert np.abs(m.predict(_theta(spec, {name: 0.0})) - base).max() < 1e-13  # the same exact path
    assert abs(theta_slowing(np.array([100.0]), 1e-12, 50.0)[0] - 100.0) < 1e-9  # series branch


def test_stacked_solve_matches_member_by_member_solves():
    """One BDF call for a population against batch_nonlinear per member (independent
    integrator calls with the library's Kinetics)."""
    data, _ = _data(SlowingDownTruth(0.0))
    spec = ModelSpec(mode="batch", kinetics=("population", "aggregation"))
    m = ForwardModel(spec, data, DESIGN.grid)
    th = np.tile(_theta(spec, {"lam_pop": -1.0, "beta0": 0.01}), (4, 1))
    th[:, spec.param_names.index("lam_pop")] = [-2.0, -0.5, 0.5, 1.0]
    th[:, spec.param_names.index("beta0")] = [0.0, 0.005, 0.01, 0.02]
    p = m._unpack(th)
    S, b = m.rates(p)[:, 0], m.frac_b(p, 4)
    stack = StackedKinetics(S, b, m._nonlinear.w, p["lam_pop"], m._nonlinear.unit_op, p["beta0"])
    t = np.array(TIMES, float)
    got = stacked_batch(stack, m._feeds[0], t, rtol=1e-10, atol=1e-13)
    for k in range(4):
        ref = batch_nonlinear(m._nonlinear._kin(S[k], b[k], p, k), m._feeds[0], t, rtol=1e-10, atol=1e-13)
        M = ref.M.copy()
        M[:, 0] += ref.overflow_mass
        assert np.abs(got[k] - M).max() < 1e-8  # both at rtol 1e-10 (error estimate of ref ~1e-10)


@pytest.mark.slow  # ~45 s: every local step is a stiff solve of 34 x 13 states
def test_fit_recovers_an_aggregation_truth_within_its_intervals():
    """1 % noise, truth beta0 = 0.01 1/s: one local fit from a start 30 % off."""
    data, _ = _data(AggregationTruth(0.01), sigma=0.01, seed=3)
    spec = ModelSpec(mode="batch", kinetics=("aggregation",))
    m = ForwardModel(spec, data, DESIGN.grid)
    truth = {**BREAKAGE_TRUTH, "beta0": 0.01}
    params = study_parameters(spec, {**truth, "beta0": 0.007})
    res = fit(m, params, global_search=False, starts=1, grid_check=False, quiet=True)
    for name, v in truth.items():
        lo, hi = res.stats["params"][name]["ci95"]
        assert lo <= v <= hi, (name, lo, v, hi)
    assert res.stats["params"]["beta0"]["se"] < 0.003  # beta0 is determined (t ~ 10)


def test_continuous_population_fit_uses_the_non_linear_steady_solve():
    design = continuous_design([60, 120, 240, 480, 960])
    truth = PopulationTruth(1.0)
    data, M = _data(truth, design)
    spec = ModelSpec(mode="well_mixed", tau_column="tau_s", kinetics=("population",))
    m = ForwardModel(spec, data, design.grid)
    assert np.abs(m.predict_grid(_theta(spec, {"lam_pop": -1.0}))[0] - M).max() < 1e-9  # Newton, both sides


def test_bad_kinetics_inputs_are_one_line_errors():
    with pytest.raises(InputError, match="model.kinetics = 'nipping'"):
        ModelSpec(mode="batch", kinetics=("nipping",))
    with pytest.raises(InputError, match="model.where = 'axis' is not possible for transport 'perfect_mixing'"):
        ModelSpec(mode="mill", transport="perfect_mixing", where="axis", kinetics=("slowing_down",),
                  classification="screen_power")
    # the age-structured balances take it: cells, and plug flow along its axis (no error)
    ModelSpec(mode="well_mixed", kinetics=("slowing_down",), classification="screen_power")
    ModelSpec(mode="plug_flow", kinetics=("slowing_down",), classification="screen_power")
    # classification along the axis of a mill with non-linear kinetics is a model like any other
    ModelSpec(mode="mill", transport="axial_dispersion", transport_params={"pe": 8.0}, tau_column="tau_s",
              kinetics=("population",), classification="screen_power")
    with pytest.raises(InputError, match="expected an integer number of tanks"):
        ModelSpec(mode="mill", transport="tanks_in_series", transport_params={"n": 2.5}, tau_column="tau_s",
                  kinetics=("population",))
    with pytest.raises(InputError, match="kinetics_params: unknown \\['kernel'\\]"):
        ModelSpec(mode="batch", kinetics=("population",), kinetics_params={"kernel": "sum"})


def _write(tmp_path, data, kinetics_toml):
    t = data.table.copy()
    # a sieve analysis reports a cumulative curve in [0, 1], non-increasing from coarse to fine
    t["passing"] = t.groupby(["condition", "location", "time_s"], sort=False).passing.transform(
        lambda v: np.minimum.accumulate(v.clip(0.0, 1.0).to_numpy()))
    t["size_mm"] = t.size_m * 1e3
    t[["condition", "location", "time_s", "size_mm", "passing"]].to_csv(tmp_path / "psd.csv", index=False)
    cfg = tmp_path / "fit.toml"
    cfg.write_text(f"""
[data]
psd = "psd.csv"
[grid]
ratio = {2 ** 0.25!r}
top_mm = 4.0
bottom_mm = {4.0 / 2 ** 8:.12g}
[model]
mode = "batch"
{kinetics_toml}
[params.ln_A0]
min = -9.0
max = 0.0
[params.beta]
min = 2.2
max = 8.0
[params.gamma]
min = 0.1
max = 2.0
[optimizer]
starts = 2
popsize = 6
maxiter = 30
[output]
plots = false
""")
    return cfg


def test_cli_fits_slowing_down_and_recovers_s(tmp_path, capsys):
    data, _ = _data(SlowingDownTruth(1.0), sigma=0.01, seed=5)
    cfg = _write(tmp_path, data, 'kinetics = "slowing_down"\n[model.kinetics_params]\nt_ref_min = 16\n'
                                 '[params.s_slow]\nmin = 0.0\nmax = 4.0')
    assert main(["fit", str(cfg), "--json", "--quiet", "--out", str(tmp_path / "out")]) == 0
    out = json.loads(capsys.readouterr().out)
    par = out["params"]
    lo, hi = par["s_slow"]["ci95"]
    assert lo <= 1.0 <= hi and hi - lo < 1.5
    lo, hi = par["ln_A0"]["ci95"]
    assert lo <= math.log(1 / 60) <= hi


def test_cli_refuses_bad_kinetics_with_exit_2(tmp_path, capsys):
    data, _ = _data(SlowingDownTruth(0.0))
    cfg = _write(tmp_path, data, 'kinetics = "aggregation"\n[model.kinetics_params]\nx_ref = 22')
    assert main(["fit", str(cfg), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "x_ref: units of measure missing" in err[0]
