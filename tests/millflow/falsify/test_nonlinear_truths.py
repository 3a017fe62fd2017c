"""Non-linear truths (aggregation, population-dependent rates) in the falsification study:
their linear limit, their physics, their config keys and a small study through the CLI."""
import json
import tomllib

import numpy as np
import pytest

from millflow.cli import main
from millflow.errors import InputError
from millflow.falsify import AggregationTruth, PopulationTruth, SlowingDownTruth, batch_design, continuous_design
from millflow.falsify.config import parse_config
from millflow.mill.well_mixed import solve_well_mixed

TIMES = [30.0, 60.0, 120.0, 240.0, 480.0, 960.0]


@pytest.mark.parametrize("truth", [AggregationTruth(0.0), PopulationTruth(0.0)])
def test_strength_zero_is_the_linear_truth(truth):
    d = batch_design(TIMES, n_sieves=10)
    lin = SlowingDownTruth(0.0).mass_fractions(d)
    # the non-linear code at strength 0 (an ODE, rtol 1e-10 for the returned solve) against
    # the exact linear solution
    assert np.abs(truth.mass_fractions(d) - lin).max() < 1e-8


def test_continuous_strength_zero_is_the_linear_perfect_mixer():
    d = continuous_design([30.0, 120.0, 480.0], n_sieves=10)
    S, b, feed = SlowingDownTruth(0.0).linear_parts(d)
    tau = dict(zip(d.conditions, d.process_dict()["tau_s"]))
    lin = np.array([solve_well_mixed(S[0], b, feed, tau[c]) for c in sorted(d.conditions)])
    assert np.abs(AggregationTruth(0.0).mass_fractions(d) - lin).max() < 1e-13  # Newton to 1e-12, linear start


def test_aggregation_coarsens_and_keeps_mass():
    d = batch_design(TIMES, n_sieves=10)
    fine = []
    for s in (0.0, 1e-3, 1e-2):
        t = AggregationTruth(s)
        M = t.mass_fractions(d)
        assert np.allclose(M.sum(axis=1), 1.0, atol=1e-12)  # overflow included in class 1
        fine.append(d.passing_at_sieves(M)[-1, -1])  # passing the finest sieve at the last time
    assert fine[0] > fine[1] > fine[2]


def test_cushioning_slows_grinding():
    d = batch_design(TIMES, n_sieves=10)
    top = [PopulationTruth(s).mass_fractions(d)[-1, :4].sum() for s in (0.0, 1.0, 3.0)]
    assert top[0] < top[1] < top[2]  # more coarse material left when fines cushion harder


BASE = """
replicates = 3
drift_replicates = 1
seed = 4
[truth]
type = "population"
strengths = [0, 3]
[assumed]
mode = "batch"
breakage = "single"
[design]
times_s = [30, 60, 120, 240, 480, 960]
n_sieves = 8
[noise]
kind = "gaussian"
sigma = 0.005
[fit]
starts = 1
popsize = 6
maxiter = 25
"""


@pytest.mark.parametrize("edit, match", [
    (("type = \"population\"", "type = \"population\"\nkernel = \"sum\""), "truth.kernel is only for"),
    (("type = \"population\"", "type = \"aggregation\"\nkernel = \"brownian\""), "truth.kernel = 'brownian'"),
    (("type = \"population\"", "type = \"aggregation\"\nx_ref_um = -3"), "truth.x_ref_um = -3"),
    (("strengths = [0, 3]", "strengths = [0, -1]"), "cushioning exponent >= 0"),
])
def test_nonlinear_config_errors(edit, match):
    with pytest.raises(InputError, match=match):
        parse_config(tomllib.loads(BASE.replace(*edit)), "c.toml")


def test_population_study_through_the_cli(tmp_path, capsys):
    p = tmp_path / "pop.toml"
    p.write_text(BASE)
    assert main(["falsify", str(p), "--json", "--quiet", "--no-plots", "--out", str(tmp_path / "out")]) == 0
    js = json.loads(capsys.readouterr().out)
    rows = {r["strength"]: r for r in js["strengths"]}
    a0, a3 = (abs(rows[s]["parameters"]["ln_A0"]["bias_pct"]) for s in (0.0, 3.0))
    # with cushioning the fitted first-order rate is biased far more than without (measured on
    # class-averaged grids: 23 % without, 90 % with; the assumed single-exponent B is itself a
    # misspecification, hence the bias at strength 0)
    assert a3 > 3 * a0 and a3 > 5.0
    # the short-vs-long refits disagree far more than noise makes them at strength 0
    assert abs(rows[3.0]["drift_pct"]) > 3 * abs(rows[0.0]["drift_pct"])


def test_nonlinear_truth_in_tanks_in_series():
    d = continuous_design([60.0, 240.0], n_sieves=8)
    one = PopulationTruth(1.0).mass_fractions(d)
    three = PopulationTruth(1.0, n_tanks=3).mass_fractions(d)
    assert np.allclose(three.sum(axis=1), 1.0, atol=1e-12)
    # three tanks leave less of the top sizes than one perfect mixer at the same tau
    assert np.all(three[:, :3].sum(axis=1) < one[:, :3].sum(axis=1))
    with pytest.raises(InputError, match="n_tanks"):
        PopulationTruth(1.0, n_tanks=0)
    raw = tomllib.loads(BASE.replace("type = \"population\"", "type = \"population\"\nn_tanks = 3"))
    with pytest.raises(InputError, match="truth.n_tanks is only for"):
        parse_config(raw, "c.toml")  # BASE is a batch design
