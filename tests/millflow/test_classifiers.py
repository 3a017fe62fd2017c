"""Efficiency curves of millflow.classifiers: defining points, limits, fish-hook, errors."""
import numpy as np
import pytest

from millflow.classifiers import CURVES, efficiency, mill_discharge_rates, plitt, screen_efficiency, tromp, whiten
from millflow.errors import InputError
from millflow.grid import SizeGrid

X = SizeGrid.geometric(1e-2, 2 ** 0.25, 60).x


@pytest.mark.parametrize("fun,kw", [
    (whiten, {"alpha": 3.0}), (whiten, {"alpha": 1.5, "beta": 0.5}),
    (plitt, {"m": 2.5}), (screen_efficiency, {"m": 6.0}), (tromp, {"m": 3.0}),
])
def test_half_at_cut_size_with_bypass(fun, kw):
    # corrected curve = 1/2 at the corrected cut size; actual = bypass + (1 - bypass)/2
    d50 = 1.5e-4
    name = "d50" if fun is screen_efficiency else "d50c"
    c = fun(np.array([d50, d50 / 2]), **{name: d50}, bypass=0.25, **kw)
    assert c[0] == pytest.approx(0.25 + 0.75 * 0.5, abs=1e-12)


@pytest.mark.parametrize("fun,kw", [(whiten, {"alpha": 3.0}), (plitt, {"m": 2.5}), (tromp, {"m": 3.0}),
                                    (screen_efficiency, {"m": 6.0})])
def test_limits_and_monotone(fun, kw):
    name = "d50" if fun is screen_efficiency else "d50c"
    c = fun(X, **{name: 1e-4}, bypass=0.2, **kw)
    assert np.all((c >= 0) & (c <= 1))
    assert np.all(np.diff(c) <= 1e-15)  # coarse -> fine: the coarse fraction falls
    assert c[0] == pytest.approx(1.0, abs=1e-6)
    assert c[-1] == pytest.approx(0.2, abs=1e-3)


def test_whiten_fish_hook_dips_below_bypass():
    c = whiten(X, 1e-4, alpha=1.5, beta=0.6, bypass=0.3)
    assert c.min() < 0.3 - 1e-3  # the dip of the fish-hook
    assert c[-1] == pytest.approx(0.3, abs=2e-2)  # back towards the bypass for the finest sizes


def test_tromp_sharpness():
    m = 3.0
    d25, d75 = 1e-5 * (1 / 3) ** (1 / m), 1e-5 * 3 ** (1 / m)
    c = tromp(np.array([d75, d25]), 1e-5, m)
    assert c == pytest.approx([0.75, 0.25], abs=1e-12)
    assert d25 / d75 == pytest.approx(3 ** (-2 / m))


def test_registry_and_errors():
    assert set(CURVES) == {"whiten", "plitt", "screen", "tromp"}
    with pytest.raises(InputError, match="valid names: plitt, screen, tromp, whiten"):
        efficiency("karra", X, d50=1e-4)
    with pytest.raises(InputError, match="d50c"):
        whiten(X, -1e-4, 3.0)
    with pytest.raises(InputError, match="bypass"):
        plitt(X, 1e-4, 2.0, bypass=1.2)
    assert efficiency(lambda x, k: np.full(len(x), k), X, k=0.5)[0] == 0.5


def test_mill_discharge_rates():
    c = screen_efficiency(X, 1e-3, m=4)
    d = mill_discharge_rates(c)
    assert d[-1] == 1.0 and np.all(d <= 1 + 1e-15) and d[0] < 1e-10
    with pytest.raises(InputError, match="finest class"):
        mill_discharge_rates(np.ones(5))
