"""Every RTD model: E integrates to 1, moments match closed forms, transform matches
quadrature of E, F is the integral of E, and the transform behaves for large and complex s.

Tolerances: quadrature itself is good to ~1e-13; 1e-8 (integral, moments) and 1e-10
(transform) are the targets of the issue.
"""
import math
import warnings

import numpy as np
import pytest
from scipy import integrate

import rtd

PES = [0.01, 0.1, 1.0, 10.0, 16.0, 30.0, 100.0, 1e3, 1e4]

CASES = (
    [rtd.PerfectMixing(2.0), rtd.TanksInSeries(2.0, 1.0), rtd.TanksInSeries(2.0, 3.0),
     rtd.TanksInSeries(1.5, 7.3), rtd.TanksInSeries(1.0, 200.0)]
    + [rtd.AxialDispersion(1.0, pe) for pe in PES]
    + [rtd.AxialDispersion(1.0, pe, bc="open") for pe in PES]
    + [rtd.RecirculatingCells(2.0, 4, r=0.5), rtd.RecirculatingCells(2.0, 3, 1.0, 0.2, 0.1),
       rtd.CompartmentNetwork([1.0, 0.5], [[0, 0.3], [0.3, 0]], [1, 0], [1.0, 0]),
       rtd.Series(rtd.PlugFlow(0.2), rtd.PerfectMixing(1.0), rtd.PerfectMixing(0.3),
                  rtd.PerfectMixing(0.3)),
       rtd.Series(rtd.AxialDispersion(1.0, 5.0), rtd.PerfectMixing(0.5)),
       rtd.Parallel(rtd.PerfectMixing(1.0), rtd.TanksInSeries(2.0, 4), weights=(0.3, 0.7))]
)
IDS = [repr(m)[:60] for m in CASES]


@pytest.mark.parametrize("model", CASES, ids=IDS)
def test_density_integrates_to_one(model, integrate_density):
    assert integrate_density(model) == pytest.approx(1.0, abs=1e-8)


@pytest.mark.parametrize("model", CASES, ids=IDS)
def test_mean_and_variance_match_closed_forms(model, integrate_density):
    m1 = integrate_density(model, lambda t: t)
    m2 = integrate_density(model, lambda t: t * t)
    assert m1 == pytest.approx(model.mean, rel=1e-8)
    assert m2 - m1**2 == pytest.approx(model.variance, rel=1e-8)


@pytest.mark.parametrize("model", CASES, ids=IDS)
def test_laplace_matches_quadrature(model, integrate_density):
    for s in (0.3 / model.mean, 2.0 / model.mean):
        ref = integrate_density(model, lambda t: np.exp(-s * t))
        assert abs(model.laplace(s) - ref) < 1e-10
    s = (0.5 + 1.0j) / model.mean
    ref = integrate_density(model, lambda t: np.exp(-s * t), complex_weight=True)
    assert abs(model.laplace(s) - ref) < 1e-10


@pytest.mark.parametrize("model", CASES, ids=IDS)
def test_cdf_is_integral_of_pdf(model):
    sd = math.sqrt(model.variance)
    start = 0.2 if isinstance(model, rtd.Series) and model.parts[0] == rtd.PlugFlow(0.2) else 0.0
    for x in (model.mean - sd, model.mean, model.mean + 2 * sd):
        if x <= start:
            continue
        pieces = [start, max(start, model.mean - 3 * sd), x]
        ref = model.atom_at_zero + sum(integrate.quad(model.pdf, a, b, epsabs=1e-14, limit=400)[0]
                                       for a, b in zip(pieces[:-1], pieces[1:]) if b > a)
        assert float(model.cdf(x)) == pytest.approx(ref, abs=1e-9)


@pytest.mark.parametrize("model", CASES, ids=IDS)
def test_laplace_arrays_large_and_complex_s(model):
    tau = model.mean
    s = np.array([0.0, 1e-3, 1e3, 1e8]) / tau
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no overflow or invalid-value warnings
        real = model.laplace(s)
        cplx = model.laplace(s + 1j * s[::-1])
        imag = model.laplace(1j * s)
    assert real.shape == (4,) and not np.iscomplexobj(real)
    assert np.iscomplexobj(cplx) and np.all(np.isfinite(cplx)) and np.all(np.isfinite(imag))
    assert real[0] == pytest.approx(1.0, abs=1e-12)
    assert np.all(np.diff(real) <= 0) and np.all(np.abs(cplx) <= 1 + 1e-12)
    assert abs(real[-1]) < 1e-3 + model.atom_at_zero
    # the transform of a real density is real on the real axis and conjugate-symmetric
    np.testing.assert_allclose(model.laplace(np.conj(cplx * 0 + s + 0.5j / tau)),
                               np.conj(model.laplace(s + 0.5j / tau)), rtol=1e-12, atol=1e-300)


@pytest.mark.parametrize("model", CASES, ids=IDS)
def test_transform_analytic_right_of_stated_singularity(model):
    edge = model.analytic_for_re_s_greater_than
    assert edge < 0
    s = 0.5 * edge if math.isfinite(edge) else -1.0
    value = model.laplace(s)  # may overflow to inf for Pe = 1e4 (true value > 1e308)
    assert not np.isnan(value) and value > 1.0


@pytest.mark.parametrize("pe", [0.01, 1.0, 30.0, 300.0])
def test_closed_axial_dispersion_first_pole_is_the_stated_edge(pe):
    m = rtd.AxialDispersion(1.0, pe)
    edge = m.analytic_for_re_s_greater_than
    assert abs(m.laplace(edge * (1 - 1e-9))) > 1e6 * abs(m.laplace(0.5 * edge))


def test_tis_branch_point_and_nonnegative_density():
    m = rtd.TanksInSeries(2.0, 2.5)
    assert m.analytic_for_re_s_greater_than == -1.25
    assert np.isnan(m.laplace(-2.0))  # left of the branch point, real n: no real value
    assert rtd.TanksInSeries(2.0, 3).laplace(-2.0) == pytest.approx((1 - 2.0 * 2 / 3) ** -3)


def test_plug_flow():
    m = rtd.PlugFlow(1.5)
    np.testing.assert_array_equal(m.cdf([1.0, 1.5, 2.0]), [0, 1, 1])
    assert m.laplace(2.0) == pytest.approx(math.exp(-3.0))
    assert m.laplace(1e8) == 0.0 and m.laplace(1e8 + 1e8j) == 0.0
    assert abs(m.laplace(1e8j)) == pytest.approx(1.0)
    assert (m.mean, m.variance) == (1.5, 0.0)


def test_moments_from_transform_agree():
    for m in CASES[:8]:
        mean, var = m.moments_from_transform()
        assert mean == pytest.approx(m.mean, rel=1e-6)
        assert var == pytest.approx(m.variance, rel=1e-4)


# ---------------------------------------------------------------------------- limits
def test_tanks_in_series_large_n_approaches_plug_flow():
    t = np.array([0.9, 0.97, 1.03, 1.1])
    errs = [np.max(np.abs(rtd.TanksInSeries(1.0, n).cdf(t) - [0, 0, 1, 1]))
            for n in (1e2, 1e3, 1e4, 1e5)]
    assert np.all(np.diff(errs) < 0) and errs[-1] < 1e-15
    s = np.array([0.5, 2.0, 5.0 + 3j])
    np.testing.assert_allclose(rtd.TanksInSeries(1.0, 1e7).laplace(s), np.exp(-s), rtol=1e-5)


def test_axial_dispersion_large_pe_approaches_plug_flow():
    t = np.array([0.8, 0.9, 1.1, 1.2])  # 7 standard deviations and more from theta = 1
    for bc in ("closed", "open"):
        m = rtd.AxialDispersion(1.0, 1e4, bc)
        np.testing.assert_allclose(m.cdf(t), [0, 0, 1, 1], atol=1e-6)
        s = np.array([0.5, 2.0, 5.0 + 3j])
        np.testing.assert_allclose(rtd.AxialDispersion(1.0, 1e8, bc).laplace(s), np.exp(-s),
                                   rtol=1e-6)
        # near theta = 1 the density is the Gaussian of variance 2/Pe
        x = np.linspace(0.97, 1.03, 7)
        gauss = np.exp(-(x - 1) ** 2 / (2 * 2e-4)) / math.sqrt(2 * math.pi * 2e-4)
        np.testing.assert_allclose(m.pdf(x), gauss, rtol=0.03, atol=0.2)


def test_closed_axial_dispersion_small_pe_approaches_perfect_mixing():
    t = np.array([0.05, 0.5, 1.0, 3.0, 8.0])
    errs = [np.max(np.abs(rtd.AxialDispersion(1.0, pe).pdf(t) - np.exp(-t)))
            for pe in (1e-1, 1e-2)]
    assert errs[0] < 0.05 and errs[1] < 0.01 and errs[1] < errs[0] / 5
    s = np.array([0.3, 4.0 + 2j])
    np.testing.assert_allclose(rtd.AxialDispersion(1.0, 1e-8).laplace(s), 1 / (1 + s), rtol=1e-7)


def test_one_cell_is_perfect_mixing():
    t = np.linspace(0, 10, 11)
    pm = rtd.PerfectMixing(2.0)
    for cell in (rtd.RecirculatingCells(2.0, 1, r=3.0), pm.network(),
                 rtd.TanksInSeries(2.0, 1).network()):
        np.testing.assert_allclose(cell.pdf(t), pm.pdf(t), rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(cell.laplace([0.5, 1j]), pm.laplace([0.5, 1j]), rtol=1e-13)


def test_series_of_k_perfect_mixers_is_tanks_in_series():
    t = np.linspace(0.01, 12, 40)
    for k in (1, 2, 3, 5):
        series = rtd.Series(*[rtd.PerfectMixing(2.0 / k)] * k)
        tis = rtd.TanksInSeries(2.0, k)
        np.testing.assert_allclose(series.pdf(t), tis.pdf(t), rtol=1e-10, atol=1e-14)
        np.testing.assert_allclose(series.cdf(t), tis.cdf(t), rtol=1e-10, atol=1e-14)
        np.testing.assert_allclose(series.laplace([0.7, 2 + 5j]), tis.laplace([0.7, 2 + 5j]),
                                   rtol=1e-13)


# ---------------------------------------------------------------------------- checks
@pytest.mark.parametrize("make, name", [
    (lambda: rtd.PerfectMixing(0.0), "tau"),
    (lambda: rtd.PlugFlow(-1.0), "tau"),
    (lambda: rtd.TanksInSeries(1.0, 0.5), "n"),
    (lambda: rtd.TanksInSeries(float("nan"), 2), "tau"),
    (lambda: rtd.AxialDispersion(1.0, 0.0), "pe"),
    (lambda: rtd.AxialDispersion(1.0, 5.0, bc="dirichlet"), "bc"),
    (lambda: rtd.RecirculatingCells(1.0, 2.5), "n"),
    (lambda: rtd.RecirculatingCells(1.0, 2, r=-1), "r"),
    (lambda: rtd.RecirculatingCells(1.0, 2, dead=1.0), "dead"),
    (lambda: rtd.RecirculatingCells(1.0, 2, bypass=1.5), "bypass"),
    (lambda: rtd.Parallel(rtd.PerfectMixing(1.0), weights=(0.5,)), "weights"),
])
def test_invalid_parameters_raise_named_errors(make, name):
    with pytest.raises(rtd.ParameterError, match=name) as err:
        make()
    assert isinstance(err.value, ValueError) and isinstance(err.value, rtd.RTDError)


def test_models_are_frozen_with_readable_repr():
    m = rtd.TanksInSeries(tau=2.0, n=3)
    assert repr(m) == "TanksInSeries(tau=2.0, n=3.0)"
    assert repr(rtd.AxialDispersion(1.0, 5)) == "AxialDispersion(tau=1.0, pe=5.0, bc='closed')"
    with pytest.raises(AttributeError):
        m.tau = 3.0
    assert m.params == {"tau": 2.0, "n": 3.0}
    assert m.replace(n=4).n == 4.0
