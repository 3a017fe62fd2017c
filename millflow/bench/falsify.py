"""Benchmark suite ``falsify``: a falsification study of 50 replicates of a 5-parameter fit.

Case: batch grinding with slowing-down (kappa(t) = 1/(1 + t/t_ref), strength 1) fitted as
first-order (eqs. 4-6; 5 parameters ln_A0, alpha, phi, gamma, beta), 6 sampling times x 12
root-2 sieves on a 25-class grid, 1 % Gaussian noise, each replicate fitted by
``millflow.fitting.fit`` with the study's default global search (differential evolution,
population 8 x 5, up to 60 generations, 3 local starts), plus short/long drift refits on
10 replicates. Run serially and with 2 worker processes. ``ratio_vs_budget`` is the run
time over the 120 s budget ("< 2 minutes on 2 cores");
``ratio_vs_one_fit`` the run time over one replicate's fit timed first in the same process
(the baseline).
"""
from __future__ import annotations

import time

DESCRIPTION = "falsification study: 50 replicates x 5-parameter global fit, serial and 2 workers"
BUDGET_S = 120.0


def _setup():
    from millflow.falsify import GaussianNoise, SlowingDownTruth, batch_design
    from millflow.fitting import ModelSpec
    design = batch_design([30.0 * 2 ** k for k in range(6)], n_sieves=12)
    return SlowingDownTruth(1.0), ModelSpec(mode="batch"), design, GaussianNoise(0.01)


def run(quick: bool = False) -> list[dict]:
    from millflow.falsify import study

    truth, spec, design, noise = _setup()
    R = 10 if quick else 50
    t0 = time.perf_counter()
    study(truth, spec, design, noise=noise, replicates=2, drift_replicates=0)
    one_fit = (time.perf_counter() - t0) / 2.0
    rows = []
    for workers in (1, 2):
        t0 = time.perf_counter()
        res = study(truth, spec, design, noise=noise, replicates=R, drift_replicates=R // 5, workers=workers, seed=1)
        rt = time.perf_counter() - t0
        ds = res.dataset
        rows.append({"case": f"slowing_down_5p_R{R}", "method": f"{workers} worker(s)", "runtime_s": rt,
                     "replicates": R, "per_fit_s": one_fit, "ratio_vs_one_fit": rt / one_fit,
                     "ratio_vs_budget": rt / BUDGET_S * (50 / R),
                     "bias_pct_ln_A0": float(ds.bias_pct.sel(parameter="ln_A0").values[0]),
                     "coverage_ln_A0": float(ds.coverage.sel(parameter="ln_A0").values[0]),
                     "n_failed": int(ds.n_failed.values[0])})
    return rows


def format_table(rows) -> str:
    return "\n".join(f"{r['case']:<24} {r['method']:<12} {r['runtime_s']:7.2f} s  ({r['ratio_vs_budget']:.3f} of the "
                     f"120 s budget scaled to 50 replicates; {r['ratio_vs_one_fit']:.0f} x one fit of "
                     f"{r['per_fit_s']:.3f} s)  bias ln_A0 {r['bias_pct_ln_A0']:.1f} %, coverage "
                     f"{r['coverage_ln_A0']:.2f}, failed {r['n_failed']}" for r in rows)
