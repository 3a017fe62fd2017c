"""Closed-vessel axial dispersion against a high-precision eigen-series (mpmath).

In double precision the residue series cancels terms of size ~exp(Pe/4) for Pe > 16, so
the package uses Fourier inversion there. With enough digits (dps > Pe/(2 ln 10) + 40)
the same series is an independent reference for that regime.
"""
import mpmath as mp
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import rtd
from rtd import axial


def series_reference(pe: float, thetas, dps: int):
    """E(theta) = sum_k c_k exp(q + p_k theta) evaluated with ``dps`` digits."""
    with mp.workdps(dps):
        q = mp.mpf(pe) / 2
        kmax = int(q / mp.pi * mp.sqrt(2 * (q + 60) / (q * min(thetas)))) + 5
        terms = []
        for k in range(1, kmax + 1):
            b = (k - mp.mpf(0.5)) * mp.pi / q
            for _ in range(80):  # Newton on 2 atan(b) + q b = k pi
                step = (2 * mp.atan(b) + q * b - k * mp.pi) / (2 / (1 + b * b) + q)
                b -= step
                if abs(step) < mp.mpf(10) ** (5 - dps) * b:
                    break
            z = (1 + 1j * b) * (2 + q * (1 + 1j * b)) * mp.exp(1j * b * q)
            terms.append((-2 * pe * b * b / (2 * mp.re(z)), -(q / 2) * (1 + b * b)))
        return np.array([float(mp.fsum(c * mp.exp(q + p * mp.mpf(th)) for c, p in terms))
                         for th in thetas])


@pytest.mark.parametrize("pe, dps", [(0.01, 30), (3.0, 30), (30.0, 40), (100.0, 60), (1000.0, 260)])
def test_density_matches_high_precision_series(pe, dps):
    thetas = [0.05, 0.3, 0.7, 0.9, 1.0, 1.2, 1.6, 2.5] if pe < 1000 else [0.7, 0.9, 1.0, 1.2, 1.6]
    ref = series_reference(pe, thetas, dps)
    got = rtd.AxialDispersion(1.0, pe).pdf(np.array(thetas))
    np.testing.assert_allclose(got, ref, rtol=1e-11, atol=1e-13)


def test_methods_agree_at_the_regime_switches():
    # Pe = 16 (series) vs Pe = 16 * (1 + 1e-9) (Fourier below theta = 2)
    theta = np.array([0.3, 1.0, 1.9])
    a = rtd.AxialDispersion(1.0, 16.0).pdf(theta)
    b = rtd.AxialDispersion(1.0, 16.0 * (1 + 1e-9)).pdf(theta)
    np.testing.assert_allclose(a, b, rtol=1e-8)
    x = np.array([2.0, 2.2, 2.5])  # the series is accurate from theta = 2 on
    for pe in (30.0, 1e3, 1e4):  # both methods where they meet (theta = 2) and around it
        for integral in (False, True):
            four = axial._closed_fourier(x, pe, integral)
            ser = axial._closed_series(x, pe, integral)
            np.testing.assert_allclose(four, ser, atol=1e-12)


@settings(max_examples=40, deadline=None)
@given(pe=st.floats(1e-2, 1e4), re=st.floats(0, 1e6), im=st.floats(-1e6, 1e6),
       bc=st.sampled_from(["closed", "open"]))
def test_transform_bounded_and_finite_in_right_half_plane(pe, re, im, bc):
    # |E_hat(s)| <= E_hat(Re s) <= 1 for a probability density and Re s >= 0
    m = rtd.AxialDispersion(1.0, pe, bc)
    value = m.laplace(complex(re, im))
    assert np.isfinite(value) and abs(value) <= m.laplace(re) * (1 + 1e-9) + 1e-300
    assert m.laplace(re) <= 1 + 1e-12


@settings(max_examples=30, deadline=None)
@given(tau=st.floats(0.1, 100), n=st.integers(1, 8), re=st.floats(0, 1e3), im=st.floats(-1e3, 1e3))
def test_tanks_network_transform_equals_gamma_form(tau, n, re, im):
    s = complex(re, im) / tau
    assert rtd.TanksInSeries(tau, n).network().laplace(s) == pytest.approx(
        rtd.TanksInSeries(tau, n).laplace(s), rel=1e-10, abs=1e-300)


def test_rtd_imports_nothing_from_millflow():
    import ast
    import pathlib
    for path in pathlib.Path(rtd.__file__).parent.glob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                names = [node.module or ""]
            else:
                continue
            assert not any(n.split(".")[0] == "millflow" for n in names), (path, names)


@pytest.mark.parametrize("pe", [1e3, 1e4, 1e5, 1e6])
def test_cdf_of_large_pe_is_a_sharp_monotone_front(pe):
    m = rtd.AxialDispersion(1.0, pe)
    theta = np.concatenate([np.linspace(0.5, 1.5, 2001), [2.0, 3.0, 10.0]])
    f = m.cdf(theta)
    assert np.all(np.diff(f) >= -1e-12) and f[0] < 1e-12 and np.all(np.abs(f[-3:] - 1.0) <= 1e-14)
    sd = np.sqrt(2 / pe)  # Gaussian limit: F(1 -/+ 2 sd) -> Phi(-/+ 2)
    np.testing.assert_allclose(m.cdf(np.array([1 - 2 * sd, 1 + 2 * sd])), [0.02275, 0.97725],
                               atol=0.05)


def wehner_wilhelm_reference(p: float, pe: float) -> float:
    """E_hat(p) of the closed vessel in 50 digits: 4 a e^{q} / [(1+a)^2 e^{qa} - (1-a)^2 e^{-qa}]."""
    with mp.workdps(50):
        q = mp.mpf(pe) / 2
        a = mp.sqrt(1 + 4 * mp.mpf(p) / pe)
        return float(4 * a * mp.exp(q) / ((1 + a) ** 2 * mp.exp(q * a) - (1 - a) ** 2 * mp.exp(-q * a)))


@pytest.mark.parametrize("pe", [1e-2, 0.3, 10.0, 100.0, 1e4])
def test_closed_transform_real_path_matches_complex_path_and_reference(pe):
    # real p > -Pe/4 runs in float64 (the segregated mill's case); complex p in complex
    p = np.r_[-0.2 * pe, 0.0, np.geomspace(1e-9, 1e9, 37)]
    real = axial.closed_transform(p, pe)
    assert real.dtype == float
    np.testing.assert_allclose(real, axial.closed_transform(p.astype(complex), pe).real, rtol=1e-13, atol=1e-300)
    ref = np.array([wehner_wilhelm_reference(v, pe) for v in p])
    np.testing.assert_allclose(real, ref, rtol=1e-13, atol=1e-300)


@pytest.mark.parametrize("pe", [1e-2, 10.0, 1e4])
def test_open_transform_matches_reference_at_small_and_large_p(pe):
    # open vessel: E_hat = exp(Pe (1 - a) / 2) / a, in 50 digits
    p = np.r_[0.0, np.geomspace(1e-9, 1e9, 19)]
    with mp.workdps(50):
        ref = [float(mp.exp(mp.mpf(pe) / 2 * (1 - mp.sqrt(1 + 4 * mp.mpf(v) / pe))) / mp.sqrt(1 + 4 * mp.mpf(v) / pe))
               for v in p]
    np.testing.assert_allclose(rtd.AxialDispersion(1.0, pe, bc="open").laplace(p), ref, rtol=1e-13, atol=1e-300)
