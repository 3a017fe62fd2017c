"""Segregated flow's hold-up G(A) f, G(s) = (1 - E_hat(s))/s, against a 40-digit reference on
every rtd model, over tau and Pe: the reported estimate bounds the actual error.

G's plain quotient cancels for |s| tau << 1 (relative error eps/(s tau)); its two-term
Taylor branch below s tau = 1e-5 erred by (s tau)^2: hold-up errors of 1e-10 tau against
an estimate of 4e-15. Every rtd model now evaluates G in closed form."""
import numpy as np
import pytest

import rtd
from millflow import steady_mill
from millflow.breakage import b_from_B, normalized_B

mp = pytest.importorskip("mpmath")


def _mp_laplace(model, s):
    """E_hat(s) of ``model`` in mpmath (s an mpf)."""
    if isinstance(model, rtd.PerfectMixing):
        return 1 / (1 + s * model.tau)
    if isinstance(model, rtd.TanksInSeries):
        return (1 + s * mp.mpf(model.tau) / mp.mpf(model.n)) ** (-mp.mpf(model.n))
    if isinstance(model, rtd.AxialDispersion):
        p, pe = s * mp.mpf(model.tau), mp.mpf(model.pe)
        a, q = mp.sqrt(1 + 4 * p / pe), pe / 2
        if model.bc == "open":
            return mp.exp(q * (1 - a)) / a
        return 4 * a * mp.exp(q) / ((1 + a) ** 2 * mp.exp(a * q) - (1 - a) ** 2 * mp.exp(-a * q))
    if isinstance(model, rtd.Series):
        return mp.fprod(_mp_laplace(p, s) for p in model.parts)
    if isinstance(model, rtd.Parallel):
        return mp.fsum(mp.mpf(w) * _mp_laplace(p, s) for w, p in zip(model.weights, model.parts))
    net = model.network()  # cells: b + (1 - b) w^T (s I - A)^-1 u
    A = net.system_matrix()
    n = net.n
    M = mp.matrix(n, n)
    for i in range(n):
        for j in range(n):
            M[i, j] = (s if i == j else 0) - mp.mpf(A[i, j])
    x = mp.lu_solve(M, mp.matrix([mp.mpf(v) for v in net.inlet]))
    w = net.outlet / net.volumes
    return mp.mpf(net.bypass) + (1 - mp.mpf(net.bypass)) * mp.fsum(mp.mpf(w[k]) * x[k] for k in range(n))


def _mp_survival(model, s):
    """G(s) in mpmath. Compositions and networks by their structure (sum_k w_k G_k; the
    tracer still inside the cells), because the float weights 0.3 + 0.7 and a float
    network's E_hat(0) differ from 1 by ~1e-17 in exact arithmetic, which (1 - E_hat)/s
    would blow up at s = 1e-15."""
    if isinstance(model, rtd.Parallel):
        return mp.fsum(mp.mpf(w) * _mp_survival(p, s) for w, p in zip(model.weights, model.parts))
    if isinstance(model, rtd.Series):
        out, before = mp.mpf(0), mp.mpf(1)
        for p in model.parts:
            out += _mp_survival(p, s) * before
            before *= _mp_laplace(p, s)
        return out
    if isinstance(model, rtd.RecirculatingCells):
        net = model.network()
        A = net.system_matrix()
        M = mp.matrix(net.n, net.n)
        for i in range(net.n):
            for j in range(net.n):
                M[i, j] = (s if i == j else 0) - mp.mpf(A[i, j])
        x = mp.lu_solve(M, mp.matrix([mp.mpf(v) for v in net.inlet]))
        return (1 - mp.mpf(net.bypass)) * mp.fsum(x)
    return (1 - _mp_laplace(model, s)) / s if s != 0 else mp.mpf(model.mean)


def _mp_segregated(S, b, f, model):
    """Product E_hat(A) f and hold-up G(A) f in 40 digits through the eigenvectors of the
    lower-triangular A = (I - b) diag(S) (distinct rates: x_j = sum_l b_jl S_l x_l / (S_j - S_k))."""
    n = S.size
    with mp.workdps(40):
        Sm = [mp.mpf(v) for v in S]
        X = mp.zeros(n, n)
        for k in range(n):
            X[k, k] = 1
            for j in range(k + 1, n):
                X[j, k] = mp.fsum(mp.mpf(b[j, l]) * Sm[l] * X[l, k] for l in range(k, j)) / (Sm[j] - Sm[k])
        c = mp.lu_solve(X, mp.matrix([mp.mpf(v) for v in f]))
        E = [_mp_laplace(model, s) for s in Sm]
        G = [_mp_survival(model, s) for s in Sm]
        p = X * mp.matrix([E[k] * c[k] for k in range(n)])
        h = X * mp.matrix([G[k] * c[k] for k in range(n)])
        return np.array([float(v) for v in p]), np.array([float(v) for v in h])


def _mill(tau):
    x = 2.0 ** (-np.arange(8) / 2)
    b = b_from_B(normalized_B(x, 0.4, 0.8, 3.0))
    # rates across the branches of G: s tau = 2, 0.3, 1e-3, 1.01e-5, 0.99e-5 (the old Taylor
    # branch's edge), 1e-9, 1e-13 and the sink
    S = np.array([2.0, 0.3, 1e-3, 1.01e-5, 0.99e-5, 1e-9, 1e-13, 0.0]) / tau
    return S, b, np.linspace(1.0, 0.2, 8)


MODELS = {
    "perfect_mixing": lambda tau: rtd.PerfectMixing(tau),
    "tanks_2.5": lambda tau: rtd.TanksInSeries(tau, 2.5),
    "tanks_3": lambda tau: rtd.TanksInSeries(tau, 3),
    "closed_pe_1e-20": lambda tau: rtd.AxialDispersion(tau, 1e-20),
    "closed_pe_1e-3": lambda tau: rtd.AxialDispersion(tau, 1e-3),
    "closed_pe_3": lambda tau: rtd.AxialDispersion(tau, 3.0),
    "closed_pe_1e3": lambda tau: rtd.AxialDispersion(tau, 1e3),
    "open_pe_0.5": lambda tau: rtd.AxialDispersion(tau, 0.5, bc="open"),
    "open_pe_1e3": lambda tau: rtd.AxialDispersion(tau, 1e3, bc="open"),
    "recirculating": lambda tau: rtd.RecirculatingCells(tau, 3, r=2.0, dead=0.1, bypass=0.05),
    "series": lambda tau: rtd.Series(rtd.PerfectMixing(0.3 * tau), rtd.TanksInSeries(0.7 * tau, 2.5)),
    "parallel": lambda tau: rtd.Parallel(rtd.PerfectMixing(tau), rtd.AxialDispersion(tau, 5.0), weights=(0.3, 0.7)),
}


@pytest.mark.parametrize("tau", [5.0, 100.0, 600.0])
@pytest.mark.parametrize("name", sorted(MODELS))
def test_segregated_hold_up_meets_a_40_digit_reference(name, tau):
    model = MODELS[name](tau)
    S, b, f = _mill(tau)
    ds = steady_mill(S, b, f, model, method="segregated")
    p_ref, h_ref = _mp_segregated(S, b, f, model)
    est = ds.attrs["error_estimate"]
    # the estimate is stated for the product and for the hold-up in units of the mean
    # residence time (docs/reliability.md)
    assert np.abs(ds["product"].values - p_ref).max() <= est
    assert np.abs(ds["holdup"].values - h_ref).max() <= est * model.mean
    assert est < 1e-12  # and it is a useful number, not a blanket bound


def test_generic_survival_transform_reports_its_cancellation():
    # a model known only by laplace and mean: G is the plain quotient, and the estimate
    # grows as eps / (s tau) instead of hiding it
    class Plain:
        def __init__(self, tau):
            self.tau, self.mean = tau, tau

        def laplace(self, s):
            return 1.0 / (1.0 + np.asarray(s) * self.tau)

    S, b, f = _mill(100.0)
    from millflow.errors import AccuracyWarning

    with pytest.warns(AccuracyWarning):
        ds = steady_mill(S, b, f, Plain(100.0), on_inaccuracy="warn")
    p_ref, h_ref = _mp_segregated(S, b, f, rtd.PerfectMixing(100.0))
    assert np.abs(ds["holdup"].values - h_ref).max() <= ds.attrs["error_estimate"] * 100.0
    assert ds.attrs["error_estimate"] > 1e-6  # eps / 1e-13: the cancellation is reported
