"""Non-linear steady results split their error estimate into a solver part and a grid part
(zero for S_i, b_ij given per class, with the reason), as steady_mill's Dataset does."""
from __future__ import annotations

import numpy as np

from millflow.breakage import b_from_B, normalized_B, power_law_rates
from millflow.grid import SizeGrid
from millflow.mill import nonlinear as nl
from millflow.mill import steady_mill
from millflow.nonlinear import Aggregation, constant_kernel, kinetics
import rtd


def test_nonlinear_steady_reports_solver_and_grid_parts():
    grid = SizeGrid.geometric(1e-2, 2 ** 0.25, 30)
    S = power_law_rates(grid.x, 0.05, 1.0, grid.x[0])
    b = b_from_B(normalized_B(grid.x, 0.4, 0.8, 3.0))
    feed = np.zeros(30)
    feed[:3] = [0.2, 0.5, 0.3]
    kin = kinetics(S, b, aggregation=Aggregation(constant_kernel(0.01), grid.x[-1]), grid=grid)
    r = nl.well_mixed(kin, feed, 600.0)
    rep = r.error_report
    assert rep["solver"]["value"] == r.error_estimate == r.solver_error_estimate
    assert rep["solver"]["method"] == r.method
    assert rep["grid"]["value"] == 0.0 == r.grid_error_estimate
    assert rep["grid"]["method"].startswith("none: S_i and b_ij given per class")
    # the same statement as the linear steady mill's Dataset
    ds = steady_mill(S, b, feed, rtd.PerfectMixing(600.0))
    assert ds.attrs["grid_error_estimate"] == 0.0 and ds.attrs["grid_error_method"].startswith("none: S_i and b_ij")
