"""Benchmark of the non-linear batch solve against scipy's BDF with the same Jacobian.

Case: breakage (power-law S, eq. 6 b) with constant-kernel aggregation on N = 100
classes, one output time, rtol 1e-8 and atol 1e-12 (the scene of ``millflow bench
model-error``). Rows, timed in interleaved rounds in the same process (CPU time of the
process, one BLAS thread; median of the rounds):

- ``batch_nonlinear`` without the error estimate (its default method, LSODA) against
  the baseline ``scipy.integrate.solve_ivp(method="BDF", jac=analytic)`` at the same
  tolerances: ratio and target >= 3x faster;
- ``batch_nonlinear`` with the error estimate (from the one solve: propagated step
  differences, :mod:`millflow.nonlinear.batch`) against the plain call: target <= 1.5x;
- the max abs error of each against a Radau solve at rtol 1e-13, and the estimate.
"""
from __future__ import annotations

import os

import numpy as np

__all__ = ["DESCRIPTION", "run", "format_table"]

DESCRIPTION = "non-linear batch (breakage + aggregation, N = 100, rtol 1e-8): batch_nonlinear vs scipy BDF"
RTOL, ATOL = 1e-8, 1e-12
TARGET_SPEEDUP = 3.0
TARGET_ESTIMATE_RATIO = 1.5


def run(quick: bool = False) -> list[dict]:
    from scipy.integrate import solve_ivp

    from millflow.bench.model_error import TAU, scene
    from millflow.bench.percase import _interleaved
    from millflow.nonlinear import batch_nonlinear

    rounds = 3 if quick else 9
    _, kin, _, feed = scene(cushion=False)
    t = [TAU]
    y0 = np.append(feed, 0.0)

    def scipy_bdf():
        return solve_ivp(lambda _t, y: kin.rate(y), (0.0, TAU), y0, method="BDF", t_eval=t,
                         jac=lambda _t, y: kin.jacobian(y), rtol=RTOL, atol=ATOL)

    med = _interleaved({"bdf": scipy_bdf,
                        "plain": lambda: batch_nonlinear(kin, feed, t, rtol=RTOL, atol=ATOL, error_estimate=False),
                        "estimate": lambda: batch_nonlinear(kin, feed, t, rtol=RTOL, atol=ATOL)}, rounds, 1)
    ref = batch_nonlinear(kin, feed, t, method="Radau", rtol=1e-13, atol=1e-17, error_estimate=False).M[0]
    plain = batch_nonlinear(kin, feed, t, rtol=RTOL, atol=ATOL, error_estimate=False)
    est = batch_nonlinear(kin, feed, t, rtol=RTOL, atol=ATOL)
    bdf = scipy_bdf().y[:-1, -1]
    load = f"{os.getloadavg()[0]:.2f}"
    return [
        {"case": "N = 100, rtol 1e-8", "method": f"batch_nonlinear ({plain.method})", "runtime_s": med["plain"],
         "baseline": "scipy BDF + analytic Jacobian", "baseline_s": med["bdf"],
         "ratio_vs_baseline": med["plain"] / med["bdf"], "speedup": med["bdf"] / med["plain"],
         "target": f">= {TARGET_SPEEDUP:g}x faster", "met": med["bdf"] / med["plain"] >= TARGET_SPEEDUP,
         "max_abs_error": float(np.abs(plain.M[0] - ref).max()),
         "baseline_max_abs_error": float(np.abs(bdf - ref).max()), "load_average": load},
        {"case": "N = 100, rtol 1e-8", "method": "batch_nonlinear + error estimate", "runtime_s": med["estimate"],
         "baseline": "batch_nonlinear without estimate", "baseline_s": med["plain"],
         "ratio_vs_baseline": med["estimate"] / med["plain"], "target": f"<= {TARGET_ESTIMATE_RATIO:g}x",
         "met": med["estimate"] / med["plain"] <= TARGET_ESTIMATE_RATIO,
         "max_abs_error": float(np.abs(est.M[0] - ref).max()), "error_estimate": est.error_estimate,
         "load_average": load},
    ]


def format_table(rows: list[dict]) -> str:
    out = []
    for r in rows:
        err = f"error {r['max_abs_error']:.1e}"
        if "error_estimate" in r:
            err += f", estimate {r['error_estimate']:.1e}"
        if "baseline_max_abs_error" in r:
            err += f" (baseline {r['baseline_max_abs_error']:.1e})"
        out.append(f"{r['method']:<34} {1e3 * r['runtime_s']:>8.2f} ms vs {r['baseline']:<34} "
                   f"{1e3 * r['baseline_s']:>8.2f} ms  ratio {r['ratio_vs_baseline']:.3f} (target {r['target']}: "
                   f"{'met' if r['met'] else 'not met'})  {err}")
    out.append(f"CPU time of the process, medians of interleaved rounds; load average {rows[0]['load_average']}")
    return "\n".join(out)
