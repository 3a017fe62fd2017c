"""A sweep's cases (base flowsheet built once, units rebuilt per case, each variant once)
give the numbers of building each case's whole flowsheet and summarising it."""
import copy

import pytest

from millflow.flowsheet import from_dict, load, solve, summary
from millflow.flowsheet.results import key_figures
from millflow.sweep import CaseSolver
from millflow.sweep.cases import set_key
from tests import paths


def _plain(data, case, source):
    d = copy.deepcopy(data)
    for k, v in case.items():
        set_key(d, k, v)
    return summary(solve(from_dict(d, source=source)))


@pytest.mark.parametrize("case", [
    {"units.ball_mill.tau_min": 3.0, "units.cyclones.d50c_um": 120.0},
    {"units.ball_mill.tau_min": 3.0},  # the same mill variant again: the kept unit
    {"units.fresh_feed.solids_tph": 180.0, "units.cyclones.bypass": 0.2},
    {"units.ball_mill.transport.n": 4.0},  # a nested table of a unit
    {"materials.ore.rate.A_per_min": 1.2},  # not a unit key: the whole flowsheet again
    {"grid.n": 40.0},
])
def test_cases_equal_the_whole_build(case):
    import tomllib

    from tests.closed_circuit import per_time_text

    data = tomllib.loads(per_time_text())  # the shipped circuit with tau_min and rates per time
    data["grid"] = {"top_um": 8000, "bottom_um": 2, "n": 50}
    data["units"]["ball_mill"]["transport"] = {"model": "tanks_in_series", "n": 3}
    before = copy.deepcopy(data)
    solver = CaseSolver(data, "<test>")
    for _ in range(2):  # a kept unit variant gives the same numbers
        got = solver.solve(case)
        ref = _plain(data, case, "<test>")
        assert got["reason"] == ""
        assert got["p80_um"] == {"overflow": ref["streams"]["overflow"]["p80_um"]}  # the product stream
        assert got["p50_um"]["overflow"] == ref["streams"]["overflow"]["p50_um"]
        assert got["circulating_load"] == ref["circulating_load"]  # the same arithmetic: equal floats
        assert got["specific_energy_kWh_per_t"] == ref["specific_energy_kWh_per_t"]
        assert got["mass_balance_error"] == ref["mass_balance_error"]
    assert data == before  # the shared document is never written


def test_bad_case_keys_are_reasons_not_exceptions():
    data = copy.deepcopy(load(paths.FLOWSHEETS / "closed_circuit_ball_mill.toml").meta["document"])
    solver = CaseSolver(data, "<test>")
    assert "no key" in solver.solve({"units.ball_mill.no_such_min": 1.0})["reason"]
    assert "no table" in solver.solve({"units.nowhere.tau_min": 1.0})["reason"]
    bad = solver.solve({"units.cyclones.d50c_um": -5.0})["reason"]
    assert "d50c" in bad


@pytest.mark.parametrize("path", sorted(paths.FLOWSHEETS.glob("*.toml")), ids=lambda p: p.stem)
def test_key_figures_are_the_summarys(path):
    sol = solve(load(path))
    s = summary(sol)
    k = key_figures(sol)
    # the same reading in other containers (Python floats against numpy arrays): equal to
    # rounding, 1e-12 relative (the sums are exact; the interpolation's few operations may
    # round differently where a platform fuses them)
    def same(a, b):
        assert (a is None and b is None) or a == pytest.approx(b, rel=1e-12, abs=1e-300), (a, b)

    for n in s["streams"]:
        same(k["p80_um"][n], s["streams"][n]["p80_um"])
        same(k["p50_um"][n], s["streams"][n]["p50_um"])
    assert set(k["circulating_load"]) == set(s["circulating_load"])
    for n, v in k["circulating_load"].items():
        same(v, s["circulating_load"][n])
    same(k["specific_energy_kWh_per_t"], s["specific_energy_kWh_per_t"])
    assert k["mass_balance_error"] == pytest.approx(s["mass_balance_error"], abs=1e-15)  # a ~1e-16 residual
