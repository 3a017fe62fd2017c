"""``diagnose``: the candidate set, the verdicts, and (slow) the choice on synthetic truths."""
import json
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from millflow.falsify.design import batch_design
from millflow.falsify.study import study_parameters
from millflow.falsify.truths import BREAKAGE_TRUTH, SlowingDownTruth
from millflow.fitting.config import FitConfig
from millflow.fitting.diagnose import _verdicts, candidate_specs, diagnose
from millflow.fitting.models import ModelSpec

DESIGN = batch_design([30, 60, 120, 240, 480, 960], n_sieves=8, sieve_ratio=2.0, grid_per_sieve=1)


def _cfg(truth, seed=1, spec=None):
    M = truth.mass_fractions(DESIGN)
    clean = DESIGN.passing_at_sieves(M).ravel()
    data = DESIGN.data(clean + 0.01 * np.random.default_rng(seed).standard_normal(clean.size), DESIGN.sample_keys())
    spec = spec or ModelSpec(mode="batch")
    return FitConfig("test", data, spec, study_parameters(spec, BREAKAGE_TRUTH), DESIGN.grid,
                     {"global_search": True, "starts": 3, "popsize": 8, "maxiter": 60, "seed": 0})


def test_candidate_sets_for_batch_and_continuous_data():
    data = SimpleNamespace(process=pd.DataFrame({"screen_mm": [1.0]}))
    assert list(candidate_specs(ModelSpec(mode="batch"), data)) == ["linear", "slowing_down", "cushioning",
                                                                     "aggregation"]
    cont = candidate_specs(ModelSpec(mode="well_mixed", tau_column="tau_s"), data)
    assert list(cont) == ["linear", "cushioning", "aggregation", "tanks_2", "tanks_3", "classification"]
    assert cont["aggregation"].kinetics == ("aggregation",) and cont["tanks_3"].n_tanks == 3
    # with classification in the user's model, the non-linear candidates keep it (well-mixed tanks)
    cl = candidate_specs(ModelSpec(mode="well_mixed", classification="screen_power"), data)
    assert cl["aggregation"].classification == "screen_power" and "classification" not in cl
    # ... also along the axis of plug flow (d* in the velocity: the non-linear solves take it)
    ax = candidate_specs(ModelSpec(mode="mill", transport="plug_flow", tau_column="tau_s", where="axis",
                                   classification="screen_power"), data)
    assert ax["aggregation"].classification == "screen_power" and ax["aggregation"].where == "axis"


def _fit(**params):
    return SimpleNamespace(stats={"params": {n: {"value": v, "se": s} for n, (v, s) in params.items()}})


def test_verdicts_compare_each_parameter_with_the_best_model():
    fits = {"linear": _fit(ln_A0=(-4.3, 0.03), gamma=(0.80, 0.02)),
            "slowing_down": _fit(ln_A0=(-4.09, 0.05), gamma=(0.81, 0.02), s_slow=(1.0, 0.2))}
    v = _verdicts(fits, "linear", "slowing_down")
    # ln_A0: 0.21 apart, combined SE 0.058: falsified, with the preferred model's value
    assert v["ln_A0"].startswith("falsified: the data prefer slowing_down, under which this parameter is -4.09 +- 0.05")
    assert v["gamma"].startswith("consistent")  # 0.01 apart, within 2 combined SE
    same = _verdicts(fits, "slowing_down", "slowing_down")
    assert all(s.startswith("consistent with the best-supported model (slowing_down)") for s in same.values())


@pytest.mark.slow  # four fits, three of them ODE-based, on a 9-class grid
@pytest.mark.parametrize("truth, best", [(SlowingDownTruth(1.0), "slowing_down"), (SlowingDownTruth(0.0), "linear")])
def test_diagnose_chooses_the_truths_class(truth, best):
    dg = diagnose(_cfg(truth), quiet=True)
    assert dg.best == best, dg.text()
    assert {r["model"] for r in dg.table} == {"linear", "slowing_down", "cushioning", "aggregation"}
    json.dumps(dg.to_dict())  # JSON-clean (no NaN)


def test_cli_bad_config_is_one_line_exit_2(tmp_path, capsys):
    from millflow.cli import main
    assert main(["diagnose", str(tmp_path / "missing.toml"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "config file not found" in err[0]


@pytest.mark.slow  # three 8-parameter fits on the 151-class knife-mill grid (~40 s)
def test_cli_knife_mill_prefers_three_tanks(tmp_path, capsys):
    """The documented conclusion on the SPRITE knife mill (docs/model-error.md): three tanks
    beat one perfect mixer by more than 10 BIC units; the files are written."""
    from millflow.cli import main
    from tests import paths
    config = paths.EXAMPLES / "knife_mill" / "knife_mill.toml"
    if not (paths.REPO.parent / "shared" / "data" / "sprite-knife-mill").is_dir():
        pytest.skip("the SPRITE knife-mill data are not present")
    out = tmp_path / "diag"
    assert main(["diagnose", str(config), "--json", "--quiet", "--no-loco", "--out", str(out)]) == 0
    res = json.loads(capsys.readouterr().out)
    rows = {r["model"]: r for r in res["table"]}
    assert res["best"] == "tanks_3" and rows["linear"]["delta_bic"] > 10
    assert {"results.nc", "table.csv", "fits.png"} <= {p.name for p in out.iterdir()}
