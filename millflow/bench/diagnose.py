"""Benchmark suite ``diagnose``: a 6-parameter non-linear batch fit and ``diagnose`` on it.

Case: batch grinding (6 times from 0.5 to 16 min x 16 root-2 sieves, 33-class grid, 1 %
Gaussian noise) whose truth is breakage (eqs. 5-6 at the falsification defaults) with
slowing-down s = 1, resp. constant-kernel aggregation beta0 = 0.01 1/s. Rows:

- ``fit slowing_down`` / ``fit aggregation``: the 6-parameter non-linear fit
  (``[model] kinetics``) with the study settings (DE population 8 x 6, up to 60
  generations, 3 local starts); budget 30 s;
- ``fit linear``: the 5-parameter first-order fit of the same data, the baseline timed in
  the same process (``ratio_vs_linear``);
- ``diagnose``: the whole candidate set (linear, slowing-down, cushioning, aggregation)
  with drift tests; budget 180 s.

``ratio_vs_budget`` = run time / budget (< 1 meets it). The machine's load is reported
(``load_1min``) with the CPU time of the process (``cpu_s``): on a shared machine the wall
time mostly measures the wait for a core, the CPU time is what an idle core would take
(one process, one BLAS thread), and the ratios to the linear fit are comparable.
"""
from __future__ import annotations

import os
import time

DESCRIPTION = "6-parameter non-linear batch fit (< 30 s) and diagnose on it (< 3 min)"
FIT_BUDGET_S, DIAGNOSE_BUDGET_S = 30.0, 180.0
SETTINGS = {"global_search": True, "starts": 3, "popsize": 8, "maxiter": 60, "seed": 0}


def _data(truth, seed=1):
    import numpy as np

    from millflow.falsify import batch_design
    design = batch_design([30.0 * 2 ** k for k in range(6)])
    M = truth.mass_fractions(design)
    clean = design.passing_at_sieves(M).ravel()
    noisy = clean + 0.01 * np.random.default_rng(seed).standard_normal(clean.size)
    return design, design.data(noisy, design.sample_keys())


def _cfg(design, data, spec):
    from millflow.falsify.study import study_parameters
    from millflow.falsify.truths import BREAKAGE_TRUTH
    from millflow.fitting.config import FitConfig
    return FitConfig("bench", data, spec, study_parameters(spec, BREAKAGE_TRUTH), design.grid, dict(SETTINGS))


def run(quick: bool = False) -> list[dict]:
    from millflow.falsify import SlowingDownTruth
    from millflow.falsify.nonlinear_truths import AggregationTruth
    from millflow.fitting import ModelSpec
    from millflow.fitting.diagnose import diagnose
    from millflow.fitting.estimate import fit

    rows = []
    truths = [("slowing_down", SlowingDownTruth(1.0))] + ([] if quick else [("aggregation", AggregationTruth(0.01))])
    for name, truth in truths:
        design, data = _data(truth)
        lin = _cfg(design, data, ModelSpec(mode="batch"))
        t0 = time.perf_counter()
        fit(lin.model(), lin.params, grid_check=False, quiet=True, **lin.optimizer)
        t_lin = time.perf_counter() - t0
        cfg = _cfg(design, data, ModelSpec(mode="batch", kinetics=(name,)))
        t0, c0 = time.perf_counter(), time.process_time()
        res = fit(cfg.model(), cfg.params, grid_check=False, quiet=True, **cfg.optimizer)
        rt, cpu = time.perf_counter() - t0, time.process_time() - c0
        load = os.getloadavg()[0]
        rows.append({"case": f"fit {name}", "n_params": res.n_params, "runtime_s": rt, "cpu_s": cpu,
                     "budget_s": FIT_BUDGET_S, "ratio_vs_budget": rt / FIT_BUDGET_S, "ratio_vs_linear": rt / t_lin,
                     "linear_fit_s": t_lin, "load_1min": load})
        if name == "slowing_down":
            t0, c0 = time.perf_counter(), time.process_time()
            dg = diagnose(lin, quiet=True, loco=False)
            rt, cpu = time.perf_counter() - t0, time.process_time() - c0
            rows.append({"case": "diagnose (slowing-down truth)", "n_params": len(dg.table), "runtime_s": rt,
                         "cpu_s": cpu, "budget_s": DIAGNOSE_BUDGET_S, "ratio_vs_budget": rt / DIAGNOSE_BUDGET_S,
                         "ratio_vs_linear": rt / t_lin, "linear_fit_s": t_lin, "best": dg.best,
                         "load_1min": os.getloadavg()[0]})
    return rows


def format_table(rows) -> str:
    lines = [f"{'case':<32}{'p':>4}{'run time [s]':>14}{'CPU [s]':>9}{'budget [s]':>12}{'/budget':>9}"
             f"{'/linear fit':>13}{'load':>7}"]
    for r in rows:
        lines.append(f"{r['case']:<32}{r['n_params']:>4}{r['runtime_s']:>14.1f}{r['cpu_s']:>9.1f}{r['budget_s']:>12.0f}"
                     f"{r['ratio_vs_budget']:>9.2f}{r['ratio_vs_linear']:>13.1f}{r['load_1min']:>7.1f}")
    return "\n".join(lines)
