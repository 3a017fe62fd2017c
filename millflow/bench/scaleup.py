"""Benchmark suite ``scaleup``: lab fit -> closed-circuit plant prediction with bands.

Case: eq. 5 rates and eq. 6 breakage (5 parameters) with a covariance from a local
eq. 9 fit to synthetic batch data (3 times x 12 sieves, noise sd 0.004); plant a
4 m x 6 m ball mill (Austin power, Herbst-Fuerstenau scaling, 3 tanks in series) closed
by a Plitt cyclone (d50c 200 um, m 2, bypass 0.25), 100 t/h, 37-class grid; quantities
product PSD, P80, and the throughput and specific energy at a target P80 of 150 um
(a root through the whole circuit per evaluation). Budgets: Monte Carlo
band from 1,000 draws < 5 s, delta-method band < 0.5 s; ``ratio_vs_budget`` = runtime /
budget (< 1 meets it). The point prediction, timed in the same process, is the baseline.
"""
from __future__ import annotations

import math
import time

import numpy as np

# the synthetic lab fit lives in millflow.synthetic (the tests use it too); kept here by its old name
from millflow.synthetic import synthetic_lab_fit

DESCRIPTION = "closed-circuit scale-up with bands: delta method and 1,000-draw Monte Carlo (budgets)"

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
    from millflow.scaleup import predict_plant

    su, target = make_case()
    t = time.perf_counter()
    su.operate(su.fit.theta)
    su.throughput_for_p80(su.fit.theta, target)
    base = time.perf_counter() - t
    rows = []
    for method, budget, n in (("delta", 0.5, 0), ("mc", 5.0, 200 if quick else 1000)):
        t = time.perf_counter()
        res = predict_plant(su, target, methods=(method,), n_draws=max(n, 10))
        rt = time.perf_counter() - t
        b = res.summary["bands"]
        rows.append({"case": "closed_circuit_target_p80", "method": method + (f"({n} draws)" if n else ""),
                     "runtime_s": rt, "budget_s": budget, "ratio_vs_budget": rt / budget,
                     "ratio_vs_point": rt / base, "point_s": base,
                     "p80_band_um": [b["p80_um"][method]["lo"], b["p80_um"][method]["hi"]],
                     "throughput_band_tph": [b["throughput_tph"][method]["lo"], b["throughput_tph"][method]["hi"]]})
    return rows


def format_table(rows) -> str:
    return "\n".join(f"{r['case']:<28} {r['method']:<18} {r['runtime_s']:7.3f} s  ({r['ratio_vs_budget']:.2f} of the "
                     f"{r['budget_s']:g} s budget; {r['ratio_vs_point']:.0f}x the point prediction)  P80 band "
                     f"[{r['p80_band_um'][0]:.1f}, {r['p80_band_um'][1]:.1f}] um" for r in rows)
