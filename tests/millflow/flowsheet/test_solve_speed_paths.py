"""Fast paths of the flowsheet solve give the plain paths' numbers."""
import dataclasses

import numpy as np
import pytest

from millflow.bench.flowsheet import growth_exponent, shipped_circuit_case
from millflow.breakage.averaged import breakage_on_grid
from millflow.flowsheet import solve
from millflow.grid import SizeGrid


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


def test_growth_exponent_recovers_a_power_law():
    ns = [100, 200, 400, 800]
    assert growth_exponent(ns, [3e-6 * n ** 1.37 for n in ns]) == pytest.approx(1.37, rel=1e-12)

