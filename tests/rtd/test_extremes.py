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


@pytest.mark.parametrize("make, name", [
    (lambda: rtd.TanksInSeries(600.0, None), "n"), (lambda: rtd.RecirculatingCells(600.0, None, 1), "n"),
    (lambda: rtd.RecirculatingCells(600.0, 3, None), "r"), (lambda: rtd.RecirculatingCells(600.0, 3, 0, None), "dead"),
    (lambda: rtd.RecirculatingCells(600.0, 3, 0, 0, None), "bypass"),
    (lambda: rtd.RecirculatingCells(600.0, math.nan), "n"), (lambda: rtd.TanksInSeries(600.0, "3"), None),
])
def test_every_parameter_goes_through_the_checked_number(make, name):
    if name is None:  # a numeric string is a number
        assert make().n == 3.0
        return
    with pytest.raises(ParameterError, match=f"{name} = "):
        make()


def _gamma_reference(n, t, tau):
    """tau E(t) and F(t) of tanks in series in 60-digit arithmetic (mpmath), n, t exact floats."""
    mp = pytest.importorskip("mpmath")
    mp.mp.dps = 60
    nn, u = mp.mpf(n), mp.mpf(t) / mp.mpf(tau)
    pdf = mp.exp(mp.log(nn) + (nn - 1) * mp.log(nn * u) - nn * u - mp.loggamma(nn))
    return float(pdf)


@pytest.mark.parametrize("n", [1e3, 1e4 + 1, 1e6, 1e9, 1e12, 1e15, 1e20, 1e300])
def test_tanks_in_series_density_at_huge_n(n):
    # the plain log form lost n ln(n) eps: 0.4 % at n = 1e12, [1, 0] at 1e20, [1, 1] at 1e300
    T = rtd.TanksInSeries(600.0, n)
    t = np.array([600.0, 600.0 * (1 + 1 / math.sqrt(n)), 600.0 * (1 - 2 / math.sqrt(n))])
    got = T.pdf(t) * 600.0
    # E near its peak has condition number n |t/tau - 1| ~ sqrt(n) in t: the reference takes
    # the same float t; the gamma limit sqrt(n / (2 pi)) exp(-k^2/2) checks the scale
    if n <= 1e15:  # mpmath's log-gamma at the float n: exact
        ref = np.array([_gamma_reference(n, x, 600.0) for x in t])
        # n <= 1e4: the plain log form, relative error ~ n ln(n) eps; above, the Stirling form ~ 30 eps
        np.testing.assert_allclose(got, ref, rtol=1e-11 if n <= 1e4 else 1e-13)
    gauss = math.sqrt(n / (2 * math.pi)) * np.exp(-0.5 * np.array([0.0, 1.0, 4.0]))
    # Stirling: 1/(12 n) + ...; exp of ln(n)/2 ~ 345 at n = 1e300 rounds to 345 eps
    np.testing.assert_allclose(got[0], gauss[0], rtol=1.0 / n + 1e-13)
    if n >= 1e12:  # 1 - t/tau = k/sqrt(n) exact to 1e-16 / (k/sqrt(n)) relative
        np.testing.assert_allclose(got, gauss, rtol=2.0 / math.sqrt(n) + 1e-16 * n ** 0.5 * 10)
    F = T.cdf(t)
    from scipy import stats

    if n <= 1e20:  # t resolves 1/sqrt(n) (at 1e300 all three times are the float 600)
        # the normal limit; the gamma's skewness adds O(1/sqrt(n)), and t's rounding
        # (1e-16 t) moves the argument by 1e-16 sqrt(n)
        ref_F = stats.norm.cdf([0.0, 1.0, -2.0])
        np.testing.assert_allclose(F, ref_F, atol=0.5 / math.sqrt(n) + 1e-16 * math.sqrt(n) + 1e-12)
    else:
        assert F[0] == pytest.approx(0.5, abs=1e-12) and T.cdf(600.0 * (1 + 1e-15)) == 1.0
    assert np.all(np.isfinite(T.pdf(np.array([0.0, 1e-300, 1e308])))) and T.cdf(1e308) == 1.0


@pytest.mark.parametrize("n", [2e4, 1e5, 1e6, 1e8])
def test_tanks_in_series_cdf_large_n_matches_scipy_where_scipy_is_exact(n):
    # Temme's expansion (n > 1e4) against scipy's gammainc, accurate up to ~1e8
    from scipy import special

    from rtd.models import _gamma_cdf_large

    u = np.array([1.0, 1 + 1 / math.sqrt(n), 1 - 3 / math.sqrt(n), 1.5, 0.7, 1 + 8 / math.sqrt(n)])
    np.testing.assert_allclose(_gamma_cdf_large(n, u - 1.0), special.gammainc(n, n * u), atol=1e-12)


def _closed_reference(pe, theta, integral=False, terms=40):
    """The residue series of the closed vessel in 60-digit arithmetic (mpmath)."""
    mp = pytest.importorskip("mpmath")
    mp.mp.dps = 60
    pe = mp.mpf(pe)
    q = pe / 2
    out = mp.mpf(0)
    for k in range(1, terms + 1):
        start = (k - 0.5) * mp.pi / q if k > 1 else (mp.sqrt(2 / q) if q < 1 else 1)
        b = mp.findroot(lambda x: 2 * mp.atan(x) + q * x - k * mp.pi, start)
        z = (1 + 1j * b) * (2 + q * (1 + 1j * b)) * mp.exp(1j * b * q)
        c, p = -2 * pe * b**2 / (2 * mp.re(z)), -q / 2 * (1 + b**2)
        term = c * mp.exp(q + p * mp.mpf(theta))
        out += term / p if integral else term
    return float(1 + out) if integral else float(out)


@pytest.mark.parametrize("pe", [1e-30, 1e-20, 1e-12, 1e-6, 1e-3, 0.5])
def test_closed_density_at_small_peclet_against_60_digits(pe):
    # the beta form of the residues lost eps/Pe: F(tau) at Pe = 1e-20 was 0.63211793 (limit 0.63212056)
    A = rtd.AxialDispersion(600.0, pe)
    theta = np.array([0.01, 0.5, 1.0, 3.0])
    E = np.array([_closed_reference(pe, th) for th in theta])
    F = np.array([_closed_reference(pe, th, True) for th in theta])
    np.testing.assert_allclose(A.pdf(600.0 * theta) * 600.0, E, atol=2e-15)
    np.testing.assert_allclose(A.cdf(600.0 * theta), F, atol=2e-15)


@pytest.mark.parametrize("pe", [5e-324, 1e-320, 1e-300, 1e-250, 1e-200, 1e-100])
def test_closed_vessel_at_vanishing_peclet_is_the_perfect_mixer(pe):
    # used to give pdf 0 / cdf 1 (1e-100), NaN (1e-200), OverflowError, ZeroDivisionError
    A = rtd.AxialDispersion(600.0, pe)
    theta = np.array([1e-3, 0.5, 1.0, 4.0])
    with np.errstate(over="raise", invalid="raise", divide="raise"):
        np.testing.assert_allclose(A.pdf(600.0 * theta) * 600.0, np.exp(-theta), rtol=1e-14)
        np.testing.assert_allclose(A.cdf(600.0 * theta), -np.expm1(-theta), rtol=1e-14, atol=1e-15)
    assert A.analytic_for_re_s_greater_than == pytest.approx(-1 / 600.0, rel=1e-12)
    assert float(A.laplace(0.01)) == pytest.approx(1 / (1 + 6.0), rel=1e-14)
