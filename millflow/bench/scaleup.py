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

DESCRIPTION = "closed-circuit scale-up with bands: delta method and 1,000-draw Monte Carlo (budgets)"

TRUTH = {"ln_A0": math.log(1 / 240), "alpha": 1.0, "phi": 0.4, "gamma": 0.8, "beta": 3.5}


def synthetic_lab_fit(theta: dict, grid, noise: float, rng, label: str = "synthetic lab fit", as_dict: bool = False):
    """A local eq. 9 fit to synthetic batch tests (1, 3, 9 min, 12 root-2 sieves from
    4 mm, feed in the top three sieve intervals) made from ``theta`` (eq. 5 rates, eq. 6
    breakage) on ``grid`` with Gaussian noise of sd ``noise`` on cumulative passing.
    Returns (the fit as :func:`millflow.scaleup.fit_from_dict` reads it, the model); with
    ``as_dict`` the fit's JSON dict (as ``millflow fit --json`` prints it) instead of the first."""
    import pandas as pd

    from millflow.fitting.data import psd_data_from_frames
    from millflow.fitting.estimate import fit
    from millflow.fitting.models import ForwardModel, ModelSpec, default_parameters
    from millflow.scaleup import fit_from_dict

    sieves = 4.0 * 2 ** (-0.5 * np.arange(12))
    rows = [pd.DataFrame({"condition": "*", "location": "feed", "time_min": 0.0, "size_mm": sieves[:4],
                          "passing": [1.0, 2 / 3, 1 / 3, 0.0]})]
    for t in (1.0, 3.0, 9.0):
        rows.append(pd.DataFrame({"condition": "lab", "location": "mill", "time_min": t, "size_mm": sieves,
                                  "passing": np.linspace(1, 0, 12)}))
    spec = ModelSpec(mode="batch", breakage="normalized")
    model = ForwardModel(spec, psd_data_from_frames(pd.concat(rows), strict=False), grid)
    y = model.predict(np.array([theta[n] for n in model.param_names])) + rng.normal(0.0, noise, model.n_data)
    k = 0
    for r in rows[1:]:
        r["passing"] = y[k:k + 12]
        k += 12
    model = ForwardModel(spec, psd_data_from_frames(pd.concat(rows), strict=False), grid)
    params = default_parameters(spec, {n: {"value": float(v)} for n, v in theta.items()})
    res = fit(model, params, global_search=False, starts=1, grid_check=False, quiet=True)
    return (res.to_dict() if as_dict else fit_from_dict(res.to_dict(), label)), model


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
