"""Fitting non-linear kinetics in classified mills of recirculating cells: synthetic data
from a stated non-linear truth (breakage + aggregation, a discharge screen, three
recirculating cells), computed by the library's non-linear cell solver
(millflow.mill.nonlinear.cells) with the classifier curve class-averaged here, are reproduced
by the fit's forward model and recovered by ``millflow fit`` within its 95 % intervals."""
import json
import math

import numpy as np
import pytest

import rtd
from millflow.breakage.averaged import curve_on_grid
from millflow.classifiers import screen_discharge
from millflow.cli import main
from millflow.falsify.design import continuous_design
from millflow.falsify.truths import BREAKAGE_TRUTH, SlowingDownTruth
from millflow.fitting.models import ForwardModel, ModelSpec
from millflow.mill import nonlinear as nl
from millflow.nonlinear import Aggregation, constant_kernel, kinetics
from tests.millflow.fitting.test_continuous_slowing_fit import write_sieve_files

TAUS = [120.0, 240.0, 480.0, 960.0, 240.0, 960.0]
SCREENS = [1.0, 1.0, 1.0, 1.0, 2.0, 2.0]  # mm
TRUTH = {**BREAKAGE_TRUTH, "ln_c50": math.log(0.5), "ln_sharp": math.log(4.0), "beta0": 0.01}
N_CELLS, R = 3, 1.0


def _truth(where="discharge", n_cells=N_CELLS):
    """(design, (C, N) product mass fractions) of the stated truth."""
    design = continuous_design(TAUS, extra_process={"screen_mm": SCREENS})
    S, b, feed = SlowingDownTruth(0.0).linear_parts(design)
    kin = kinetics(S[0], b, aggregation=Aggregation(constant_kernel(TRUTH["beta0"]), float(design.sieves_m[-1])),
                   grid=design.grid)
    rows = []
    for tau, screen in zip(TAUS, SCREENS):
        # the screen curve class-averaged on the grid, as the fit's forward model puts it there
        d = curve_on_grid(lambda y, screen=screen: screen_discharge(y, 0.5 * screen * 1e-3, 4.0), design.grid)
        r = nl.cells(kin, feed, rtd.RecirculatingCells(tau, n_cells, R), d, where)
        assert r.error_estimate < 1e-10
        p = r.product.copy()
        p[0] += r.overflow_mass  # aggregates above the top class sit on the top sieve
        rows.append(p)
    return design, np.array(rows)


@pytest.mark.parametrize("where", [None, "cells"])
def test_forward_model_reproduces_the_classified_cells_truth(where):
    design, M = _truth(where or "discharge")
    spec = ModelSpec(mode="mill", transport="recirculating_cells", transport_params={"n": N_CELLS, "r": R},
                     tau_column="tau_s", classification="screen", screen_column="screen_mm",
                     kinetics=("aggregation",), where=where)
    m = ForwardModel(spec, design.data(), design.grid)
    got = m.predict_grid(np.array([[TRUTH[n] for n in spec.param_names]]))[0]
    assert np.abs(got - M).max() < 1e-10  # Newton on both sides, converged to ~1e-12


@pytest.mark.slow  # ~4 min on a loaded machine: a 8-parameter global search over 6 steady non-linear mills
def test_cli_fit_recovers_a_non_linear_truth_with_classification_and_recirculating_cells(tmp_path, capsys):
    design, M = _truth()
    write_sieve_files(tmp_path, design, M, 0.005, 1)
    cfg = tmp_path / "fit.toml"
    # bounds: at ln_c50 -> -2 with ln_A0 -> -7 the retained coarse classes aggregate faster than
    # they break and the mill has no steady state (the fit's corner check refuses such bounds)
    cfg.write_text(f"""
[data]
psd = "psd.csv"
process = "process.csv"
[grid]
ratio = {2 ** 0.25!r}
top_mm = 4.0
bottom_mm = {4.0 / 2 ** 8:.12g}
[model]
mode = "mill"
transport = "recirculating_cells"
transport_params = {{ n = {N_CELLS}, r = {R} }}
tau_column = "tau_s"
classification = "screen"
screen_column = "screen_mm"
kinetics = "aggregation"
[params.ln_A0]
min = -6.0
max = -2.0
[params.alpha]
min = 0.0
max = 2.0
[params.beta]
min = 2.2
max = 8.0
[params.gamma]
min = 0.1
max = 2.0
[params.ln_c50]
min = -1.5
max = 0.5
[params.ln_sharp]
min = 0.5
max = 2.5
[params.beta0]
min = 0.0
max = 0.02
[optimizer]
starts = 2
popsize = 6
maxiter = 20
[output]
plots = false
""")
    assert main(["fit", str(cfg), "--json", "--quiet", "--out", str(tmp_path / "out")]) == 0
    par = json.loads(capsys.readouterr().out)["params"]
    for name, v in TRUTH.items():
        lo, hi = par[name]["ci95"]
        assert lo <= v <= hi, (name, lo, v, hi)
    assert par["beta0"]["se"] < 0.002  # aggregation is determined (t ~ 20), not only bounded


@pytest.mark.parametrize("transport, tp", [("recirculating_cells", {"n": N_CELLS, "r": R}),
                                           ("tanks_in_series", {"n": 3}), ("perfect_mixing", {})])
def test_holdup_and_cell_samples_at_zero_strength_equal_the_linear_model(transport, tp):
    """Hold-up and cell samples of a classified non-linear mill (beta0 = 0 through the
    non-linear code) against the linear forward model's own solves (another code path)."""
    import pandas as pd

    from millflow.fitting.data import psd_data_from_frames

    design = continuous_design(TAUS, extra_process={"screen_mm": SCREENS})
    base = design.data()
    locs = ["product", "holdup"] + (["cell:2"] if transport != "perfect_mixing" else [])
    t = base.table
    feed = t[t.location == "feed"]
    samples = [t[(t.location != "feed")].assign(location=loc) for loc in locs]
    data = psd_data_from_frames(pd.concat([feed, *samples], ignore_index=True),
                                base.process.reset_index(), strict=False)
    common = dict(mode="mill", transport=transport, transport_params=tp, tau_column="tau_s",
                  classification="screen", screen_column="screen_mm")
    lin = ForwardModel(ModelSpec(**common), data, design.grid)
    nlm = ForwardModel(ModelSpec(**common, kinetics=("aggregation",)), data, design.grid)
    th = {**TRUTH, "beta0": 0.0}
    ref = lin.predict_grid(np.array([[th[n] for n in lin.param_names]]))[0]
    got = nlm.predict_grid(np.array([[th[n] for n in nlm.param_names]]))[0]
    assert {g[1] for g in nlm.groups} == set(locs)
    assert np.abs(got - ref).max() < 1e-11
    # at beta0 = 0.01 the hold-up samples move (aggregation seen inside the mill)
    th1 = np.array([[TRUTH[n] for n in nlm.param_names]])
    assert np.abs(nlm.predict_grid(th1)[0] - got).max() > 1e-3
