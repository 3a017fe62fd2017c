"""Transient plug flow with classes at different speeds (millflow.mill.plug_fronts), through
transient_mill: first-order breakage against the solution along the characteristics by
quadrature, no breakage and one speed against the exact delays, non-linear kinetics against
their own steady solver at both ends, the mass balance, an independent splitting scheme with
exact shifts, and the reported estimate against a finer solve."""
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from scipy.integrate import quad, solve_ivp

import rtd
from millflow.mill import nonlinear as nl
from millflow.mill import transient_mill
from millflow.mill.plug_fronts import plug_fronts
from millflow.nonlinear import Aggregation, constant_kernel, kinetics
from tests.millflow.mill.nonlinear_scene import TAU, breakage_scene

FEED = np.array([1.0, 0.0, 0.0])


def _two_classes(v1, v2, S1, S2, tau, theta, z=1.0):
    """(c1, c2) at (z, theta) of a start-up from empty, class 1 -> 2 (all of it), along the
    characteristics: c1 = e^{-tau S1 z / v1} / v1 behind its front; c2 the integral of its
    source tau S1 c1 along its own characteristic, damped by e^{-tau S2 s} (adaptive quadrature
    split at the crossing of class 1's front)."""
    def c1(zp, thp):
        return np.exp(-tau * S1 * zp / v1) / v1 if thp >= zp / v1 else 0.0

    smax = min(z / v2, theta)
    cross = (theta - z / v1) / (1.0 - v2 / v1)
    points = [cross] if 0.0 < cross < smax else None
    c2 = quad(lambda s: tau * S1 * c1(z - v2 * s, theta - s) * np.exp(-tau * S2 * s), 0.0, smax, points=points,
              epsabs=1e-14, epsrel=1e-12, limit=200)[0]
    return np.array([c1(z, theta), c2])


@pytest.mark.parametrize("v", [(0.5, 1.0), (1.0, 0.4)])
def test_first_order_breakage_against_the_characteristics(v):
    S = np.array([0.08, 0.03, 0.0])  # 1 -> 2 -> 3 (the sink, at class 2's speed)
    b = np.eye(3, k=-1)
    tau = 10.0
    t = np.array([3.0, 7.0, 10.0, 13.0, 17.0, 21.0, 24.0, 26.0])
    ds = transient_mill(S, b, rtd.PlugFlow(tau), t, feed=FEED, d=np.array([*v, v[1]]))
    assert ds.attrs["method"] == "plug_flow_fronts"
    ref = np.array([np.array(v) * _two_classes(*v, *S[:2], tau, tk / tau) for tk in t])
    # quadrature to 1e-12 relative: the estimate alone must cover the difference
    assert np.abs(ds["product"].values[:, :2] - ref).max() <= ds.attrs["error_estimate"]
    for k in (1, 4):
        th = t[k] / tau
        kinks = [min(1.0, v[0] * th), min(1.0, v[1] * th)]
        ref_h = [tau * quad(lambda z: _two_classes(*v, *S[:2], tau, th, z)[i], 0.0, 1.0, points=kinks,
                            epsabs=1e-13, limit=200)[0] for i in (0, 1)]
        assert np.abs(ds["holdup"].values[k, :2] - ref_h).max() <= ds.attrs["holdup_error_estimate"] + 1e-9


@settings(max_examples=8, deadline=None)
@given(v=st.lists(st.floats(0.2, 1.5), min_size=3, max_size=3), f=st.lists(st.floats(0.1, 2.0), min_size=3,
                                                                               max_size=3))
def test_without_breakage_each_class_is_delayed_by_its_own_transit_time(v, f):
    v, f = np.array(v), np.array(f)
    if np.ptp(v) < 1e-3:
        v[0] += 0.1
    tau = 5.0
    transit = tau / v
    t = np.unique(np.concatenate([[0.0], 0.5 * transit, 0.999 * transit, transit, 1.001 * transit]))
    # not within rounding of another class's front (a jump: either side is right there)
    gap = np.abs(t[:, None] - transit[None, :])
    t = t[~np.any((gap > 0) & (gap < 1e-9 * t[:, None]), axis=1)]
    ds = transient_mill(np.zeros(3), np.eye(3, k=-1), rtd.PlugFlow(tau), t, feed=f, d=v)
    arrived = t[:, None] >= transit[None, :]
    # exact: a step delayed by tau / v_i; hold-up f_i min(t, tau / v_i). The method is exact
    # here up to its tolerances (rtol 1e-10 on hold-ups of order f tau / v).
    assert np.abs(ds["product"].values - np.where(arrived, f, 0.0)).max() <= max(ds.attrs["error_estimate"], 1e-12)
    hold = f[None, :] * np.minimum(t[:, None], transit[None, :])
    assert np.abs(ds["holdup"].values - hold).max() <= ds.attrs["holdup_error_estimate"] + 1e-9 * hold.max()


def test_one_speed_is_plug_flow_with_tau_over_v():
    grid, S, b, feed = breakage_scene(8)
    t = np.array([0.0, 0.5 * TAU, 1.999 * TAU, 2.0 * TAU, 3.0 * TAU])
    ds = transient_mill(S, b, rtd.PlugFlow(TAU), t, feed=feed, d=np.full(8, 0.5))
    ref = transient_mill(S, b, rtd.PlugFlow(2.0 * TAU), t, feed=feed)
    # the same exact formulas (batch grind for 2 tau, hold-up by ages): equal to round-off
    assert np.allclose(ds["product"].values, ref["product"].values, rtol=1e-12, atol=1e-15)
    assert np.allclose(ds["holdup"].values, ref["holdup"].values, rtol=1e-12, atol=1e-12)


def _nonlinear_scene(n=6, strength=1.0):
    grid, S, b, feed = breakage_scene(n)
    S = strength * S
    w = np.zeros((n, n))
    w[:, n // 2:] = 3.0
    kin = kinetics(S, b, w=w, lam=-1.0, aggregation=Aggregation(constant_kernel(0.02), grid.x[-1]), grid=grid)
    return kin, feed


D3 = np.array([0.25, 0.5, 0.5, 1.0, 1.0, 1.0])  # three speeds, commensurate for the shift scheme below


def test_nonlinear_ends_are_the_steady_states_and_mass_balances():
    kin, feed = _nonlinear_scene(strength=0.25)
    old = 0.5 * feed[::-1]
    t = np.array([0.0, 0.5, 1.2, 1.5, 1.5 + 1e-3, 2.6, 3.0, 4.0, 4.5]) * TAU
    ds = transient_mill(kin, None, rtd.PlugFlow(TAU), t, feed=feed, initial_feed=old, d=D3)
    assert ds.attrs["method"] == "plug_flow_fronts_nonlinear"
    new_ss, old_ss = nl.plug_flow(kin, feed, TAU, D3), nl.plug_flow(kin, old, TAU, D3)
    p, h = ds["product"].values, ds["holdup"].values
    # the steady solver (LSODA on the z-ODE, its own estimate) against the strip's edges
    for k, ss in ((0, old_ss), (-1, new_ss), (-2, new_ss)):
        assert np.abs(p[k] - ss.product).max() <= ds.attrs["error_estimate"] + ss.error_estimate
        assert np.abs(h[k] - ss.info["holdup"]).max() <= (ds.attrs["holdup_error_estimate"]
                                                                + TAU * ss.error_estimate)
    # no class has arrived before tau / v_max: the old product
    assert np.abs(p[1] - old_ss.product).max() <= ds.attrs["error_estimate"] + old_ss.error_estimate
    # d(hold-up)/dt = feed - product (overflow included) by a central difference at 1.5 tau
    # (O(dt^2) with dt = 1e-3 tau: measured 3e-7 of the feed), inside the sector
    dt = 1e-3 * TAU
    tc = np.array([1.5 * TAU - dt, 1.5 * TAU + dt, 1.5 * TAU])
    dc = transient_mill(kin, None, rtd.PlugFlow(TAU), tc, feed=feed, initial_feed=old, d=D3)
    total_h = dc["holdup"].values.sum(axis=1) + dc["overflow_holdup"].values
    out = dc["product"].values[2].sum() + float(dc["overflow"].values[2])
    assert abs((total_h[1] - total_h[0]) / (2 * dt) - (feed.sum() - out)) <= 1e-5 * feed.sum()


def _shift_reference(kin, feed, v, thetas, N):
    """The same mill by Lie splitting with exact shifts: nodes dz = 1 / N, steps dtheta = dz /
    min(v); class i moves v_i / min(v) nodes per step (integers here), then every node reacts
    for the step (DOP853, rtol 1e-11). First order in dz."""
    m = v.size
    dth = 1.0 / N / v.min()
    shift = np.rint(v / v.min()).astype(int)
    C = np.zeros((N + 1, m))
    out = {}
    for s in range(1, int(round(thetas.max() / dth)) + 1):
        for k in range(m):
            C[shift[k]:, k] = C[:-shift[k], k].copy()
            C[:shift[k], k] = feed[k] / v[k]
        sol = solve_ivp(lambda _t, y: TAU * kin.rate_many(y.reshape(-1, m)).ravel(), (0.0, dth), C.ravel(),
                        method="DOP853", rtol=1e-11, atol=1e-14)
        C = sol.y[:, -1].reshape(-1, m)
        for th in thetas:
            if int(round(th / dth)) == s:
                out[th] = v * C[-1]
    return np.array([out[th] for th in thetas])


def test_nonlinear_start_up_against_a_splitting_scheme_with_exact_shifts():
    kin, feed = _nonlinear_scene()
    v = np.array([0.5, 0.5, 0.5, 1.0, 1.0, 1.0, 1.0])  # two speeds: steps of dtheta = 2 dz, small enough
    thetas = np.array([0.6, 1.0, 1.3, 1.7, 1.95, 2.2])
    f = np.append(feed, 0.0)
    p, h, diff, info = plug_fronts(kin.rate_many, kin.jacobian_many, v, TAU, f, np.zeros(v.size), thetas * TAU)
    coarse, fine = (_shift_reference(kin, f, v, thetas, N) for N in (100, 200))
    assert np.abs(fine - p).max() < 0.6 * np.abs(coarse - p).max()  # the scheme converges to the strip
    # one Richardson step removes the first-order term; what is left (measured 1.8e-4 at N = 200,
    # 8e-5 at N = 400) is the scheme's, far above the strip's estimate
    assert np.abs(2 * fine - coarse - p).max() <= 1e-3 * f.sum()
    assert diff["product"] <= 1e-7 * f.sum()


def test_the_estimate_covers_the_error_against_a_finer_strip():
    kin, feed = _nonlinear_scene(strength=0.25)
    v = np.append(D3, 1.0)
    t = np.array([0.3, 1.1, 1.9, 2.7, 3.6]) * TAU
    f = np.append(feed, 0.0)
    old = np.append(0.3 * feed[::-1], 0.0)
    p, h, diff, _ = plug_fronts(kin.rate_many, kin.jacobian_many, v, TAU, f, old, t, tol=1e-4)
    pr, hr, dr, _ = plug_fronts(kin.rate_many, kin.jacobian_many, v, TAU, f, old, t, tol=1e-8, nodes=(14, 20),
                                rtol=1e-11)
    assert np.abs(p - pr).max() <= diff["product"]
    assert np.abs(h - hr).max() <= diff["holdup"]
    assert dr["product"] <= 1e-8 * f.sum()


# ---------------------------------------------------------------- slowing-down in the age, kappa(a)
S3 = np.array([0.08, 0.03, 0.0])
B3 = np.eye(3, k=-1)


def _hyperbolic(s=2.0, tau=10.0):
    return (lambda a: 1.0 / (1.0 + s * a / tau)), (lambda a: tau / s * np.log1p(s * a / tau))


@pytest.mark.parametrize("v", [(0.5, 1.0), (1.0, 0.4)])
def test_kappa_in_the_age_against_the_exit_ages_by_quadrature(v):
    """Class 1 leaves whole at tau / v1 (a delta), ground for theta(tau / v1); a fragment born
    at age a1 (at z = v1 a1 / tau) leaves at a = a1 + (1 - v1 a1 / tau) tau / v2, so class 2's
    product at t is the integral over exit ages up to t of S1 kappa(a1) e^{-S1 theta(a1)}
    e^{-S2 (theta(a) - theta(a1))} |da1/da|."""
    tau = 10.0
    kap, theta = _hyperbolic(tau=tau)
    kin = kinetics(S3, B3, kappa_t=kap)
    d = np.array([*v, v[1]])
    t = np.array([3.0, 7.0, 10.0, 13.0, 17.0, 21.0, 24.0, 26.0])
    ds = transient_mill(kin, None, rtd.PlugFlow(tau), t, feed=FEED, d=d)
    assert ds.attrs["method"] == "plug_flow_age_fronts"
    v1, v2 = v
    jac = 1.0 / abs(1.0 - v1 / v2)

    def exit_density(a):
        a1 = (a - tau / v2) / (1.0 - v1 / v2)
        if not 0.0 <= a1 <= tau / v1:
            return 0.0
        return S3[0] * kap(a1) * np.exp(-S3[0] * theta(a1) - S3[1] * (theta(a) - theta(a1))) * jac

    lo, hi = sorted((tau / v1, tau / v2))
    for k, tk in enumerate(t):
        p1 = np.exp(-S3[0] * theta(tau / v1)) if tk >= tau / v1 else 0.0
        p2 = quad(exit_density, lo, min(tk, hi), epsabs=1e-14, epsrel=1e-12)[0] if tk > lo else 0.0
        # quadrature to 1e-12: the estimate covers the difference
        assert abs(ds["product"].values[k, 0] - p1) <= ds.attrs["error_estimate"]
        assert abs(ds["product"].values[k, 1] - p2) <= ds.attrs["error_estimate"]


def test_kappa_one_in_the_age_is_the_first_order_fronts_and_the_ends_are_steady():
    grid, S, b, feed = breakage_scene(6)
    S = 0.25 * S  # tau S up to 7.5: a few pieces, a test of seconds
    d = D3
    old = 0.5 * feed[::-1]
    t = np.array([0.0, 0.5, 1.2, 1.5, 2.6, 3.0, 4.0, 4.5]) * TAU
    one = kinetics(S, b, kappa_t=lambda a: 1.0)
    ds = transient_mill(one, None, rtd.PlugFlow(TAU), t, feed=feed, initial_feed=old, d=d)
    lin = transient_mill(S, b, rtd.PlugFlow(TAU), t, feed=feed, initial_feed=old, d=d)
    # two formulations: an impulse with its deltas (age) against the step (first order)
    for var, est in (("product", "error_estimate"), ("holdup", "holdup_error_estimate")):
        assert np.abs(ds[var] - lin[var]).max() <= ds.attrs[est] + lin.attrs[est]
    kin = kinetics(S, b, kappa_t=_hyperbolic(tau=TAU)[0])
    ds = transient_mill(kin, None, rtd.PlugFlow(TAU), t, feed=feed, initial_feed=old, d=d)
    for k, f in ((0, old), (-1, feed)):  # the ends: the steady age-position balance (Romberg over cells)
        ss = nl.plug_flow(kin, f, TAU, d)
        assert np.abs(ds["product"].values[k] - ss.product).max() <= ds.attrs["error_estimate"] + ss.error_estimate
        assert np.abs(ds["holdup"].values[k] - ss.info["holdup"]).max() <= (ds.attrs["holdup_error_estimate"]
                                                                          + TAU * ss.error_estimate)
    # d(hold-up)/dt = feed - product inside the sector (central difference, O(dt^2): 1e-6 of the feed)
    dt = 1e-3 * TAU
    dc = transient_mill(kin, None, rtd.PlugFlow(TAU), np.array([1.5 * TAU - dt, 1.5 * TAU + dt, 1.5 * TAU]),
                        feed=feed, initial_feed=old, d=d)
    H = dc["holdup"].values.sum(axis=1)
    assert abs((H[1] - H[0]) / (2 * dt) - (feed.sum() - dc["product"].values[2].sum())) <= 1e-5 * feed.sum()
