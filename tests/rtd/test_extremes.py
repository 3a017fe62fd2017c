"""rtd models at extreme parameters and with wrong types: a number or one ParameterError."""
import math

import numpy as np
import pytest

import rtd
from rtd.base import ParameterError


@pytest.mark.parametrize("make", [
    lambda: rtd.PerfectMixing(None), lambda: rtd.PerfectMixing([1.0]), lambda: rtd.PerfectMixing("fast"),
    lambda: rtd.TanksInSeries(None, 3), lambda: rtd.AxialDispersion(60.0, None),
    lambda: rtd.RecirculatingCells(60.0, 3, dead=None), lambda: rtd.PerfectMixing(True),
])
def test_wrong_types_are_parameter_errors(make):
    with pytest.raises(ParameterError, match="expected"):
        make()


@pytest.mark.parametrize("bc", ["closed", "open"])
def test_huge_peclet_moments_do_not_overflow(bc):
    A = rtd.AxialDispersion(600.0, 1e300, bc=bc)
    assert A.variance == pytest.approx(600.0**2 * 2e-300, rel=1e-12)  # 2/Pe, the next term is 1e-300 smaller
    assert A.mean == pytest.approx(600.0, rel=1e-15)


def test_closed_density_at_large_peclet_is_the_gaussian_spike_or_refused():
    # Pe = 1e8: E(t = tau) -> sqrt(Pe / (4 pi)) / tau to relative O(1/sqrt(Pe)) (the
    # Gaussian limit; the closed vessel's correction near theta = 1 is O(1/Pe))
    A = rtd.AxialDispersion(600.0, 1e8)
    assert float(A.pdf(600.0)) == pytest.approx(math.sqrt(1e8 / (4 * math.pi)) / 600.0, rel=1e-3)
    assert float(A.cdf(600.0)) == pytest.approx(0.5, abs=1e-3)
    # Pe = 1e300 used to ask numpy for ~10 GB; now refused before allocating
    with pytest.raises(ParameterError, match="spike"):
        rtd.AxialDispersion(600.0, 1e300).pdf(np.linspace(0, 1200, 11))
