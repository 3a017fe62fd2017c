"""Series and Parallel compositions: exact routes agree with convolution integrals."""
import numpy as np
import pytest
from scipy import integrate

import rtd
from rtd.compose import chain_networks, talbot_inverse


def convolution(a, b, t):
    """(E_a * E_b)(t) by adaptive quadrature (independent of the transforms)."""
    return integrate.quad(lambda u: float(a.pdf(u) * b.pdf(t - u)), 0, t,
                          epsabs=1e-14, epsrel=1e-12, limit=200)[0]


def test_austin_model_plug_flow_plus_one_large_two_small_mixers():
    mill = rtd.Series(rtd.PlugFlow(0.2), rtd.PerfectMixing(1.0), rtd.PerfectMixing(0.3),
                      rtd.PerfectMixing(0.3))
    assert mill.mean == pytest.approx(1.8) and mill.variance == pytest.approx(1 + 2 * 0.09)
    t = np.array([0.1, 0.2, 0.5, 1.0, 3.0])
    mixers = rtd.Series(*mill.parts[1:])
    # the same formula reached through the Series delay: SIMD and scalar exp may differ by an ulp
    np.testing.assert_allclose(mill.pdf(t), mixers.pdf(t - 0.2), rtol=1e-14, atol=0)
    assert mill.pdf(0.1) == 0.0 and mill.cdf(0.2) == 0.0
    small = rtd.TanksInSeries(0.6, 2)
    for x in (0.4, 1.0, 2.5):
        assert mixers.pdf(x) == pytest.approx(convolution(rtd.PerfectMixing(1.0), small, x),
                                              rel=1e-9)
    assert "Series(PlugFlow(tau=0.2), PerfectMixing(tau=1.0)" in repr(mill)


def test_talbot_route_matches_convolution():
    ad, pm = rtd.AxialDispersion(1.0, 5.0), rtd.PerfectMixing(0.5)
    series = rtd.Series(ad, pm)
    for x in (0.3, 1.0, 2.0, 5.0):
        assert series.pdf(x) == pytest.approx(convolution(ad, pm, x), abs=1e-11)
    f_ref = integrate.quad(lambda u: float(series.pdf(u)), 0, 2.0, epsabs=1e-13)[0]
    assert series.cdf(2.0) == pytest.approx(f_ref, abs=1e-10)


def test_talbot_inverse_of_known_transforms():
    t = np.array([0.05, 0.5, 2.0, 10.0])
    got = talbot_inverse(lambda s: 1 / (1 + s) ** 3, t)
    np.testing.assert_allclose(got, t**2 * np.exp(-t) / 2, rtol=1e-10, atol=1e-14)


def test_chained_network_keeps_volumes_per_unit_feed():
    net = chain_networks([rtd.PerfectMixing(1.0), rtd.RecirculatingCells(2.0, 3, r=0.5)])
    assert net.n == 4 and net.volumes.sum() == pytest.approx(3.0)
    assert net.mean == pytest.approx(3.0, rel=1e-12)


def test_parallel_is_weighted_sum():
    a, b = rtd.PerfectMixing(1.0), rtd.TanksInSeries(3.0, 4)
    par = rtd.Parallel(a, b, weights=(0.25, 0.75))
    t = np.array([0.5, 2.0, 6.0])
    np.testing.assert_allclose(par.pdf(t), 0.25 * a.pdf(t) + 0.75 * b.pdf(t))
    assert par.mean == pytest.approx(0.25 + 2.25)
    assert par.variance == pytest.approx(0.25 * 2 + 0.75 * (9 / 4 + 9) - 2.5**2)
    assert par.laplace(1 + 1j) == pytest.approx(0.25 * a.laplace(1 + 1j) + 0.75 * b.laplace(1 + 1j))
    with pytest.raises(rtd.ParameterError, match="weights"):
        rtd.Parallel(a, b, weights=(0.5, 0.6))


@pytest.mark.parametrize("pe, bc", [(50.0, "closed"), (1e3, "closed"), (1e4, "open")])
def test_fourier_route_for_sharp_axial_dispersion_in_series(pe, bc):
    ad, pm = rtd.AxialDispersion(1.0, pe, bc), rtd.PerfectMixing(0.5)
    series = rtd.Series(ad, pm)
    for x in (0.5, 1.0, 1.2, 2.0, 5.0):
        ref = integrate.quad(lambda u: float(ad.pdf(u) * pm.pdf(x - u)), 0, x,
                             points=[ad.mean] if x > ad.mean else None, epsabs=1e-14, limit=400)[0]
        assert series.pdf(x) == pytest.approx(ref, abs=1e-12)
    # F(t) = P(age_ad + age_pm <= t): for a sharp front, ~ 1 - exp(-(t - mean_ad)/0.5)
    assert series.cdf(3.0) == pytest.approx(1 - np.exp(-(3.0 - ad.mean) / 0.5), abs=0.02)
