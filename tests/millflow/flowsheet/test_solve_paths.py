"""Fast paths of the flowsheet solve give the plain paths' numbers."""
import dataclasses

import numpy as np
import pytest

from millflow.breakage.averaged import breakage_on_grid
from millflow.flowsheet import solve
from millflow.grid import SizeGrid
from millflow.synthetic import CLOSED_CIRCUIT_TOML, closed_circuit_case, shipped_circuit_case


def test_mill_keeps_its_forms_per_grid_read_only():
    fs = shipped_circuit_case(40, cells=3)
    mill = fs.units["ball_mill"]
    S1, b1 = mill._on_grid(fs.grid)
    S2, b2 = mill._on_grid(fs.grid)
    assert S1 is S2 and b1 is b2  # computed once per grid object
    S0, b0, _ = breakage_on_grid(mill.rate, mill.breakage, fs.grid)
    np.testing.assert_array_equal(S1, S0)
    np.testing.assert_array_equal(b1, b0)
    with pytest.raises(ValueError):
        S1[0] = 0.0  # read-only: nobody can change what the next tear iteration reads
    other = SizeGrid.geometric(8e-3, 2 ** 0.25, 30)
    assert mill._on_grid(other)[0].shape == (30,)  # another grid: computed for it
    assert dataclasses.replace(mill).__dict__.get("_grid_forms") is None  # not a field: a copy starts afresh
    assert dataclasses.replace(mill) == mill


def test_torn_solve_with_kept_forms_equals_a_fresh_unit_each_iteration():
    # the energy + hold-up circuit (torn on the mill's throughput): keeping S^E, b across the
    # tear iterations gives exactly the numbers of recomputing them at every iteration
    fs = shipped_circuit_case(40, cells=3)
    kept = solve(fs)
    mill = fs.units["ball_mill"]
    plain = type(mill)._on_grid

    def fresh(self, grid):
        object.__setattr__(self, "_grid_forms", None)
        return plain(self, grid)

    try:
        type(mill)._on_grid = fresh
        again = solve(shipped_circuit_case(40, cells=3))
    finally:
        type(mill)._on_grid = plain
    np.testing.assert_array_equal(kept.flows, again.flows)
    assert kept.solver["tear"]["iterations"] == again.solver["tear"]["iterations"] > 1



def _sparse(fs):
    from millflow.flowsheet.solve import _linear_solve, _unit_blocks

    blocks, infos = _unit_blocks(fs, {})
    return _linear_solve(fs, blocks)[0], blocks, infos


@pytest.mark.parametrize("n,cells", [(2, 1), (25, 1), (60, 3), (100, 10), (37, 7)])
def test_class_by_class_solve_equals_sparse_lu(n, cells):
    from millflow.flowsheet.structured import structured_solve

    fs = closed_circuit_case(n, cells)
    x, info, blocks, infos = structured_solve(fs)
    ref, ref_blocks, ref_infos = _sparse(fs)
    np.testing.assert_allclose(x, ref, rtol=0, atol=1e-14 * ref.max())
    assert info["relative_residual"] < 1e-13
    # the mill's transfer matrix, built only when read, is the dense path's
    np.testing.assert_array_equal(blocks["ball_mill"]["out"], ref_blocks["ball_mill"]["out"])
    assert set(infos["ball_mill"]) == set(ref_infos["ball_mill"])  # the same report keys
    assert infos["ball_mill"]["method"] == ref_infos["ball_mill"]["method"]
    assert infos["ball_mill"]["error_estimate"] < 1e-12
    sol = solve(fs)
    assert sol.solver["method"].startswith("class-by-class")
    np.testing.assert_array_equal(sol.flows, x)


def test_two_mills_in_series_and_parallel_equal_sparse_lu():
    from millflow.flowsheet import from_dict
    from millflow.flowsheet.structured import structured_solve
    import tomllib

    data = tomllib.loads(CLOSED_CIRCUIT_TOML)
    data["grid"] = {"top_um": 8000, "bottom_um": 2, "n": 50}
    data["units"]["ball_mill"]["transport"] = {"model": "tanks_in_series", "n": 4}
    data["units"]["regrind"] = {"type": "mill", "material": "ore", "tau_min": 1.5,
                                "transport": {"model": "perfect_mixing"}}
    data["streams"]["overflow"] = {"from": "cyclones.overflow", "to": "regrind"}
    data["streams"]["final"] = {"from": "regrind", "to": "overflow_product"}
    fs = from_dict(data)
    x = structured_solve(fs)[0]
    ref = _sparse(fs)[0]
    np.testing.assert_allclose(x, ref, rtol=0, atol=1e-14 * ref.max())


def test_classified_or_other_mills_take_the_sparse_path():
    from millflow.flowsheet import from_dict
    from millflow.flowsheet.structured import structured_solve
    import tomllib

    data = tomllib.loads(CLOSED_CIRCUIT_TOML)
    data["grid"] = {"top_um": 8000, "bottom_um": 2, "n": 30}
    data["units"]["ball_mill"]["transport"] = {"model": "plug_flow"}
    fs = from_dict(data)
    assert structured_solve(fs) is None
    assert solve(fs).solver["method"].startswith("sparse LU")


@pytest.mark.parametrize("cells", [1, 3])
def test_torn_circuit_class_by_class_equals_sparse_lu(cells, monkeypatch):
    # energy + hold-up: the tear iterations solve the circuit class by class; the same
    # tear with the sparse LU and dense transfer matrices gives the same flows and iterations
    from millflow.flowsheet import structured

    fast = solve(shipped_circuit_case(50, cells))
    assert fast.solver["method"].startswith("class-by-class")
    monkeypatch.setattr(structured, "structured_solve", lambda fs, state=None: None)
    plain = solve(shipped_circuit_case(50, cells))
    assert plain.solver["method"].startswith("sparse LU")
    np.testing.assert_allclose(fast.flows, plain.flows, rtol=0, atol=1e-12 * plain.flows.max())
    assert abs(fast.solver["tear"]["iterations"] - plain.solver["tear"]["iterations"]) <= 1
    assert fast.units["ball_mill"]["tau_s"] == pytest.approx(plain.units["ball_mill"]["tau_s"], rel=1e-12)
    np.testing.assert_allclose(fast.unit_blocks["ball_mill"]["out"], plain.unit_blocks["ball_mill"]["out"],
                               rtol=0, atol=1e-12)
