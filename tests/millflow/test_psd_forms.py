"""Distribution forms (Rosin-Rammler, Gates-Gaudin-Schuhmann) and the fitted tail below
the finest sieve (millflow.psd.from_sieves(tail=...), fit_tail, from_distribution)."""
import numpy as np
import pytest
from numpy.testing import assert_allclose

from millflow.errors import GridError
from millflow.grid import SizeGrid
from millflow.psd import (cum_passing, fit_tail, from_distribution, from_sieves, gates_gaudin_schuhmann,
                          rosin_rammler)

GRID = SizeGrid.geometric(2e-3, 2 ** 0.25, 40)  # 2 mm down to ~2.4 um
SIEVES = 2e-3 * 2 ** (-0.5 * np.arange(12))     # 2 mm down to ~45 um


@pytest.mark.parametrize("rule, form, params", [
    ("gates_gaudin_schuhmann", gates_gaudin_schuhmann, {"xmax": 2e-3, "m": 0.7}),
    ("rosin_rammler", rosin_rammler, {"x63": 4e-4, "n": 1.1}),
])
def test_tail_recovers_the_form_below_the_finest_sieve(rule, form, params):
    P = form(SIEVES, **params)
    P[0] = 1.0 if rule == "gates_gaudin_schuhmann" else P[0]
    if rule == "rosin_rammler":  # a complete PSD: the top sieve passes 100 % to 1e-12
        P = P / P[0]
    fit = fit_tail(SIEVES, P, rule, n_points=4)
    for k, v in params.items():  # the data lie on the form: the fit is exact to rounding
        assert fit.params[k] == pytest.approx(v, rel=1e-9 if rule == "gates_gaudin_schuhmann" else 1e-2)
    frac = from_sieves(SIEVES, P, GRID, tail=rule, tail_points=4)
    below = GRID.x < SIEVES[-1]
    # P at the grid edges below the finest sieve follows the form through the finest value
    expected = form(GRID.x[below], **fit.params) * P[-1] / form(SIEVES[-1:], **fit.params)[0]
    assert_allclose(cum_passing(frac)[below], expected, rtol=1e-10)
    assert abs(frac.sum() - 1) < 1e-14 and frac.min() >= 0


def test_without_a_tail_the_fines_go_to_the_sink_as_before():
    P = gates_gaudin_schuhmann(SIEVES, 2e-3, 0.7)
    frac = from_sieves(SIEVES, P, GRID)
    below = GRID.x < SIEVES[-1]
    assert_allclose(cum_passing(frac)[below], P[-1], rtol=1e-12)  # flat: all in the sink
    assert frac[-1] == pytest.approx(P[-1], rel=1e-12)


def test_tail_errors_name_the_problem():
    P = gates_gaudin_schuhmann(SIEVES, 2e-3, 0.7)
    with pytest.raises(GridError, match="tail = 'weibull'"):
        fit_tail(SIEVES, P, "weibull")
    with pytest.raises(GridError, match="at least 2"):
        fit_tail(SIEVES, np.r_[1.0, np.zeros(11)], "ggs")
    flat = np.r_[1.0, 0.9, 0.5, np.full(9, 0.3)]
    with pytest.raises(GridError, match="slope"):
        fit_tail(SIEVES, flat, "rosin_rammler")
    with pytest.raises(GridError, match="tail_points"):
        fit_tail(SIEVES, P, "ggs", n_points=1)


def test_from_distribution_lumps_only_within_its_tolerance():
    frac = from_distribution(GRID, lambda x: rosin_rammler(x, 2e-4, 1.0))  # 5e-5 above the top: lumped
    assert abs(frac.sum() - 1) < 1e-14
    assert_allclose(cum_passing(frac)[1:], rosin_rammler(GRID.x[1:], 2e-4, 1.0) / rosin_rammler(GRID.x[0], 2e-4, 1.0),
                    rtol=1e-12)
    with pytest.raises(GridError, match="does not cover"):
        from_distribution(GRID, lambda x: rosin_rammler(x, 2e-3, 1.0))
