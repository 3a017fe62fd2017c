"""Fitting slowing-down in the particle's age (kappa(t)) in continuous mills: the fit's
forward model is the library's segregated flow over the exit ages
(millflow.mill.nonlinear.age_slowing) for every transport, reduces to the linear
continuous models at s = 0 (another code path), is smooth in s, recovers a noise-free
truth and a truth with 1 % noise through ``millflow fit``; with classification in cells the
forward model is the age-structured balance (millflow.mill.age_cells) and a noise-free
truth is recovered; what the age model cannot fit (classification on the axis, cell
samples) is refused with one-line errors."""
import json

import numpy as np
import pytest

import rtd
from millflow.cli import main
from millflow.errors import InputError
from millflow.falsify.design import continuous_design
from millflow.falsify.study import study_parameters
from millflow.falsify.truths import BREAKAGE_TRUTH, SlowingDownTruth
from millflow.fitting.estimate import fit
from millflow.fitting.kinetics import theta_slowing
from millflow.fitting.models import ForwardModel, ModelSpec
from millflow.mill.nonlinear import age_slowing
from millflow.nonlinear import kinetics

TAUS = [60.0, 240.0, 960.0]
T_REF = max(TAUS)  # the fit's default t_ref in a continuous mill: the longest tau
TRUTH = {**BREAKAGE_TRUTH, "s_slow": 1.0}
CELLS = {"n": 3, "r": 1.0}

# (spec keywords, rtd model of the truth)
TRANSPORTS = {
    "perfect_mixing": (dict(mode="well_mixed"), lambda tau: rtd.PerfectMixing(tau)),
    "tanks_3": (dict(mode="well_mixed", n_tanks=3), lambda tau: rtd.TanksInSeries(tau, 3)),
    "plug_flow": (dict(mode="plug_flow"), lambda tau: rtd.PlugFlow(tau)),
    "cells": (dict(mode="mill", transport="recirculating_cells", transport_params=CELLS),
              lambda tau: rtd.RecirculatingCells(tau, CELLS["n"], CELLS["r"])),
    "axial_closed": (dict(mode="mill", transport="axial_dispersion", transport_params={"pe": 8.0}),
                     lambda tau: rtd.AxialDispersion(tau, 8.0)),
    "axial_open": (dict(mode="mill", transport="axial_dispersion_open", transport_params={"pe": 8.0}),
                   lambda tau: rtd.AxialDispersion(tau, 8.0, bc="open")),
}


def _truth(make, s=1.0, taus=TAUS, holdup=False):
    """(design, (C, N) products [, (C, N) hold-up mass fractions]) of the stated truth, by the library."""
    design = continuous_design(taus)
    S, b, feed = SlowingDownTruth(0.0).linear_parts(design)
    kin = kinetics(S[0], b, theta_t=lambda t: float(theta_slowing(t, s, T_REF)))
    rs = [age_slowing(kin, feed, make(tau), tol=1e-12, holdup=holdup) for tau in taus]
    M = np.array([r.product for r in rs])
    if not holdup:
        return design, M
    H = np.array([r.info["holdup"] / r.info["holdup"].sum() for r in rs])
    return design, M, H


def _theta(spec, values):
    return np.array([[values[n] for n in spec.param_names]])


@pytest.mark.parametrize("name", list(TRANSPORTS))
def test_forward_model_is_the_age_segregated_product(name):
    kw, make = TRANSPORTS[name]
    design, M = _truth(make)
    spec = ModelSpec(tau_column="tau_s", kinetics=("slowing_down",), **kw)
    m = ForwardModel(spec, design.data(), design.grid)
    assert m._nonlinear.t_ref == T_REF
    # the fit at AGE_TOL = 1e-10 against the truth at 1e-12 (quadrature errors ~1e-13)
    assert np.abs(m.predict_grid(_theta(spec, TRUTH))[0] - M).max() < 1e-9


@pytest.mark.parametrize("name", ["perfect_mixing", "tanks_3", "cells"])
def test_zero_strength_is_the_linear_continuous_model(name):
    """s = 0 through the exit-age quadrature against the linear forward model's exact cell
    solves (eq. 3 per cell, or the network's linear solve): another code path."""
    kw, _ = TRANSPORTS[name]
    design = continuous_design(TAUS)
    lin = ForwardModel(ModelSpec(tau_column="tau_s", **kw), design.data(), design.grid)
    age = ForwardModel(ModelSpec(tau_column="tau_s", kinetics=("slowing_down",), **kw), design.data(), design.grid)
    th = {**TRUTH, "s_slow": 0.0}
    ref = lin.predict_grid(_theta(lin.spec, th))[0]
    got = age.predict_grid(_theta(age.spec, th))[0]
    assert np.abs(got - ref).max() < 1e-9  # the quadrature to 1e-10 of the feed


def test_holdup_samples_are_the_age_segregated_holdup():
    import pandas as pd

    from millflow.fitting.data import psd_data_from_frames

    """Hold-up samples of three tanks in series (of one perfect mixer they would equal the product)."""
    design, M, H = _truth(TRANSPORTS["tanks_3"][1], holdup=True)
    base = design.data()
    t = base.table
    data = psd_data_from_frames(pd.concat([t[t.location == "feed"], t[t.location != "feed"],
                                           t[t.location != "feed"].assign(location="holdup")], ignore_index=True),
                                base.process.reset_index(), strict=False)
    spec = ModelSpec(mode="mill", transport="tanks_in_series", transport_params={"n": 3}, tau_column="tau_s",
                     kinetics=("slowing_down",))
    m = ForwardModel(spec, data, design.grid)
    got = m.predict_grid(_theta(spec, TRUTH))[0]
    for g, (c, loc, _) in enumerate(m.groups):
        assert np.abs(got[g] - (M[c] if loc == "product" else H[c])).max() < 1e-9, (c, loc)
    assert np.abs(H - M).max() > 1e-2  # the hold-up is not the product: the samples carry information


def test_predictions_are_smooth_in_s_slow():
    """Finite differences in s see no quadrature noise: central differences at steps h and
    2 h agree to O(h^2) (the fit's step for AGE_TOL = 1e-10 is ~5e-4 x scale)."""
    kw, _ = TRANSPORTS["cells"]
    design = continuous_design(TAUS)
    spec = ModelSpec(tau_column="tau_s", kinetics=("slowing_down",), **kw)
    m = ForwardModel(spec, design.data(), design.grid)
    k = spec.param_names.index("s_slow")
    h = 5e-4
    th = np.repeat(_theta(spec, TRUTH), 5, axis=0)
    th[:, k] += h * np.arange(-2, 3)
    Y = m.predict(th)
    d1 = (Y[3] - Y[1]) / (2 * h)
    d2 = (Y[4] - Y[0]) / (4 * h)
    assert np.abs(d1).max() > 1e-2  # s moves the predictions
    # truncation (2 h)^2 |f'''| ~ 1e-6 x |f'| at most; noise 1e-10 / h ~ 2e-7
    assert np.abs(d1 - d2).max() < 1e-5 * np.abs(d1).max()
    assert np.abs(np.diff(Y, 4, axis=0)).max() < 1e-10  # fourth differences: no jumps


def test_noise_free_truth_is_recovered():
    """A local fit from a start 30 % off: the truth to 1e-5 (relative; ln_A0 and the
    exponents absolute), the limit of the least-squares tolerance (1e-8 in the SSR)."""
    kw, make = TRANSPORTS["tanks_3"]
    design, M = _truth(make)
    data = design.data(design.passing_at_sieves(M).ravel(), design.sample_keys())
    spec = ModelSpec(tau_column="tau_s", kinetics=("slowing_down",), **kw)
    m = ForwardModel(spec, data, design.grid)
    start = {n: 0.7 * v if n in ("s_slow", "phi") else v + 0.1 for n, v in TRUTH.items()}
    res = fit(m, study_parameters(spec, start), global_search=False, starts=1, grid_check=False, quiet=True,
              profile=False)
    for name, v in TRUTH.items():
        got = res.stats["params"][name]["value"]
        assert abs(got - v) < 1e-5 * max(1.0, abs(v)), (name, got, v)


def write_sieve_files(tmp_path, design, M, sigma, seed):
    """psd.csv and process.csv of ``design``'s samples of the products M, with Gaussian
    noise ``sigma`` on the cumulative passing (seeded), as a sieve analysis reports them."""
    clean = design.passing_at_sieves(M).ravel()
    noisy = clean + sigma * np.random.default_rng(seed).standard_normal(clean.size)
    data = design.data(noisy, design.sample_keys())
    t = data.table.copy()
    # a sieve analysis reports a cumulative curve in [0, 1], non-increasing from coarse to fine
    t["passing"] = t.groupby(["condition", "location", "time_s"], sort=False).passing.transform(
        lambda v: np.minimum.accumulate(v.clip(0.0, 1.0).to_numpy()))
    t["size_mm"] = t.size_m * 1e3
    t[["condition", "location", "time_s", "size_mm", "passing"]].to_csv(tmp_path / "psd.csv", index=False)
    data.process.reset_index().to_csv(tmp_path / "process.csv", index=False)


def _write_fit(tmp_path, design, M, sigma, seed, model_toml, params_toml, optimizer_toml):
    write_sieve_files(tmp_path, design, M, sigma, seed)
    cfg = tmp_path / "fit.toml"
    cfg.write_text(f"""
[data]
psd = "psd.csv"
process = "process.csv"
[grid]
ratio = {2 ** 0.25!r}
top_mm = 4.0
bottom_mm = {4.0 / 2 ** 8:.12g}
[model]
tau_column = "tau_s"
kinetics = "slowing_down"
{model_toml}
{params_toml}
[optimizer]
{optimizer_toml}
[output]
plots = false
""")
    return cfg


_CELLS_TOML = 'mode = "mill"\ntransport = "recirculating_cells"\ntransport_params = { n = 3, r = 1.0 }'


def test_cli_fits_slowing_down_in_recirculating_cells(tmp_path, capsys):
    """``millflow fit`` on 1 % noise from three residence times of a 3-cell recirculating
    mill, the breakage shape (phi, gamma, beta) fixed at the truth, a local fit from a
    start off the truth (ln A0 + 0.3, alpha + 0.2, s = 0.5): ln A0, alpha and s within
    their 95 % intervals (a 1-in-20 miss per parameter is the intervals' nominal rate;
    the seed is fixed, so the test is deterministic)."""
    _, make = TRANSPORTS["cells"]
    design, M = _truth(make)
    params = "\n".join(f"[params.{n}]\nvalue = {TRUTH[n]!r}\nvary = false" for n in ("phi", "gamma", "beta"))
    params += (f"\n[params.ln_A0]\nvalue = {TRUTH['ln_A0'] + 0.3!r}\nmin = -7.0\nmax = -2.0"
               "\n[params.alpha]\nvalue = 1.2\nmin = 0.0\nmax = 2.0"
               "\n[params.s_slow]\nvalue = 0.5\nmin = 0.0\nmax = 4.0")
    cfg = _write_fit(tmp_path, design, M, 0.01, 7, _CELLS_TOML, params, "global = false\nstarts = 1")
    assert main(["fit", str(cfg), "--json", "--quiet", "--out", str(tmp_path / "out")]) == 0
    par = json.loads(capsys.readouterr().out)["params"]
    for name in ("ln_A0", "alpha", "s_slow"):
        lo, hi = par[name]["ci95"]
        assert lo <= TRUTH[name] <= hi, (name, lo, TRUTH[name], hi)
    assert par["s_slow"]["se"] < 0.5  # s is determined by three residence times, not only bounded


@pytest.mark.slow  # ~5.5 min on a loaded 2-core machine: a 6-parameter global search, one exit-age
# quadrature per member and condition (5 conditions)
def test_cli_global_fit_recovers_slowing_down_in_tanks_in_series(tmp_path, capsys):
    _, make = TRANSPORTS["tanks_3"]
    design, M = _truth(make, taus=[60.0, 120.0, 240.0, 480.0, 960.0])
    params = ("[params.ln_A0]\nmin = -7.0\nmax = -2.0\n[params.beta]\nmin = 2.2\nmax = 8.0\n"
              "[params.gamma]\nmin = 0.1\nmax = 2.0\n[params.s_slow]\nmin = 0.0\nmax = 4.0")
    cfg = _write_fit(tmp_path, design, M, 0.01, 3, 'mode = "well_mixed"\nn_tanks = 3', params,
                     "starts = 2\npopsize = 6\nmaxiter = 20")
    assert main(["fit", str(cfg), "--json", "--quiet", "--out", str(tmp_path / "out")]) == 0
    par = json.loads(capsys.readouterr().out)["params"]
    for name in ("ln_A0", "s_slow"):
        lo, hi = par[name]["ci95"]
        assert lo <= TRUTH[name] <= hi, (name, lo, TRUTH[name], hi)


def test_slowing_down_refusals_are_one_line_errors():
    # cells, plug flow and both axial vessels take classification (the age-structured balances)
    ModelSpec(mode="mill", transport="axial_dispersion_open", transport_params={"pe": 8.0}, tau_column="tau_s",
              kinetics=("slowing_down",), classification="screen_power", screen_column="screen_mm")
    ModelSpec(mode="plug_flow", tau_column="tau_s", kinetics=("slowing_down",), classification="screen_power",
              screen_column="screen_mm")
    ModelSpec(mode="mill", transport="axial_dispersion", transport_params={"pe": 8.0}, tau_column="tau_s",
              kinetics=("slowing_down",), classification="screen_power", screen_column="screen_mm")
    ModelSpec(mode="well_mixed", tau_column="tau_s", kinetics=("slowing_down",), classification="screen_power",
              screen_column="screen_mm")
    with pytest.raises(InputError, match="model.kinetics_params.t_ref_s"):
        ModelSpec(mode="mill", transport="perfect_mixing", transport_fit=("tau",), kinetics=("slowing_down",))
    ModelSpec(mode="mill", transport="perfect_mixing", transport_fit=("tau",), kinetics=("slowing_down",),
              kinetics_params={"t_ref_s": 600.0})
    with pytest.raises(InputError, match="combines with no other form"):
        ModelSpec(mode="well_mixed", kinetics=("slowing_down", "aggregation"))
    import pandas as pd

    from millflow.fitting.data import psd_data_from_frames
    design = continuous_design(TAUS)
    t = design.data().table
    data = psd_data_from_frames(pd.concat([t, t[t.location != "feed"].assign(location="cell:2")], ignore_index=True),
                                design.data().process.reset_index(), strict=False)
    spec = ModelSpec(tau_column="tau_s", kinetics=("slowing_down",), **TRANSPORTS["cells"][0])
    with pytest.raises(InputError, match=r"locations \['cell:2'\].*'product' and 'holdup'"):
        ForwardModel(spec, data, design.grid)


# ------------------------------------------------ classification: the age-structured balance
SCREEN = {"ln_c50": 0.0, "ln_sharp": 1.0}
CLASSIFIED = {  # (spec keywords, rtd model, where the library places d*)
    "tanks_3_every_tank": (dict(mode="well_mixed", n_tanks=3), lambda tau: rtd.TanksInSeries(tau, 3), "cells"),
    "tanks_3_discharge": (dict(mode="mill", transport="tanks_in_series", transport_params={"n": 3}),
                          lambda tau: rtd.TanksInSeries(tau, 3), "discharge"),
    "cells_discharge": (dict(mode="mill", transport="recirculating_cells", transport_params=CELLS),
                        lambda tau: rtd.RecirculatingCells(tau, CELLS["n"], CELLS["r"]), "discharge"),
}


def _classified_truth(name, s=1.0):
    """(design, spec, (C, N) products) of slowing-down with a screen (d* of the fit's
    classification form at the truth), by the library's age-structured solve to 1e-12."""
    kw, make, where = CLASSIFIED[name]
    design = continuous_design(TAUS, extra_process={"screen_mm": [1.0] * len(TAUS)})
    spec = ModelSpec(tau_column="tau_s", kinetics=("slowing_down",), classification="screen",
                     screen_column="screen_mm", **kw)
    m = ForwardModel(spec, design.data(), design.grid)
    d = m.discharge(m._unpack(_theta(spec, {**TRUTH, **SCREEN})), 1)[0]
    S, b, feed = SlowingDownTruth(0.0).linear_parts(design)
    kin = kinetics(S[0], b, kappa_t=lambda t: 1.0 / (1.0 + s * t / T_REF))
    M = np.array([age_slowing(kin, feed, make(tau), d[c], where, tol=1e-12).product for c, tau in enumerate(TAUS)])
    return design, spec, M


@pytest.mark.parametrize("name", list(CLASSIFIED))
def test_classified_forward_model_is_the_age_structured_product(name):
    design, spec, M = _classified_truth(name)
    m = ForwardModel(spec, design.data(), design.grid)
    got = m.predict_grid(_theta(spec, {**TRUTH, **SCREEN}))[0]
    assert np.abs(got - M).max() < 1e-9
    # the screen matters: the unclassified product differs
    _, plain = _truth(TRANSPORTS["tanks_3"][1])
    assert np.abs(plain - M).max() > 1e-2


def test_noise_free_truth_with_classification_is_recovered():
    """Three tanks in series classified in every tank (a screen): a local fit from a start
    off the truth (s 30 % low, the others + 0.1; the breakage shape phi, gamma, beta fixed
    at the truth to keep the test short) recovers ln A0, alpha, s and the screen to 1e-5
    (relative; ln_A0, alpha and the screen's logs absolute)."""
    design, spec, M = _classified_truth("tanks_3_every_tank")
    data = design.data(design.passing_at_sieves(M).ravel(), design.sample_keys())
    m = ForwardModel(spec, data, design.grid)
    truth = {**TRUTH, **SCREEN}
    start = {n: 0.7 * v if n == "s_slow" else v + 0.1 for n, v in truth.items()}
    fixed = {n: {"value": truth[n], "vary": False} for n in ("phi", "gamma", "beta")}
    res = fit(m, study_parameters(spec, start, fixed), global_search=False, starts=1, grid_check=False, quiet=True,
              profile=False)
    for name, v in ((n, v) for n, v in truth.items() if n not in fixed):
        got = res.stats["params"][name]["value"]
        assert abs(got - v) < 1e-5 * max(1.0, abs(v)), (name, got, v)


#: The axis cases of the fit with slowing-down and classification: spec, fixed-grid solve,
#: tolerance of the fixed grid against the refined solve (measured: ~1e-4 for 64 volumes at
#: Pe 8, second order; ~2e-7 for the plug-flow cells 8..128 extrapolated).
AXIS_CASES = {
    "closed": (dict(mode="mill", transport="axial_dispersion", transport_params={"pe": 8.0}), 1e-3),
    "open": (dict(mode="mill", transport="axial_dispersion_open", transport_params={"pe": 8.0}), 1e-3),
    "plug": (dict(mode="plug_flow"), 1e-5),
}


@pytest.mark.parametrize("case", ["closed", pytest.param("open", marks=pytest.mark.slow), "plug"])  # open: ~50 s
def test_classified_forward_model_on_the_axis(case):
    """Classification on the axis with slowing-down: the forward model is the age-position
    balance on the fit's fixed grids (millflow.mill.age_axis: the closed or open vessel,
    the latter with the sampled discharge, the linear fit's; plug flow by its upwind cells
    extrapolated, PLUG_LEVELS), to the ODE's tolerance (1e-8 relative: ~1e-9 of the feed),
    and within the fixed grids' error of the refined solve (AXIS_CASES)."""
    from millflow.fitting.kinetics import AGE_ODE_ATOL, AGE_ODE_RTOL, AXIAL_CELLS, PLUG_LEVELS
    from millflow.mill.age_axis import age_structured_axial, age_structured_plug

    kw, tol = AXIS_CASES[case]
    design = continuous_design(TAUS, extra_process={"screen_mm": [1.0] * len(TAUS)})
    spec = ModelSpec(tau_column="tau_s", kinetics=("slowing_down",), classification="screen",
                     screen_column="screen_mm", **kw)
    m = ForwardModel(spec, design.data(), design.grid)
    d = m.discharge(m._unpack(_theta(spec, {**TRUTH, **SCREEN})), 1)[0]
    S, b, feed = SlowingDownTruth(0.0).linear_parts(design)
    kin = kinetics(S[0], b, kappa_t=lambda t: 1.0 / (1.0 + t / T_REF))
    got = m.predict_grid(_theta(spec, {**TRUTH, **SCREEN}))[0]
    for c, tau in enumerate(TAUS):
        if case == "plug":
            T = rtd.PlugFlow(tau)
            fixed = age_structured_plug(kin, feed, T, d[c], rtol=AGE_ODE_RTOL, tail=AGE_ODE_ATOL, levels=PLUG_LEVELS,
                                        error_estimate=False)
        else:
            T = rtd.AxialDispersion(tau, 8.0, bc=case)  # the open vessel: routed to age_structured_open, sampled
            fixed = age_structured_axial(kin, feed, T, d[c], m_cells=AXIAL_CELLS, rtol=AGE_ODE_RTOL,
                                         tail=AGE_ODE_ATOL, error_estimate=False)
        assert np.abs(got[c] - fixed.product).max() < 1e-8
        refined = age_structured_axial(kin, feed, T, d[c], tol=1e-7 if case == "plug" else 1e-6)
        assert np.abs(got[c] - refined.product).max() < tol

