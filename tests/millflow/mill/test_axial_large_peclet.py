"""Axial dispersion with classification at Peclet numbers the finite volumes cannot resolve.

Above Pe d*/dispersion = 16384 (the cell Peclet number stays > 1 on the finest grid) the
mill is the plug-flow limit plus its 1/Pe terms, fitted from finite-volume solutions at
Pe 512..2048 (:func:`millflow.mill.axial.large_peclet_limit`). It used to be refused with
"error estimate 8.5e-6 above the tolerance 1e-8" at Pe = 1e5..1e100. The references here
are exact: segregated flow with rates S/d* where every class has the same Peclet number
(v = w = d*), and one breaking class in closed form (Wehner-Wilhelm; the open vessel's
flux-weighted density E_f = (1 + 1/theta) E / 2, transform e^(q (1 - a)) (1 + 1/a) / 2)."""
import math

import numpy as np
import pytest

import rtd
from millflow import steady_mill
from millflow.breakage import NormalizedBreakage, PowerLawRate
from millflow.errors import SolverError
from millflow.grid import SizeGrid

TAU = 600.0


def _mill(n=10, a=0.01):
    g = SizeGrid.geometric(top_m=2e-3, ratio=2**0.5, n=n)
    S = PowerLawRate(A=a, alpha=1.0, x0=1e-3)(g.x)
    S[-1] = 0.0
    b = NormalizedBreakage(0.5, 0.8, 3.0).b(g.x)
    d = np.where(g.x > 7e-4, 0.5, 1.0)
    return S, b, np.r_[1.0, np.zeros(n - 1)], d


@pytest.mark.parametrize("pe", [1e5, 1e6, 1e8, 1e100])
@pytest.mark.parametrize("bc", ["closed", "open"])
def test_one_peclet_number_for_all_classes_meets_segregated_flow(bc, pe):
    # v = w = d*: every transport time of class i is scaled by 1/d_i, so the mill is
    # segregated flow with rates S/d* (closed: Wehner-Wilhelm; open sampled: the open E)
    S, b, f, d = _mill()
    ds = steady_mill(S, b, f, rtd.AxialDispersion(TAU, pe, bc=bc), d=d, dispersion=d)
    ref = steady_mill(S / d, b, f, rtd.AxialDispersion(TAU, pe, bc=bc))
    est = ds.attrs["error_estimate"] + ref.attrs["error_estimate"]
    assert "plug-flow limit" in ds.attrs["limit"]
    assert np.abs(ds["product"].values - ref["product"].values).max() <= est
    assert np.abs(ds["holdup"].values - ref["holdup"].values / d).max() <= est * TAU
    assert ds.attrs["error_estimate"] < 1e-9


def _one_class_product(k, pe_1, kind):
    """Product of a class with breakage k = S tau / v at its own Peclet number (mpmath)."""
    mp = pytest.importorskip("mpmath")
    with mp.workdps(40):
        k, pe_1 = mp.mpf(k), mp.mpf(pe_1)
        q, a = pe_1 / 2, mp.sqrt(1 + 4 * mp.mpf(k) / pe_1)
        if kind == "closed":  # Wehner-Wilhelm, divided through by exp(a q)
            return float(4 * a * mp.exp(q * (1 - a)) / ((1 + a) ** 2 - (1 - a) ** 2 * mp.exp(-2 * a * q)))
        if kind == "sampled":
            return float(mp.exp(q * (1 - a)) / a)
        return float(mp.exp(q * (1 - a)) * (1 + 1 / a) / 2)  # flux


@pytest.mark.parametrize("bc, discharge", [("closed", None), ("open", "sampled"), ("open", "flux")])
def test_one_breaking_class_in_closed_form_at_pe_1e6(bc, discharge):
    # class 1 (d* = 0.5) breaks into the sink; closed default dispersion 1 (its own Peclet
    # number Pe d/1), open default dispersion d (Pe); class 1's hold-up is (f1 - p1)/S1
    S = np.array([0.004, 0.0])
    b = np.array([[0.0, 0.0], [1.0, 0.0]])
    f = np.array([1.0, 0.0])
    d = np.array([0.5, 1.0])
    pe = 1e6
    kw = {} if discharge is None else {"discharge": discharge}
    ds = steady_mill(S, b, f, rtd.AxialDispersion(TAU, pe, bc=bc), d=d, **kw)
    pe_1 = pe * 0.5 if bc == "closed" else pe
    p1 = _one_class_product(S[0] * TAU / 0.5, pe_1, "closed" if bc == "closed" else discharge)
    est = ds.attrs["error_estimate"]
    assert abs(float(ds["product"][0]) - p1) <= est
    assert abs(float(ds["product"][1]) - (1 - p1)) <= est
    assert abs(float(ds["holdup"][0]) - (1 - p1) / S[0]) <= est * TAU
    # and against the plug-flow answer: the difference is the O(1/Pe) term (k^2 - c k) e^-k / Pe_1
    # (ln E_hat = -k + (k^2 - c k)/Pe + O(Pe^-2): c = 0 closed, 2 sampled (1/a), 1 flux ((1 + 1/a)/2))
    plug = steady_mill(S, b, f, rtd.PlugFlow(TAU), d=d)
    k = S[0] * TAU / 0.5
    c = {None: 0.0, "sampled": 2.0, "flux": 1.0}[discharge]
    first = (k * k - c * k) * math.exp(-k) / pe_1
    diff = float(ds["product"][0] - plug["product"][0])
    assert diff == pytest.approx(first, rel=1e-4)  # the next term is O(k^3 / Pe) relative
    assert est < 1e-2 * first  # the 1/Pe term is resolved, not bounded away


def test_a_class_retained_by_classification_is_refused_with_the_reason():
    # d* = 1e-3 with dispersion 1: that class's own Peclet number is 1e3 and it breaks in a
    # dispersion layer at the feed end (deviation O(Pe^-1/2)); neither the grid nor the
    # plug-flow limit reaches 1e-8, and the refusal says why
    S, b, f, d = _mill()
    d = np.where(d < 1, 1e-3, 1.0)
    with pytest.raises(SolverError, match="plug-flow limit needs every class's Peclet number"):
        steady_mill(S, b, f, rtd.AxialDispersion(TAU, 1e6), d=d)


@pytest.mark.parametrize("pe", [8e3, 1e4, 2e4])
@pytest.mark.parametrize("bc", ["closed", "open"])
def test_between_the_grids_reach_and_the_large_peclet_range(bc, pe):
    # Pe below 16384 (the finite volumes' route) but too large for the grids to reach
    # their second-order range before the finest: where they stop above the tolerance the
    # large-Pe route (nodes at Pe 512..2048, x = 1/Pe between 0 and the first node) takes
    # over when its estimate is smaller. Exact reference as above (v = w = d*).
    S, b, f, d = _mill()
    d = np.where(d < 1.0, 0.3, 1.0)  # a strongly retained coarse class
    ds = steady_mill(S, b, f, rtd.AxialDispersion(TAU, pe, bc=bc), d=d, dispersion=d)
    ref = steady_mill(S / d, b, f, rtd.AxialDispersion(TAU, pe, bc=bc))
    err = float(np.abs(ds["product"].values - ref["product"].values).max())
    assert ds.attrs["error_estimate"] <= 1e-8  # the default tolerance met
    assert err <= ds.attrs["error_estimate"] + 1e-14  # the estimate bounds the actual error (rounding aside)
