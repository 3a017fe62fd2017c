"""Benchmark suite ``scaleup``: lab fit -> closed-circuit plant prediction with bands.

Case: eq. 5 rates and eq. 6 breakage (5 parameters) with a covariance from a local
eq. 9 fit to synthetic batch data (3 times x 12 sieves, noise sd 0.004); plant a
4 m x 6 m ball mill (Austin power, Herbst-Fuerstenau scaling, 3 tanks in series) closed
by a Plitt cyclone (d50c 200 um, m 2, bypass 0.25), 100 t/h, 37-class grid; quantities
product PSD, P80, and the throughput and specific energy at a target P80 of 150 um
(a root through the whole circuit per evaluation). Budgets: Monte Carlo
band from 1,000 draws < 5 s, delta-method band < 0.5 s; ``ratio_vs_budget`` = runtime /
budget (< 1 meets it). The point prediction, timed in the same process, is the baseline.

A last row times the bands of ``millflow scaleup`` (point, delta method and a 400-draw Monte
Carlo, target P80) on the plant flowsheet (:mod:`millflow.scaleup.study`: population solves,
vectorised roots) against the earlier path, kept here only as the baseline
(:class:`LegacyCircuit`: a dense transfer matrix per mill flow, ``np.linalg.solve`` of
I - C T, Brent's method member by member, Austin's upper-edge S and b), interleaved medians
in one process: ``ratio_vs_baseline`` = new / earlier (< 1 is faster).
"""
from __future__ import annotations

import math
import statistics
import time

import numpy as np

# the synthetic lab fit lives in millflow.synthetic (the tests use it too); kept here by its old name
from millflow.synthetic import synthetic_lab_fit

DESCRIPTION = "closed-circuit scale-up with bands: delta method, 1,000-draw Monte Carlo (budgets), vs the earlier path"

TRUTH = {"ln_A0": math.log(1 / 240), "alpha": 1.0, "phi": 0.4, "gamma": 0.8, "beta": 3.5}


def make_case():
    """(ScaleUp, target P80 [m]) of the benchmark case."""
    from millflow.grid import SizeGrid
    from millflow.scaleup import Circuit, MillDesign, ScaleUp

    grid = SizeGrid.between(4e-3, 1e-5, 2 ** 0.25)
    fitted, _ = synthetic_lab_fit(TRUTH, grid, 0.004, np.random.default_rng(0), "bench")
    lab = MillDesign(0.2, 0.2, 0.35, 0.8, 25.0, power_model="hogg_fuerstenau", name="lab")
    plant = MillDesign(4.0, 6.0, 0.35, 0.75, 50.0, name="plant")
    feed = np.zeros(fitted.x.size)
    feed[:4] = 0.25
    circuit = Circuit(plant, "tis", {"n": 3}, {"curve": "plitt", "d50c": 200e-6, "m": 2.0, "bypass": 0.25})
    return ScaleUp(fitted, lab, {}, circuit, feed, 100.0), 150e-6


def run(quick: bool = False) -> list[dict]:
    import warnings

    from millflow.scaleup import predict_plant

    import xarray  # noqa: F401  (imported before timing: its first import is not the bands' cost)

    su, target = make_case()
    t = time.perf_counter()
    su.operate(su.fit.theta)
    su.throughput_for_p80(su.fit.theta, target)
    base = time.perf_counter() - t
    rows = []
    with warnings.catch_warnings():  # the synthetic case's energy-range note is not the bench's subject
        warnings.simplefilter("ignore", UserWarning)
        for method, budget, n in (("delta", 0.5, 0), ("mc", 5.0, 200 if quick else 1000)):
            t = time.perf_counter()
            res = predict_plant(su, target, methods=(method,), n_draws=max(n, 10))
            rt = time.perf_counter() - t
            b = res.summary["bands"]
            rows.append({"case": "closed_circuit_target_p80", "method": method + (f"({n} draws)" if n else ""),
                         "runtime_s": rt, "budget_s": budget, "ratio_vs_budget": rt / budget,
                         "ratio_vs_point": rt / base, "point_s": base,
                         "p80_band_um": [b["p80_um"][method]["lo"], b["p80_um"][method]["hi"]],
                         "throughput_band_tph": [b["throughput_tph"][method]["lo"],
                                                 b["throughput_tph"][method]["hi"]]})
        rows.append(before_after(su, target, draws=100 if quick else 400, reps=1 if quick else 3))
    return rows


def before_after(su, target: float, draws: int = 400, reps: int = 3) -> dict:
    """Bands of the example command (point, delta, Monte Carlo) on the plant flowsheet against
    :class:`LegacyCircuit`, interleaved medians of ``reps`` (see the module docstring)."""
    import dataclasses

    from millflow.scaleup import predict_plant

    new_t, old_t = [], []
    new = old = None
    for _ in range(reps):
        fresh = dataclasses.replace(su)  # no cached roots or flowsheets between repetitions
        t = time.perf_counter()
        new = predict_plant(fresh, target, methods=("delta", "mc"), n_draws=draws).summary
        new_t.append(time.perf_counter() - t)
        t = time.perf_counter()
        old = legacy_bands(su, target, draws)
        old_t.append(time.perf_counter() - t)
    tn, to = statistics.median(new_t), statistics.median(old_t)
    return {"case": "scaleup bands (point, delta, Monte Carlo)", "method": "flowsheet vs earlier circuit",
            "runtime_s": tn, "runtime_baseline_s": to, "ratio_vs_baseline": tn / to, "draws": draws,
            "throughput_tph": new["throughput_tph"], "throughput_earlier_tph": old["throughput_tph"]}


class LegacyCircuit:
    """The earlier closed-circuit solve of scale-up, kept only as this bench's baseline.

    At mill flow F_m: T = (I + tau/n A)^-n (one triangular solve and n - 1 products),
    m_hat = (I - C T)^-1 f by ``np.linalg.solve``, fresh feed F_m / sum(m_hat); Brent's method
    on ln F_m for a fresh feed or a target P80, member by member.
    """

    def __init__(self, holdup_kg: float, n: int, c):
        self.H, self.n, self.c = holdup_kg, n, c

    def at_mill_flow(self, S, b, feed, F_m):
        from scipy.linalg import solve_triangular

        tau = self.H / F_m
        M = (np.eye(S.size) - b) * (tau / self.n * S)[None, :]
        M[np.diag_indices_from(M)] += 1.0
        T = Ti = solve_triangular(M, np.eye(S.size), lower=True, check_finite=False)
        for _ in range(self.n - 1):
            T = Ti @ T
        m = np.linalg.solve(np.eye(feed.size) - self.c[:, None] * T, feed)
        s = m.sum()
        return (1 - self.c) * (T @ m), F_m / s

    def root(self, g, u0):
        from scipy.optimize import brentq

        a, b = u0 - 0.05, u0 + 0.05
        while g(a) > 0:
            a -= 0.2
        while g(b) < 0:
            b += 0.2
        return brentq(g, a, b, xtol=1e-13, rtol=4 * np.finfo(float).eps)


def legacy_bands(su, target: float, draws: int) -> dict:
    """Point, delta-method and Monte Carlo evaluations through :class:`LegacyCircuit` (Austin's
    upper-edge S and b, as the earlier scale-up used): what the earlier command computed."""
    from millflow.psd import percentile_size

    fit, f = su.fit, su.factors()
    x = su.x
    circ = LegacyCircuit(f["plant_holdup_kg"], int(su.circuit.transport_params["n"]), su.circuit.partition(x))
    F = su.feed_tph / 3.6

    def g(theta, u_op, u_t):
        S = fit.rates(theta, x, su.lab_process, f["A"], f["mu"])
        b = fit.frac_b(theta, x)
        u = circ.root(lambda v: math.log(circ.at_mill_flow(S, b, su.feed, math.exp(v))[1] / F), u_op)
        p80 = percentile_size(x, circ.at_mill_flow(S, b, su.feed, math.exp(u))[0], 80.0, validate=False)

        def h(v):
            prod = circ.at_mill_flow(S, b, su.feed, math.exp(v))[0]
            return math.log(percentile_size(x, prod / prod.sum(), 80.0, validate=False) / target)
        ut = circ.root(h, u_t)
        return p80, circ.at_mill_flow(S, b, su.feed, math.exp(ut))[1] * 3.6, u, ut

    p80, q, u_op, u_t = g(fit.theta, math.log(3 * F), math.log(3 * F))
    v0 = fit.theta[fit.index]
    se = np.sqrt(np.diag(fit.cov))
    for k in range(v0.size):  # the delta method's central differences
        for sgn in (1, -1):
            e = np.zeros_like(v0)
            e[k] = sgn * 1e-3 * se[k]
            g(fit.full(v0 + e), u_op, u_t)
    w, V = np.linalg.eigh(fit.cov)
    L = V * np.sqrt(np.clip(w, 0.0, None))
    z = v0 + np.random.default_rng(0).standard_normal((draws, v0.size)) @ L.T
    for v in z:
        g(fit.full(v), u_op, u_t)
    return {"p80_um": p80 * 1e6, "throughput_tph": q}


def format_table(rows) -> str:
    lines = []
    for r in rows:
        if "ratio_vs_baseline" in r:
            lines.append(f"{r['case']}: {r['runtime_s']:.3f} s on the plant flowsheet, {r['runtime_baseline_s']:.3f} s "
                         f"on the earlier circuit path ({r['draws']} draws; interleaved medians): ratio "
                         f"{r['ratio_vs_baseline']:.2f}")
            continue
        lines.append(f"{r['case']:<28} {r['method']:<18} {r['runtime_s']:7.3f} s  ({r['ratio_vs_budget']:.2f} of the "
                     f"{r['budget_s']:g} s budget; {r['ratio_vs_point']:.0f}x the point prediction)  P80 band "
                     f"[{r['p80_band_um'][0]:.1f}, {r['p80_band_um'][1]:.1f}] um")
    return "\n".join(lines)
