"""Fitting: exact recovery, eq. 9 statistics, interval coverage, inlet, step, errors."""
import math

import numpy as np
import pytest
from scipy import stats

import rtd

T = np.linspace(0.1, 6.0, 60)


@pytest.mark.parametrize("name, truth, fixed", [
    ("cstr", rtd.PerfectMixing(1.3), {}),
    ("tis", rtd.TanksInSeries(2.0, 3.4), {}),
    ("ad-closed", rtd.AxialDispersion(2.0, 7.0), {}),
    ("ad-closed", rtd.AxialDispersion(1.0, 400.0), {}),
    ("ad-open", rtd.AxialDispersion(1.5, 12.0, "open"), {}),
    ("cells", rtd.RecirculatingCells(2.0, 4, r=0.8), {"n": 4}),
])
def test_noise_free_curves_give_the_generating_parameters(name, truth, fixed):
    t = np.linspace(0.02, 6.0, 300)
    res = rtd.fit(name, t, 2.5 * truth.pdf(t), **fixed)
    for key in res.names:
        assert getattr(res.model, key) == pytest.approx(getattr(truth, key), rel=1e-6), key
    assert res.scale == pytest.approx(2.5, rel=1e-6) and res.r2 == pytest.approx(1.0, abs=1e-10)


def test_statistics_follow_eq_9():
    rng = np.random.default_rng(5)
    truth = rtd.TanksInSeries(2.0, 3.0)
    c = truth.pdf(T) + 0.01 * rng.standard_normal(T.size)
    res = rtd.fit("tis", T, c)
    n, p = T.size, 3  # tau, n and the scale
    np.testing.assert_allclose(res.residuals, res.fitted - c)
    assert res.ssr == pytest.approx(np.sum(res.residuals**2))
    assert res.ser == pytest.approx(math.sqrt(res.ssr / (n - p)))
    assert res.aic == pytest.approx(n * math.log(res.ssr / n) + 2 * p)
    assert res.bic == pytest.approx(n * math.log(res.ssr / n) + p * math.log(n))
    # C = SER^2 (J^T J)^-1 with an independent forward-difference Jacobian
    x = np.array([res.model.tau, res.model.n, res.scale])
    f0 = x[2] * rtd.TanksInSeries(x[0], x[1]).pdf(T)
    jac = []
    for i in range(3):
        xp = x.copy()
        xp[i] *= 1 + 1e-7
        jac.append((xp[2] * rtd.TanksInSeries(xp[0], xp[1]).pdf(T) - f0) / (x[i] * 1e-7))
    jac = np.column_stack(jac)
    cov = res.ser**2 * np.linalg.inv(jac.T @ jac)
    np.testing.assert_allclose(res.se, np.sqrt(np.diag(cov))[:2], rtol=1e-4)
    assert res.correlation[0, 1] == pytest.approx(cov[0, 1] / math.sqrt(cov[0, 0] * cov[1, 1]),
                                                  rel=1e-3)
    lo, hi = res.interval("tau")
    half = stats.t.ppf(0.975, n - p) * res.se[0]
    assert (lo, hi) == pytest.approx((res.model.tau - half, res.model.tau + half))


def coverage(model, names, repeats=200, noise=0.02):
    """Share of seeded repeats whose 95 % interval covers the truth, per parameter."""
    clean = model.pdf(T)
    hits = dict.fromkeys(names, 0)
    kwargs = {"bc": model.bc} if isinstance(model, rtd.AxialDispersion) else {}
    for seed in range(repeats):
        rng = np.random.default_rng(seed)
        c = clean + noise * clean.max() * rng.standard_normal(T.size)
        res = rtd.fit(type(model), T, c, **kwargs)
        for key in names:
            lo, hi = res.interval(key)
            hits[key] += lo <= getattr(model, key) <= hi
    return {k: v / repeats for k, v in hits.items()}


@pytest.mark.slow
@pytest.mark.parametrize("model, names", [
    (rtd.TanksInSeries(2.0, 3.0), ("tau", "n")),
    (rtd.AxialDispersion(2.0, 10.0), ("tau", "pe")),
])
def test_95_percent_intervals_cover_truth(model, names):
    # 2 % noise (sd = 2 % of the peak), 60 points, 200 seeds 0..199: the share must lie
    # in [0.90, 0.98] (binomial sd of the share at 0.95 is 0.015)
    share = coverage(model, names)
    for key in names:
        assert 0.90 <= share[key] <= 0.98, (key, share)


def test_fit_with_measured_inlet_curve():
    t = np.linspace(0, 12, 241)
    inlet = rtd.TanksInSeries(0.4, 3).pdf(t)
    truth = rtd.TanksInSeries(2.0, 2.5)
    c = 1.7 * rtd.convolve_inlet(truth.cdf, t, inlet)
    res = rtd.fit("tis", t, c, inlet=inlet)
    assert res.model.tau == pytest.approx(2.0, rel=1e-6) and res.model.n == pytest.approx(2.5, rel=1e-6)
    # without the inlet the same data would put the injection's spread into the vessel
    naive = rtd.fit("tis", t, c)
    assert naive.model.tau > 2.2 and naive.model.n > 2.5
    shifted = np.interp(t - 3.0, t, inlet, left=0.0)  # the inlet curve delayed by 3
    plug = rtd.fit("plug", t, shifted, inlet=inlet)
    assert plug.model.tau == pytest.approx(3.0, rel=1e-3)


def test_fit_step_response():
    t = np.linspace(0, 15, 151)
    truth = rtd.AxialDispersion(3.0, 20.0)
    c = 0.8 * truth.cdf(t) + 0.005 * np.random.default_rng(1).standard_normal(t.size)
    res = rtd.fit("ad-closed", t, c, kind="step")
    assert res.model.tau == pytest.approx(3.0, abs=4 * res.se[0])
    assert res.model.pe == pytest.approx(20.0, abs=4 * res.se[1])


def test_compare_ranks_the_generating_model_first():
    rng = np.random.default_rng(3)
    c = rtd.TanksInSeries(2.0, 3.0).pdf(T) * (1 + 0.0) + 0.005 * rng.standard_normal(T.size)
    ranked = rtd.compare(["cstr", "tis", "ad-open", "plug"], T, c)
    assert isinstance(ranked[0].model, rtd.TanksInSeries)
    assert [r.aic for r in ranked] == sorted(r.aic for r in ranked)


def test_plug_flow_on_pulse_data_is_the_first_moment():
    c = rtd.TanksInSeries(2.0, 50).pdf(T)
    res = rtd.fit("plug", T, c)
    assert res.model.tau == pytest.approx(2.0, rel=1e-3)
    assert math.isnan(res.se[0]) and "moments" in res.notes[-1]
    assert res.to_dict()["params"]["tau"]["se"] is None


def test_cut_off_curve_uses_tail_and_says_so():
    t = np.linspace(0.1, 4.0, 40)
    res = rtd.fit("tis", t, rtd.TanksInSeries(2.0, 3.0).pdf(t))
    assert any("exponential tail" in n for n in res.notes)
    assert res.model.tau == pytest.approx(2.0, rel=1e-6)


def test_fit_errors():
    with pytest.raises(rtd.TracerError, match="3 data points for 3 parameters"):
        rtd.fit("tis", [1.0, 2.0, 3.0], [1.0, 2.0, 1.0])
    with pytest.raises(rtd.RTDError, match=r"expected one of perfect_mixing, plug_flow"):
        rtd.fit("gamma", T, rtd.PerfectMixing(1.0).pdf(T))
    with pytest.raises(rtd.RTDError, match="cannot fit"):
        rtd.fit("cells", T, rtd.PerfectMixing(1.0).pdf(T), vary=("tau", "n"))
    with pytest.raises(rtd.RTDError, match="cannot fit"):
        rtd.fit("tis", T, rtd.PerfectMixing(1.0).pdf(T), vary=("tau", "pe"))
    with pytest.raises(rtd.TracerError, match="row 3"):
        rtd.fit("tis", [0.0, 1.0, 0.5, 2.0], [0.0, 1.0, 0.5, 0.1])


def test_fit_accepts_class_instance_and_curve():
    c = rtd.TanksInSeries(2.0, 3.0).pdf(T)
    a = rtd.fit(rtd.TanksInSeries, T, c)
    b = rtd.fit(rtd.TanksInSeries(1.0, 1.0), rtd.TracerCurve(T, c))
    assert a.model.tau == pytest.approx(b.model.tau, rel=1e-8)
    cells = rtd.fit(rtd.RecirculatingCells(1.0, 5), T, c)  # n = 5 kept from the instance
    assert cells.model.n == 5 and cells.params["n"] == (5, None)


def test_bypass_needs_a_known_scale():
    t = np.linspace(0.05, 8, 200)
    truth = rtd.RecirculatingCells(2.0, 3, r=0.5, bypass=0.15)
    # with a free scale the missing area (bypass) trades off against A and tau: the data
    # are matched exactly by bypass = 0 and tau / (1 - bypass), with |correlation| ~ 1
    free = rtd.fit(rtd.RecirculatingCells(1.0, 3), t, 3.0 * truth.pdf(t), vary=("tau", "r", "bypass"))
    assert free.ssr < 1e-20 and free.model.tau == pytest.approx(2.0 / 0.85, rel=1e-6)
    assert abs(free.correlation[0, 2]) > 0.99 and abs(free.correlation[2, 3]) > 0.99
    # with the known tracer area the bypass is estimated
    known = rtd.fit(rtd.RecirculatingCells(1.0, 3), t, 3.0 * truth.pdf(t), scale=3.0,
                    vary=("tau", "r", "bypass"))
    assert known.model.bypass == pytest.approx(0.15, rel=1e-5)
    assert known.model.tau == pytest.approx(2.0, rel=1e-5) and known.n_params == 3
